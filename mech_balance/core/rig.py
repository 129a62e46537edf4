"""
The Rig protocol: one model of a rig, whatever its kind, and the data it evaluates to.

The pinocchio idea: a :class:`Rig` is an immutable model built once per geometry and design
(it holds no speeds and no warnings); :meth:`Rig.at` evaluates it at a batch of crank angles,
speeds and accelerations and returns a fresh :class:`RigData`.  Every consumer (analysis,
balancing, the node, the recording, the command line, the benchmarks) works through this
protocol; none asks which kind of rig it has.  A rig says what it can do through
:attr:`Rig.capabilities` (for example ``'bearing_reactions'`` or ``'mass_redistribution'``),
and :func:`rig_for` builds the rig of any scene from the kind registry of
:mod:`mech_balance.schema.registry`.

Implementations: :class:`mech_balance.core.planar.rig.PlanarRig` (every single-input planar
linkage) and :class:`mech_balance.core.spatial.rig.SpatialRig` (every single-input spatial
linkage, the RGGR of seed 002 among them).

Frames, units and signs: :mod:`mech_balance.conventions`.  The shaking wrench is always a pair
of 3-vectors in the frame's axes (planar rigs: force z = 0, moment x = y = 0), reduced to the
rig's moment point (:attr:`Rig.moment_point`).
"""

from dataclasses import dataclass, field
from typing import Protocol

from mech_balance.schema import registry
import numpy as np


@dataclass
class BodyPoses:
    """
    Where every body is, for drawing and for sensors: ``(n, nb, 3)`` origins, ``(n, nb, 3, 3)``.

    ``names[k]`` is body k (``frame`` first); ``rotation[i, k]`` maps body k's own axes to the
    frame's at sample i, ``origin_m[i, k]`` is its origin in the frame, m.
    """

    names: tuple
    origin_m: np.ndarray
    rotation: np.ndarray

    def world(self, body, local_m):
        """Return ``(n, 3)`` frame coordinates of a point fixed in ``body`` (name or index)."""
        k = self.names.index(body) if isinstance(body, str) else int(body)
        local = np.asarray(local_m, dtype=float)
        if local.shape == (2,):
            local = np.append(local, 0.0)
        return self.origin_m[:, k] + self.rotation[:, k] @ local


@dataclass
class BodyKinematics:
    """
    The motion of every moving body at n samples, in the frame's axes (SI).

    ``names[k]`` is body k (moving bodies only, the order of :attr:`Drawing.bodies`);
    ``rotation[i, k]`` ``(3, 3)`` maps body k's own axes to the frame's, ``origin_m[i, k]``
    is its origin, m; ``omega_rad_s``, ``alpha_rad_s2`` its angular velocity and acceleration
    and ``accel_origin_m_s2`` its origin's linear acceleration, all ``(n, nb, 3)`` in frame
    axes.  With these, every body's inertia wrench is linear in its ten inertial parameters
    (:mod:`mech_balance.core.regressor`), which is what spatial balancing and identification
    build on.  Rigs that can produce it list ``'body_kinematics'`` in their capabilities.
    """

    names: tuple
    rotation: np.ndarray
    origin_m: np.ndarray
    omega_rad_s: np.ndarray
    alpha_rad_s2: np.ndarray
    accel_origin_m_s2: np.ndarray


@dataclass
class RigData:
    """
    A rig evaluated at n crank angles (SI; arrays are sample-first).

    ``joint_*`` are ``(n, n_joints)`` in the order of ``joint_names`` (ROS ``JointState``
    values; the implementations document their coordinates); ``joint_effort`` is None when
    no torque was asked for.  ``force_N`` and ``moment_Nm`` are the shaking wrench ``(n, 3)``
    (None for kinematics only).  ``series`` holds the scalar outputs that were asked for
    (``driving_torque`` or ``driving_force``, ``kinetic_energy``, ...:
    :data:`mech_balance.schema.scene.SERIES`),
    ``reactions`` the bearing loads ``{joint: (force (n, 3), moment (n, 3))}`` when asked for.
    ``residual`` (loop closure, relative), ``condition`` (Jacobian condition number) and
    ``near_singular`` are the per-angle diagnostics of the position solution.  ``poses`` is
    the :class:`BodyPoses` or a function computing them (read :attr:`bodies`).  ``native`` is
    the implementation's own result (planar: ``(state, wrenches)``), for code inside the core.
    """

    crank_angle_rad: np.ndarray
    crank_speed_rad_s: np.ndarray
    crank_accel_rad_s2: np.ndarray
    joint_position: np.ndarray
    joint_velocity: np.ndarray
    joint_effort: np.ndarray
    force_N: np.ndarray
    moment_Nm: np.ndarray
    joint_names: tuple = ()
    series: dict = field(default_factory=dict)
    reactions: dict = None
    residual: np.ndarray = None
    condition: np.ndarray = None
    near_singular: np.ndarray = None
    poses: object = None
    native: object = None

    def __len__(self):
        """Return the number of samples."""
        return self.crank_angle_rad.shape[0]

    @property
    def bodies(self):
        """Return the :class:`BodyPoses` (computed on first use: drawing and sensors only)."""
        if callable(self.poses):
            self.poses = self.poses()
        return self.poses

    @property
    def state(self):
        """Return the planar kinematic state, or None for other rigs (the recorder's input)."""
        return self.native[0] if isinstance(self.native, tuple) else None

    @property
    def wrenches(self):
        """Return the planar inertia wrenches, or None (other rigs, kinematics only)."""
        return self.native[1] if isinstance(self.native, tuple) else None


