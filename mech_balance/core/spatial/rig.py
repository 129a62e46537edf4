"""The spatial rig behind the Rig protocol; joint values: docs/core.md#module-overviews."""

from mech_balance.core.rig import batch, BodyKinematics, BodyPoses, Drawing, DrawingBody, \
    RigData
from mech_balance.core.spatial import coordinates, dynamics, kinematics
from mech_balance.core.spatial.vectors import cross
from mech_balance.schema.scene import FRAME, needs
import numpy as np

CAPABILITIES = frozenset({'kinematics', 'shaking_wrench', 'driving_torque',
                          'bearing_reactions', 'kinetic_energy', 'body_kinematics'})
"""What a spatial rig computes (:attr:`Rig.capabilities`)."""

_LINKAGES = {}
_LINKAGE_CACHE_SIZE = 64


def linkage_for(scene, cache=True):
    """Return the compiled :class:`~kinematics.Linkage` of a scene's geometry (cached)."""
    from mech_balance.schema.spatial import geometry
    key = repr(geometry(scene)[0])
    linkage = _LINKAGES.get(key) if cache else None
    if linkage is None:
        linkage = kinematics.Linkage(scene)
        if cache:
            if len(_LINKAGES) > _LINKAGE_CACHE_SIZE:
                _LINKAGES.clear()
            _LINKAGES[key] = linkage
    return linkage


class SpatialRig:
    """A spatial scene with its compiled linkage and inertia (module docstring)."""

    capabilities = CAPABILITIES

    def __init__(self, scene, linkage=None, cache=True):
        self.scene = scene
        self.name = scene.name
        if getattr(scene, 'balancing_weights', ()):   # seed 002's method (balancing.weights)
            self.capabilities = CAPABILITIES | {'balancing_weights'}
        self.linkage = linkage if linkage is not None else linkage_for(scene, cache)
        self.linkage.skeleton  # noqa: B018 - trace the branch now: fail early
        self.linkage.check_idle_inertia(scene)  # a design of the geometry keeps its rods
        self.inertia = dynamics.Inertia.from_scene(scene)
        self.joint_names, self.joint_prismatic = coordinates.joint_names(scene)
        self.crank_joint = scene.crank_joint
        self.crank_index = self.joint_names.index(scene.crank_joint)
        self.driving_series = 'driving_torque' if self.linkage.periodic else 'driving_force'
        self.moment_point_m = tuple(float(x) for x in scene.moment_point_m)
        self.moment_point = "the frame point (%g, %g, %g) m (the scene's moment_point_m)" % \
            self.moment_point_m
        self._drawing = None

    @property
    def outputs(self):
        """Return what the scene asks for (its ``outputs:``)."""
        return self.scene.outputs

    @property
    def warnings(self):
        """Return the near-singular and other warnings of the linkage."""
        return list(self.linkage.warnings)

    @property
    def reactions_unique(self):
        """Return whether the bearing reactions are unique (False: over-constrained)."""
        return self.linkage.redundant == 0

    def with_scene(self, scene):
        """Return the rig of another design (inertia) of the same geometry."""
        return SpatialRig(scene, self.linkage)

    def evaluate(self, psi, outputs=None, speed=None, accel=None):
        """Return the core's ``(state, wrenches)`` at crank angles ``psi`` (rad)."""
        psi, speed, accel = batch(self.scene, psi, speed, accel)
        return self._evaluate(psi, outputs, speed, accel)

    def _evaluate(self, psi, outputs, speed, accel):
        """Return :meth:`evaluate` of already checked ``(n,)`` arrays (:func:`batch`)."""
        need = needs(self.scene.outputs if outputs is None else outputs)
        state = self.linkage.solve(psi, speed, accel, need_acc='accelerations' in need)
        if 'accelerations' not in need:
            return state, None
        return state, dynamics.inverse_dynamics(self.linkage, state, self.inertia,
                                                self.moment_point_m, need)

    def at(self, psi, speed=None, accel=None, outputs=None):
        """Return the :class:`RigData` at crank angles ``psi`` (module docstring: joints)."""
        psi, speed, accel = batch(self.scene, psi, speed, accel)
        outputs = self.scene.outputs if outputs is None else tuple(outputs)
        want = set(outputs)
        state, w = self._evaluate(psi, tuple(outputs) or ('kinematics',), speed, accel)
        _, _, position, velocity = coordinates.joint_values(self.linkage, state)
        x, x_d, _ = self.linkage.input_motion(psi, speed, accel)
        position[:, self.crank_index] = x
        velocity[:, self.crank_index] = x_d
        series, effort, reactions, force, moment = {}, None, None, None, None
        if w is not None:
            force, moment = w.force_N, w.moment_Nm
            if w.driving_torque is not None:
                # the effort on tree coordinate 0, in the input joint's own sense
                driving = w.driving_torque if self.linkage.input_sign > 0.0 else \
                    -w.driving_torque
                series[self.driving_series] = driving
                effort = np.zeros_like(position)
                effort[:, self.crank_index] = driving
            if w.reactions is not None and 'bearing_reactions' in want:
                reactions = w.reactions
        if 'kinetic_energy' in want:
            series['kinetic_energy'] = dynamics.kinetic_energy(state, self.inertia)
        return RigData(
            psi, speed, accel, position, velocity, effort, force, moment, self.joint_names,
            series=series, reactions=reactions, residual=state.residual,
            condition=state.cond, near_singular=state.cond > kinematics.COND_WARN,
            poses=lambda: body_poses(self.linkage, state), native=state)

    def body_kinematics(self, psi, speed=None, accel=None):
        """Return the :class:`~mech_balance.core.rig.BodyKinematics` at crank angles ``psi``."""
        psi, speed, accel = batch(self.scene, psi, speed, accel)
        state = self.linkage.solve(psi, speed, accel, need_acc=True)
        fr, tw, ac = state.frames, state.twist, state.accel
        p = fr.origin
        w, v = tw[..., :3], tw[..., 3:]
        acc_origin = ac[..., 3:] + cross(ac[..., :3], p) + cross(w, v + cross(w, p))
        return BodyKinematics(self.linkage.body_names[1:], fr.rot[:, 1:].copy(),
                              p[:, 1:].copy(), w[:, 1:].copy(), ac[:, 1:, :3].copy(),
                              acc_origin[:, 1:])

    @property
    def drawing(self):
        """Return the rig's :class:`Drawing` (3-D; bodies in their own frames)."""
        if self._drawing is None:
            sc = self.scene
            bodies = tuple(
                DrawingBody(lk.name, dict(lk.points), tuple(lk.points), tuple(lk.com_m),
                            lk.mass_kg)
                for lk in sc.links)
            joints = tuple((j.name, j.link_b, j.point_b) for j in sc.joints)
            axes = []
            for j in sc.joints:
                if j.axis is None or FRAME not in (j.link_a, j.link_b):
                    continue
                on_frame_a = j.link_a == FRAME
                point = sc.frame_points[j.point_a if on_frame_a else j.point_b]
                axis = j.axis if on_frame_a else (j.axis_b or j.axis)
                norm = float(np.linalg.norm(axis))
                axes.append((j.name, tuple(point), tuple(float(x) / norm for x in axis)))
            self._drawing = Drawing(3, dict(sc.frame_points), bodies, joints, tuple(axes))
        return self._drawing


def body_poses(linkage, state):
    """Return the :class:`BodyPoses` of a solved spatial state (frame first)."""
    return BodyPoses(tuple(linkage.body_names), state.frames.origin, state.frames.rot)
