"""
The Rig protocol: one model of a rig, whatever its kind, and the data it evaluates to.

:func:`rig_for` builds the rig of any scene; consumers ask :attr:`Rig.capabilities`, never the
kind.  docs/design.md#the-rig-protocol; frames, units and signs: :mod:`mech_balance.conventions`.
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

    ``names``: the moving bodies (:attr:`Drawing.bodies` order); ``rotation`` ``(n, nb, 3, 3)``
    body to frame axes; ``origin_m``, ``omega_rad_s``, ``alpha_rad_s2`` and the origin's
    ``accel_origin_m_s2`` ``(n, nb, 3)`` in frame axes.
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

    ``joint_*`` ``(n, n_joints)`` in the order of ``joint_names`` (``joint_effort`` None
    without a torque); ``force_N``, ``moment_Nm`` the shaking wrench ``(n, 3)`` (None for
    kinematics only); ``series`` the scalar outputs asked for
    (:data:`mech_balance.schema.scene.SERIES`); ``reactions`` ``{joint: (force (n, 3),
    moment (n, 3))}``; ``residual``, ``condition``, ``near_singular`` per angle; ``poses``
    read through :attr:`bodies`; ``native`` the implementation's own result.
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

    ``centre_m`` in the carrying body's frame; a disc of ``radius_m`` and ``thickness_m``
    about the body's z (a sphere when the thickness is its diameter).
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

    ``dimension`` 2 or 3; ``frame`` the fixed points; ``bodies`` in :class:`BodyPoses` order;
    ``joints`` ``(name, body, point)``; ``axes`` ``(name, point, direction)`` of the joint
    axes (planar: the prismatic guides) fixed in the frame.
    """

    dimension: int
    frame: dict
    bodies: tuple
    joints: tuple
    axes: tuple = ()


class Rig(Protocol):
    """
    The protocol every rig implements.

    ``joint_prismatic`` says which ``joint_names`` slide (m; the others turn, rad);
    ``moment_point`` says in words where the shaking moment is reduced, ``moment_point_m`` is
    that point in the frame, m; ``driving_series`` names the series holding the driving
    effort: ``'driving_torque'`` (N m, revolute input) or ``'driving_force'`` (N, prismatic).
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
    """Return the :class:`Rig` of a validated scene of any kind (``cache``: shared geometry)."""
    return registry.kind_of(scene).rig_factory()(scene, cache=cache)


def batch(scene, psi, speed, accel):
    """Return ``psi``, ``speed`` and ``accel`` as checked ``(n,)`` arrays (None: the scene's)."""
    speed = scene.crank_speed_rad_s if speed is None else speed
    accel = scene.crank_acceleration_rad_s2 if accel is None else accel
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
    """Raise :class:`CapabilityError` unless the rig (or a scene's kind) has ``capability``."""
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
