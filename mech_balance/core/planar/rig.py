"""The planar rig behind the Rig protocol; joint values: docs/core.md#module-overviews."""

from mech_balance.core import equimomental
from mech_balance.core.planar import dynamics, kinematics
from mech_balance.core.planar.algebra import cross
from mech_balance.core.rig import AddedBody, batch, BodyPoses, Drawing, DrawingBody, \
    RigData
from mech_balance.schema import FRAME, needs
from mech_balance.schema.scene import Normalization, SERIES
import numpy as np

CAPABILITIES = frozenset({'kinematics', 'shaking_wrench', 'driving_torque',
                          'bearing_reactions', 'kinetic_energy', 'gravity',
                          'mass_redistribution', 'counterweights',
                          'analytic_balance', 'accuracy_study', 'identification'})
"""What a planar rig computes and how it can be balanced (:attr:`Rig.capabilities`)."""

_LINKAGES = {}
_LINKAGE_CACHE_SIZE = 64


def linkage_for(scene):
    """Return the compiled :class:`~kinematics.Linkage` of a scene's geometry (cached)."""
    key = (scene.source, scene.name, scene.frame_points.__repr__(),
           tuple((lk.name, repr(lk.points)) for lk in scene.links), scene.joints,
           scene.crank_joint, scene.assembly_crank_angle_rad,
           repr(sorted(scene.assembly_link_angles_rad.items())),
           repr(sorted(scene.assembly_displacements_m.items())),
           None if scene.normalization is None else scene.normalization.length_m)
    linkage = _LINKAGES.get(key)
    if linkage is None:
        linkage = kinematics.Linkage(scene)
        if len(_LINKAGES) > _LINKAGE_CACHE_SIZE:
            _LINKAGES.clear()
        _LINKAGES[key] = linkage
    return linkage


def objective_units(scene):
    """Return the units of the objective: the scene's normalization, else its crank's."""
    if scene.normalization is not None:
        return scene.normalization
    rig_linkage = linkage_for(scene)
    crank = next(j for j in scene.joints if j.name == scene.crank_joint)
    name = crank.link_b if crank.link_a == FRAME else crank.link_a
    return Normalization(scene.link(name).mass_kg, rig_linkage.length_scale,
                         abs(scene.crank_speed_rad_s))