@dataclass(frozen=True)
class AddedBody:
    """
    A body fixed to a moving body, drawn at true size: a counterweight disc, a balancing weight.

    ``centre_m`` ``(x, y, z)`` in the carrying body's frame; a disc (cylinder) of
    ``radius_m`` and ``thickness_m`` whose axis is the body frame's z (a sphere when the
    thickness is its diameter); ``mass_kg`` its mass.  On a planar rig the z of ``centre_m``
    is the disc's plane: its mid-plane's offset along the normal from its link's plane.
    """

    name: str
    centre_m: tuple
    radius_m: float
    thickness_m: float
    mass_kg: float


@dataclass(frozen=True)
class DrawingBody:
    """
    A body to draw: its points in its own frame (m, 3-D) and the outline joining them.

    ``mass_kg`` and ``mass_centre_m`` are the body's totals (added bodies included);
    ``added`` its :class:`AddedBody` parts; ``point_masses`` ``((mass_kg, (x, y, z)), ...)``
    an equimomental point-mass model of it, where the rig has one (planar: seed 001).
    """

    name: str
    points: dict
    outline: tuple
    mass_centre_m: tuple
    mass_kg: float = None
    added: tuple = ()
    point_masses: tuple = ()


@dataclass(frozen=True)
class Drawing:
    """
    What a rig looks like, in body frames: the static part of every picture of it.

    ``dimension`` is 2 (planar: z = 0) or 3; ``frame`` the fixed points ``{name: (x, y, z)}``;
    ``bodies`` the moving bodies in the order of :class:`BodyPoses`'s names after ``frame``;
    ``joints`` ``(name, body, point)`` for the joint markers; ``axes`` ``(name, point (3,),
    direction (3,))`` of the joint axes fixed in the frame (3-D rigs: the revolute axes;
    planar rigs: the guides of prismatic joints on the frame).
    """

    dimension: int
    frame: dict
    bodies: tuple
    joints: tuple
    axes: tuple = ()


class Rig(Protocol):
    """
    The protocol every rig implements (see the module docstring).

    ``scene`` is the validated scene, ``name`` its name; ``joint_names`` and ``crank_joint``
    name the published joints, ``joint_prismatic`` says which of them slide (m; the others
    turn, rad); ``moment_point`` says in words where the shaking moment is reduced and
    ``moment_point_m`` is that point ``(x, y, z)`` in the frame, m; ``capabilities`` what the
    rig can compute or be balanced by; ``outputs`` what its scene asks for; ``drawing`` its
    :class:`Drawing`.  ``driving_series`` names the series of :attr:`RigData.series` that
    holds the driving effort when it is asked for (output ``driving_torque``):
    ``'driving_torque'`` (N m about a revolute input's axis) or ``'driving_force'`` (N along
    a prismatic input's axis); its label and dimension are in
    :data:`mech_balance.schema.scene.SERIES`.
    """

    scene: object
    name: str
    joint_names: tuple
    joint_prismatic: tuple
    crank_joint: str
    moment_point: str
    moment_point_m: tuple
    capabilities: frozenset
    driving_series: str
    outputs: tuple
    drawing: Drawing

    def at(self, psi, speed=None, accel=None, outputs=None):
        """Return the :class:`RigData` at crank angles ``psi`` (rad), rad/s, rad/s^2."""

    def with_scene(self, scene):
        """Return the rig of another design (inertia) of the same geometry."""


def rig_for(scene, cache=True):
    """
    Return the :class:`Rig` of a validated scene of any registered kind.

    With ``cache`` (the default) a rig reuses what an earlier rig of the same geometry built
    (the planar linkage and its branch trace); without, it builds everything anew.
    """
    return registry.kind_of(scene).rig_factory()(scene, cache=cache)


def batch(psi, speed, accel):
    """Return ``psi``, ``speed`` and ``accel`` as checked ``(n,)`` float arrays."""
    psi = np.atleast_1d(np.asarray(psi, dtype=float)).ravel()
    if psi.size == 0 or not np.all(np.isfinite(psi)):
        raise ValueError(f'crank_angle_rad: got {psi!r}, expected finite angles (rad)')
    speed = np.broadcast_to(np.asarray(speed, dtype=float), psi.shape).copy()
    accel = np.broadcast_to(np.asarray(accel, dtype=float), psi.shape).copy()
    if not (np.all(np.isfinite(speed)) and np.all(np.isfinite(accel))):
        raise ValueError('crank speed and acceleration: got non-finite values, expected '
                         'finite rad/s and rad/s^2')
    return psi, speed, accel


class CapabilityError(ValueError):
    """A verb asked of a rig whose kind lacks the capability it needs (one line)."""


def as_rig(rig_or_scene):
    """Return a :class:`Rig`: ``rig_or_scene`` itself if it is one, else its scene's rig."""
    if hasattr(rig_or_scene, 'at') and hasattr(rig_or_scene, 'capabilities'):
        return rig_or_scene
    return rig_for(rig_or_scene)


def require(rig_or_scene, capability, verb):
    """
    Raise :class:`CapabilityError` unless the rig (or a scene's kind) has ``capability``.

    The message is one line naming the verb, the capability, the scene and its kind, and the
    kinds that have it; verbs call this before doing any work.
    """
    kind = registry.kind_of(rig_or_scene)
    caps = getattr(rig_or_scene, 'capabilities', None)
    if caps is None:
        caps = kind.rig_factory().capabilities
    if capability in caps:
        return
    able = [k.name for k in registry.KINDS.values()
            if capability in k.rig_factory().capabilities]
    sc = getattr(rig_or_scene, 'scene', rig_or_scene)
    raise CapabilityError(f'{verb}: needs the capability {capability!r}, which scene '
                          f'{getattr(sc, "name", "?")!r} of kind {kind.name} lacks; expected '
                          f'a scene of kind {" or ".join(able) or "(none yet)"}')