class PlanarRig:
    """A planar scene with its compiled linkage and inertial parameters."""

    moment_point = 'the crank pivot'
    capabilities = CAPABILITIES
    driving_series = 'driving_torque'

    def __init__(self, scene, linkage=None, cache=True):
        self.scene = scene
        self.name = scene.name
        if linkage is None:
            linkage = linkage_for(scene) if cache else kinematics.Linkage(scene)
        self.linkage = linkage
        self.linkage.skeleton  # noqa: B018 - assemble and trace the branch: fail early
        self.inertia = dynamics.Inertia.from_links(scene.links)
        self.gravity = complex(*scene.gravity_m_s2)
        lk = self.linkage
        body = {name: i for i, name in enumerate(lk.body_names)}
        points = {FRAME: scene.frame_points, **{link.name: link.points for link in scene.links}}
        joints = scene.joints
        self.joint_names = tuple(j.name for j in joints)
        self.crank_joint = scene.crank_joint
        self.crank_index = self.joint_names.index(scene.crank_joint)
        self._a = np.array([body[j.link_a] for j in joints])
        self._b = np.array([body[j.link_b] for j in joints])
        self._pa = np.array([complex(*points[j.link_a][j.point_a]) for j in joints])[:, None]
        self._pb = np.array([complex(*points[j.link_b][j.point_b]) for j in joints])[:, None]
        self._prismatic = np.array([j.prismatic for j in joints])
        self.joint_prismatic = tuple(bool(p) for p in self._prismatic)
        self._axis = np.array([complex(*j.axis) for j in joints])[:, None]
        self._drawing = None

    @property
    def outputs(self):
        """Return what the scene asks for (its ``outputs:``)."""
        return self.scene.outputs

    @property
    def moment_point_m(self):
        """Return the crank pivot in the frame, ``(x, y, 0)`` m (the shaking moment's point)."""
        return (self.linkage.pivot.real, self.linkage.pivot.imag, 0.0)

    def with_scene(self, scene):
        """Return a rig for another inertia on the same geometry (no re-tracing)."""
        return PlanarRig(scene, self.linkage)

    def evaluate(self, psi, outputs=None, speed=None, accel=None):
        """Return the core's ``(state, wrenches or None)`` at crank angles ``psi`` (rad)."""
        need = needs(self.scene.outputs if outputs is None else outputs)
        # this rig's crank speed, not that of the scene the shared linkage was compiled from
        speed = self.scene.crank_speed_rad_s if speed is None else speed
        accel = self.scene.crank_acceleration_rad_s2 if accel is None else accel
        state = self.linkage.solve(psi, speed, accel, need_acc='accelerations' in need)
        if 'accelerations' not in need:
            return state, None
        return state, dynamics.inverse_dynamics(self.linkage, state, self.inertia,
                                                self.gravity, need)

    def series(self, state, names):
        """Return the scalar series among ``names`` that come from the kinematics alone."""
        out = {}
        if 'kinetic_energy' in names:
            out['kinetic_energy'] = kinetic_energy(state, self.inertia)
        return out

    def at(self, psi, speed=None, accel=None, outputs=None):
        """Return the :class:`RigData` at crank angles ``psi`` (module docstring: joints)."""
        psi, speed, accel = batch(self.scene, psi, speed, accel)
        outputs = self.scene.outputs if outputs is None else tuple(outputs)
        want = set(outputs)
        # the reaction moments of prismatic joints come with the bearing reactions; those
        # also give the driving torque at zero crank speed (the NOC projection divides by it)
        effort = bool({'driving_torque', 'bearing_reactions'} & want)
        core_outputs = {o for o in outputs if o not in SERIES or o == 'driving_torque'}
        if effort and np.any(self._prismatic):
            core_outputs.add('bearing_reactions')
        state, w = self.evaluate(psi, tuple(core_outputs) or ('kinematics',), speed, accel)
        pose, a, b = state.pose, self._a, self._b
        position = pose.phi[b] - pose.phi[a]
        velocity = state.omega[b] - state.omega[a]
        if np.any(self._prismatic):
            s = self._prismatic
            pa = pose.origin[a[s]] + pose.rot[a[s]] * self._pa[s]
            pb = pose.origin[b[s]] + pose.rot[b[s]] * self._pb[s]
            va = state.vel[a[s]] + 1j * state.omega[a[s]] * (pa - pose.origin[a[s]])
            vb = state.vel[b[s]] + 1j * state.omega[b[s]] * (pb - pose.origin[b[s]])
            axis = pose.rot[a[s]] * self._axis[s]
            d = pb - pa
            position[s] = (d * np.conj(axis)).real
            velocity[s] = ((vb - va) * np.conj(axis)).real + \
                (d * np.conj(1j * state.omega[a[s]] * axis)).real
        position[self.crank_index] = psi
        velocity[self.crank_index] = state.psi_d
        series, reactions, joint_effort, force, moment = {}, None, None, None, None
        if w is not None:
            force, moment = _frame_wrench(w.shaking_force, w.shaking_moment)
            if w.driving_torque is not None and effort:
                series['driving_torque'] = w.driving_torque
                joint_effort = np.zeros_like(position)
                for j in np.flatnonzero(self._prismatic):
                    joint_effort[j] = w.reaction_moment[self.joint_names[j]]
                joint_effort[self.crank_index] = w.driving_torque
                joint_effort = joint_effort.T
            if w.reaction_force is not None and 'bearing_reactions' in want:
                reactions = {name: _frame_wrench(f, w.reaction_moment[name])
                             for name, f in w.reaction_force.items()}
        series.update(self.series(state, want))
        return RigData(
            psi, speed, accel, position.T, velocity.T, joint_effort, force, moment,
            self.joint_names, series=series, reactions=reactions,
            residual=state.residual, condition=state.cond,
            near_singular=state.cond > kinematics.COND_WARN,
            poses=lambda: body_poses(self.linkage, state), native=(state, w))

    @property
    def drawing(self):
        """Return the rig's :class:`Drawing` (links at z = 0, a disc's z its ``plane_m``)."""
        if self._drawing is None:
            sc = self.scene
            bodies = tuple(
                DrawingBody(lk.name, {k: (v[0], v[1], 0.0) for k, v in lk.points.items()},
                            tuple(lk.points), (lk.com_m[0], lk.com_m[1], 0.0), lk.mass_kg,
                            tuple(AddedBody(f'{lk.name} counterweight {i + 1}',
                                            (cw.centre_m[0], cw.centre_m[1], cw.plane_m),
                                            cw.radius_m, cw.thickness_m, cw.mass_kg)
                                  for i, cw in enumerate(lk.counterweights)),
                            _point_masses(lk))
                for lk in sc.links)
            joints = tuple((j.name, j.link_b, j.point_b) for j in sc.joints)
            guides = tuple((j.name, (*sc.frame_points[j.point_a], 0.0), (*j.axis, 0.0))
                           for j in sc.joints if j.prismatic and j.link_a == FRAME)
            self._drawing = Drawing(2, {k: (v[0], v[1], 0.0) for k, v in
                                        sc.frame_points.items()}, bodies, joints, guides)
        return self._drawing


def _frame_wrench(force, moment):
    """Return a planar force (complex) and moment ``(n,)`` as ``(n, 3)`` frame vectors."""
    f, m = np.zeros((force.size, 3)), np.zeros((force.size, 3))
    f[:, 0], f[:, 1], m[:, 2] = force.real, force.imag, moment
    return f, m


def _point_masses(link):
    """Return a link's three equimomental point masses (seed 001 eqs. 13-15) for drawing."""
    if not (link.mass_kg > 0.0 and link.inertia_origin_kg_m2 > 0.0):
        return ()
    pm = equimomental.from_link(link.mass_kg, link.com_m, link.inertia_origin_kg_m2)
    at = pm.distance_m * equimomental.UNIT
    return tuple((m, (float(z.real), float(z.imag), 0.0)) for m, z in zip(pm.masses_kg, at))


def kinetic_energy(state, inertia):
    """Return the kinetic energy of the moving links ``(p,)``, J (seed 000 eq. 38)."""
    world_h = state.pose.rot * inertia.first_moment[:, None]
    v, omega = state.vel, state.omega
    t = 0.5 * inertia.mass[:, None] * (v.real ** 2 + v.imag ** 2)
    t += omega * cross(world_h, v)
    t += 0.5 * inertia.inertia_origin[:, None] * omega * omega
    return np.sum(t, axis=0)


def body_poses(linkage, state):
    """Return the :class:`BodyPoses` of a solved planar state (3-D, z out of the plane)."""
    pose = state.pose
    n, nb = state.size, linkage.nb
    origin = np.zeros((n, nb, 3))
    origin[:, :, 0], origin[:, :, 1] = pose.origin.real.T, pose.origin.imag.T
    c, s = pose.rot.real.T, pose.rot.imag.T
    rot = np.zeros((n, nb, 3, 3))
    rot[:, :, 0, 0], rot[:, :, 0, 1] = c, -s
    rot[:, :, 1, 0], rot[:, :, 1, 1] = s, c
    rot[:, :, 2, 2] = 1.0
    return BodyPoses(tuple(linkage.body_names), origin, rot)
