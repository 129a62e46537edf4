"""The spatial built-ins in MuJoCo for ``bench --compare mujoco`` (:class:`SpatialMujocoRig`)."""

from mech_balance import schema as scene_mod
from mech_balance.bench.mujoco_model import agreement, agreement_rows, import_mujoco, mjcf, \
    MujocoModel, norms, relative_difference, TIMED, us_rows, worst, xml_numbers
from mech_balance.conventions import cycle_angles
from mech_balance.core.rig import rig_for
from mech_balance.core.spatial import dynamics as sdyn
from mech_balance.core.spatial.kinematics import NEWTON_TOL
from mech_balance.schema.scene import SERIES
import numpy as np

SPATIAL_BUILTINS = ('rggr', 'rggr_spatial', 'rssr_skew', 'rssp_slider', 'spatial_two_loop',
                    'pssr_skew')
"""The spatial built-ins compared (``mech-balance scenes``)."""
NEWTON_MAX_ITER = 10
"""MuJoCo's Newton iterations per angle (stops at the package's NEWTON_TOL, scaled)."""
IDLE_PLACEHOLDER_RTOL = 1e-6
"""Placeholder principal moment (times the trace) compiled for a zero moment."""
ZERO_MOMENT_RTOL = 1e-12
"""A principal moment below this fraction of the trace counts as zero (idle rods)."""


def _quat(mj, rot):
    q = np.empty(4)
    mj.mju_mat2Quat(q, np.ascontiguousarray(rot, dtype=float).ravel())
    return q


def _rotation(mj, quat):
    mat = np.empty(9)
    mj.mju_quat2Mat(mat, quat)
    return mat.reshape(3, 3)


class SpatialMujocoRig(MujocoModel):
    """A spatial rig as a MuJoCo model: its spanning tree plus ``connect`` loop closures."""

    def __init__(self, rig, mj=None):
        self.mj = mj = mj or import_mujoco()
        self.rig = rig
        lk = self.linkage = rig.linkage
        sc = rig.scene
        bad = [sc.joints[ji] for ji in lk.cut_joints if sc.joints[ji].joint_type != 'spherical']
        if bad:
            raise ValueError(
                f'scene {sc.name!r}: the spatial MuJoCo comparison closes loops at spherical '
                f'cut joints only (connect equalities); the spanning tree cuts '
                + ', '.join(f'{j.name} ({j.joint_type})' for j in bad))
        placeholders = []
        self.xml, self.cut_sign = self._mjcf(sc, placeholders)
        self.model = m = mj.MjModel.from_xml_string(self.xml)
        for name, tensor in placeholders:   # zero principal moments (idle freedoms, docs)
            body = m.body(name).id
            frame = _rotation(mj, m.body_iquat[body])
            m.body_inertia[body] = np.maximum(np.diag(frame.T @ tensor @ frame), 0.0)
        self.data = mj.MjData(self.model)
        self.warnings = self._first_inverse()
        self.length = lk.length_scale
        self.inertia_error = self._inertia_error(sc)
        # dof addresses of every tree coordinate (package order), ball blocks by tree joint
        self.tree_jnt = []
        self.dof_of = np.zeros(lk.ndof, dtype=int)
        for i, t in enumerate(lk.tree):
            count = 1 if t.joint_type == 'spherical' else len(t.dofs)
            ids = [m.joint(f't{i}_{k}').id for k in range(count)]
            self.tree_jnt.append(ids)
            if t.joint_type == 'spherical':
                self.dof_of[list(t.dofs)] = m.jnt_dofadr[ids[0]] + np.arange(3)
            else:
                self.dof_of[list(t.dofs)] = [m.jnt_dofadr[j] for j in ids]
        self.crank = int(self.dof_of[0])
        self.passive = np.array([d for d in range(m.nv) if d != self.crank])
        self.crank_qpos = m.jnt_qposadr[self.tree_jnt[0][0]]
        self.tol, self.max_iter = NEWTON_TOL, NEWTON_MAX_ITER
        ncut = len(lk.cut_joints)
        self._find_cuts(ncut)
        self.point = np.array(rig.moment_point_m, dtype=float)
        # the package's spin convention rows: (R_k v) . n = 0 (kinematics docstring)
        self.spins = [(m.body(lk.body_names[int(r.body_b[0])]).id, r.vec_b[0].copy(),
                       r.vec_a[0].copy()) for r in lk.rows if r.form == 'spin']
        self.nrow = 3 * ncut + len(self.spins)
        # per tree joint: name, child body, its root, the body of the scene's link b and its
        # joint point there (the moment's point: C and P joints' two points differ), sign
        self.tree_reactions = []
        for t in lk.tree:
            c = m.body(lk.body_names[t.child]).id
            on_b = (m.body(lk.body_names[t.parent]).id, t.s_parent) if t.flipped else \
                (c, t.s_child)
            self.tree_reactions.append((t.name, c, int(m.body_rootid[c])) + on_b
                                       + (-1.0 if t.flipped else 1.0,))
        self.cut_names = [sc.joints[ji].name for ji in lk.cut_joints]
        self._jacr = np.zeros((3, m.nv))

    def _mjcf(self, sc, placeholders):
        """Return the MJCF and the cut signs; list ``(link, tensor)`` of zero moments."""
        lk = self.linkage
        names = lk.body_names
        body_of = {n: i for i, n in enumerate(names)}
        links = {link.name: link for link in sc.links}

        def site(link, point):
            return xml_numbers(*lk._points[link][point])

        def inertial(name):
            link = links[name]
            tensor = np.array(link.inertia_matrix(), dtype=float)
            values, vectors = np.linalg.eigh(tensor)
            trace = float(np.trace(tensor))
            six = list(link.inertia_com_kg_m2)
            zero = values <= ZERO_MOMENT_RTOL * trace
            if zero.any():
                u = vectors[:, zero]
                t2 = tensor + IDLE_PLACEHOLDER_RTOL * trace * (u @ u.T)
                six = [t2[0, 0], t2[1, 1], t2[2, 2], t2[0, 1], t2[0, 2], t2[1, 2]]
                placeholders.append((name, tensor))
            return (f'<inertial pos="{xml_numbers(*link.com_m)}" '
                    f'mass="{xml_numbers(link.mass_kg)}" fullinertia="{xml_numbers(*six)}"/>')

        def body(i, t):
            if t.joint_type == 'spherical':
                rel, pos, kinds = np.eye(3), t.s_parent - t.s_child, [('ball', None)]
            else:
                rel, pos = t.fixed, t.s_parent - t.fixed @ t.s_child
                local = t.fixed.T @ t.axis
                kinds = {'revolute': [('hinge', local)], 'prismatic': [('slide', local)],
                         'cylindrical': [('hinge', local), ('slide', local)],
                         'universal': [('hinge', local), ('hinge', t.axis_child)]
                         }[t.joint_type]
            joints = [f'<joint name="t{i}_{k}" type="{kind}" pos="{xml_numbers(*t.s_child)}"'
                      + ('' if axis is None else f' axis="{xml_numbers(*axis)}"') + '/>'
                      for k, (kind, axis) in enumerate(kinds)]
            return (f'<body name="{names[t.child]}" pos="{xml_numbers(*pos)}" '
                    f'quat="{xml_numbers(*_quat(self.mj, rel))}">', *joints,
                    inertial(names[t.child]))

        cuts = [sc.joints[ji] for ji in lk.cut_joints]
        return mjcf('mech_balance_spatial', lk, [
            (j.name, body_of[j.link_b], site(j.link_b, j.point_b),
             body_of[j.link_a], site(j.link_a, j.point_a)) for j in cuts], body,
            header=('  <compiler angle="radian"/>',))

    def _first_inverse(self):
        """Run ``mj_inverse`` once at ``qpos0``; return MuJoCo's warnings (caught, not printed)."""
        mj = self.mj
        caught = []
        previous = mj.get_mju_user_warning()
        mj.set_mju_user_warning(caught.append)
        try:
            mj.mj_inverse(self.model, self.data)
        finally:
            mj.set_mju_user_warning(previous)
        return caught

    def _inertia_error(self, sc):
        """Return max |I_MuJoCo - I_scene| / max |I_scene| over the links (link axes)."""
        mj, m = self.mj, self.model
        error = 0.0
        for link in sc.links:
            b = m.body(link.name).id
            frame = _rotation(mj, m.body_iquat[b])
            tensor = frame @ np.diag(m.body_inertia[b]) @ frame.T
            ours = np.array(link.inertia_matrix(), dtype=float)
            error = max(error, float(np.max(np.abs(tensor - ours)) / np.max(np.abs(ours))),
                        abs(float(m.body_mass[b]) - link.mass_kg) / link.mass_kg,
                        float(np.max(np.abs(m.body_ipos[b] - link.com_m))) / self.length)
        return error

    def to_mujoco(self, state):
        """Return ``(qpos (n, nq), qvel (n, nv), qacc (n, nv))`` of a solved package state."""
        mj, m, lk = self.mj, self.model, self.linkage
        n = state.size
        qpos, qvel, qacc = np.zeros((n, m.nq)), np.zeros((n, m.nv)), np.zeros((n, m.nv))
        fr, tw, ac = state.frames, state.twist, state.accel
        si = 0
        for i, t in enumerate(lk.tree):
            ids = self.tree_jnt[i]
            if t.joint_type != 'spherical':
                for k, j in enumerate(ids):
                    d = t.dofs[k]
                    qpos[:, m.jnt_qposadr[j]] = state.q[:, d]
                    qvel[:, m.jnt_dofadr[j]] = state.qd[:, d]
                    qacc[:, m.jnt_dofadr[j]] = state.qdd[:, d]
                continue
            rel = state.sph[:, si]
            si += 1
            adr, dof = m.jnt_qposadr[ids[0]], m.jnt_dofadr[ids[0]]
            for k in range(n):
                qpos[k, adr:adr + 4] = _quat(mj, rel[k])
            rc_t = np.swapaxes(fr.rot[:, t.child], 1, 2)
            wp, w_rel = tw[:, t.parent, :3], tw[:, t.child, :3] - tw[:, t.parent, :3]
            qvel[:, dof:dof + 3] = np.einsum('nij,nj->ni', rc_t, w_rel)
            qacc[:, dof:dof + 3] = np.einsum(
                'nij,nj->ni', rc_t, ac[:, t.child, :3] - ac[:, t.parent, :3]
                - np.cross(wp, w_rel))
        return qpos, qvel, qacc

    def tree_coordinates(self, qpos):
        """Return the package's tree coordinates ``(n, ndof)`` and ball rotations of qpos."""
        mj, m, lk = self.mj, self.model, self.linkage
        n = qpos.shape[0]
        q = np.zeros((n, lk.ndof))
        sph = np.zeros((n, len(lk.sph_index), 3, 3))
        si = 0
        for i, t in enumerate(lk.tree):
            ids = self.tree_jnt[i]
            if t.joint_type != 'spherical':
                for k, j in enumerate(ids):
                    q[:, t.dofs[k]] = qpos[:, m.jnt_qposadr[j]]
                continue
            adr = m.jnt_qposadr[ids[0]]
            for k in range(n):
                quat = qpos[k, adr:adr + 4]
                sph[k, si] = _rotation(mj, quat / np.linalg.norm(quat))
            si += 1
        return q, sph

    def _rigid(self, reactions=False):
        """From ``mj_inverse``'s outputs: torque, multipliers, shaking wrench (docstring)."""
        mj, m, d = self.mj, self.model, self.data
        nefc = d.nefc
        jac = d.efc_J[:nefc * m.nv].reshape(nefc, m.nv)
        gen = d.qfrc_inverse + d.qfrc_constraint
        rows = self._spin_rows(jac) if self.spins else jac
        ju_t = rows[:, self.passive].T
        if ju_t.shape[0] == ju_t.shape[1]:
            sol = np.linalg.solve(ju_t, gen[self.passive])
        else:
            sol = np.linalg.lstsq(ju_t, gen[self.passive], rcond=None)[0]
        lam = sol[:nefc]
        resid = float(np.max(np.abs(sol[nefc:]), initial=0.0))
        tau = float(gen[self.crank] - rows[:, self.crank] @ sol)
        d.efc_force[:nefc] = lam
        d.qfrc_constraint[:] = jac.T @ lam
        mj.mj_rnePostConstraint(m, d)
        cfrc, com, p = d.cfrc_int, d.subtree_com, self.point
        force, moment = np.zeros(3), np.zeros(3)
        for b in self.roots:
            f = cfrc[b, 3:]
            force += f
            moment += cfrc[b, :3] + np.cross(com[b] - p, f)
        for k in self.world_cuts:
            f = lam[3 * k:3 * k + 3]
            force += f
            moment += np.cross(d.site_xpos[self.site1[k]] - p, f)
        out = (tau, lam, -force, -moment, resid)
        if not reactions:
            return out
        react = {}
        for name, c, root, b, point, sign in self.tree_reactions:
            f = cfrc[c, 3:]
            x = d.xpos[b] + d.xmat[b].reshape(3, 3) @ point   # (xanchor: a slide's zero)
            react[name] = (sign * f, sign * (cfrc[c, :3] + np.cross(com[root] - x, f)))
        for k, name in enumerate(self.cut_names):
            react[name] = (self.cut_sign[k] * lam[3 * k:3 * k + 3], np.zeros(3))
        return out + (react,)

    def _spin_rows(self, jac):
        """Return ``efc_J`` with the spin convention's rows below it (rad per dof rate)."""
        mj, m, d = self.mj, self.model, self.data
        rows = np.empty((jac.shape[0] + len(self.spins), m.nv))
        rows[:jac.shape[0]] = jac
        for s, (b, v, nref) in enumerate(self.spins):
            rv = d.xmat[b].reshape(3, 3) @ v
            mj.mj_jacBody(m, d, None, self._jacr, b)
            rows[jac.shape[0] + s] = np.cross(rv, nref) @ self._jacr
        return rows

    def _motion(self):
        """Return the bodies' poses, twists and accelerations (frame origin, world axes)."""
        m, d = self.model, self.data
        ids = [m.body(n).id for n in self.linkage.body_names[1:]]
        ref = d.subtree_com[m.body_rootid[ids]]
        rot = d.xmat[ids].reshape(-1, 3, 3)
        tw = d.cvel[ids].copy()
        tw[:, 3:] -= np.cross(tw[:, :3], ref)
        acc = d.cacc[ids].copy()
        acc[:, 3:] -= np.cross(acc[:, :3], ref)
        return d.xpos[ids].copy(), rot.copy(), tw, acc

    def dynamics(self, state):
        """
        Return MuJoCo's results for the package's motion ``state`` (dict of ``(n, ...)``).

        Keys: ``driving_torque``, ``force``, ``moment``, ``reactions`` (joint -> (force, moment)),
        ``spin_residual`` (N m), ``origin``, ``rot``, ``twist``, ``accel``.
        """
        keys = ('driving_torque', 'force', 'moment', 'spin_residual', 'origin', 'rot', 'twist',
                'accel')
        out = {k: [] for k in keys}
        react = {jt.name: ([], []) for jt in self.linkage.scene.joints}

        def rigid(i):
            tau, _, fsh, nsh, resid, rc = self._rigid(reactions=True)
            for key, val in zip(keys, (tau, fsh, nsh, resid, *self._motion())):
                out[key].append(val)
            for name, (f, mom) in rc.items():
                react[name][0].append(f)
                react[name][1].append(mom)
        self._inverse(*self.to_mujoco(state), rigid)
        out = {k: np.array(v) for k, v in out.items()}
        out['reactions'] = {k: (np.array(f), np.array(mom)) for k, (f, mom) in react.items()}
        return out

    def inverse_rigid(self, qpos, qvel, qacc):
        """``mj_inverse`` plus the rigid multipliers and the shaking wrench (same outputs)."""
        self._inverse(qpos, qvel, qacc, lambda i: self._rigid(reactions=True))

    def _closure(self):
        """Return the closure rows' scaled residual (nrow,) and Jacobian (nrow, nv)."""
        mj, m, d = self.mj, self.model, self.data
        mj.mj_kinematics(m, d)
        mj.mj_comPos(m, d)
        mj.mj_makeConstraint(m, d)
        nc = d.nefc
        r = np.empty(self.nrow)
        r[:nc] = d.efc_pos[:nc] / self.length
        for s, (b, v, nref) in enumerate(self.spins):
            r[nc + s] = (d.xmat[b].reshape(3, 3) @ v) @ nref
        jac = self._spin_rows(d.efc_J[:nc * m.nv].reshape(nc, m.nv) / self.length)
        return r, jac

    def _bias(self, qvel):
        """Return the rows' second derivatives at zero qacc (``Jdot qvel``, scaled)."""
        mj, m, d = self.mj, self.model, self.data
        gam = np.empty(self.nrow)
        for k, (s1, s2, b1, b2) in enumerate(zip(self.site1, self.site2, self.body1,
                                                 self.body2)):
            mj.mj_jacDot(m, d, self._jac1, None, d.site_xpos[s1], b1)
            acc = self._jac1 @ qvel
            if b2:
                mj.mj_jacDot(m, d, self._jac2, None, d.site_xpos[s2], b2)
                acc = acc - self._jac2 @ qvel
            gam[3 * k:3 * k + 3] = acc / self.length
        nc = 3 * len(self.site1)
        for s, (b, v, nref) in enumerate(self.spins):
            rv = d.xmat[b].reshape(3, 3) @ v
            mj.mj_jacBody(m, d, None, self._jacr, b)
            mj.mj_jacDot(m, d, None, self._jac1, d.xpos[b], b)
            w, al = self._jacr @ qvel, self._jac1 @ qvel
            gam[nc + s] = (np.cross(al, rv) + np.cross(w, np.cross(w, rv))) @ nref
        return gam

    def full(self, psi, speed, accel, qpos_start):
        """Return MuJoCo's ``(tau, force, moment, reactions, qpos, residual, iterations)``."""
        p = psi.size
        tau, fsh, nsh = np.empty(p), np.empty((p, 3)), np.empty((p, 3))
        react = {name: (np.empty((p, 3)), np.empty((p, 3))) for name, *_ in
                 self.tree_reactions}
        react.update({name: (np.empty((p, 3)), np.zeros((p, 3))) for name in self.cut_names})

        def rigid(i):
            tau[i], _, fsh[i], nsh[i], _, rc = self._rigid(reactions=True)
            for name, (f, mom) in rc.items():
                react[name][0][i] = f
                react[name][1][i] = mom
        # the input's coordinate and rates at each angle (a prismatic input: its Scotch-yoke
        # slide, Linkage.input_motion); the predictor's slope and curve stay d/dpsi
        coordinate = self.linkage.input_coordinate(psi, speed, accel)
        q, res, iters = self._solution(psi, speed, accel, coordinate, qpos_start, rigid)
        return tau, fsh, nsh, react, q, res, iters


def _fresh_dynamics(rig, state, need):
    """Return the package's inverse dynamics of a solved state, its per-state caches cleared."""
    for key in ('_motion', '_spin'):
        if key in state.__dict__:
            delattr(state, key)
    return sdyn.inverse_dynamics(rig.linkage, state, rig.inertia, rig.moment_point_m, need)


def reaction_differences(ours, theirs):
    """
    Return ``(forces, moments)``: the bearing reactions' worst relative differences.

    Forces to each joint's cycle peak; moments to the largest peak over the joints.
    """
    forces = max(relative_difference(f, theirs[j][0]) for j, (f, _) in ours.items())
    peak = max(float(np.max(norms(mo))) for _, mo in ours.values())
    moments = max(float(np.max(norms(theirs[j][1] - mo))) for j, (_, mo) in ours.items())
    return forces, moments / (peak if peak > 0.0 else 1.0)


def compare(scene, timer, samples=360, repeat=50, slow=10, progress=None, mj=None):
    """
    Return the agreement and timing figures of one spatial scene (name or scene), one process.

    ``timer(fns)``: the median seconds of each ``(function, runs)``; keys as the planar
    :func:`.mujoco.compare`'s, plus the spin residual, inertia check and ``driving_series``.
    """
    sc = scene_mod.load(scene) if isinstance(scene, str) else scene
    sc = sc.with_outputs(scene_mod.OUTPUTS)
    rig = rig_for(sc)
    lk = rig.linkage
    mjr = SpatialMujocoRig(rig, mj)
    psi = cycle_angles(samples, sc.assembly_crank_angle_rad)
    speed, accel = sc.crank_speed_rad_s, sc.crank_acceleration_rad_s2
    need = scene_mod.needs(sc.outputs)
    state, w = rig.evaluate(psi)
    res = mjr.dynamics(state)
    fr = state.frames
    pose = max(float(np.max(np.abs(res['origin'] - fr.origin[:, 1:]))) / lk.length_scale,
               float(np.max(np.abs(res['rot'] - fr.rot[:, 1:]))))
    motion = max(pose, relative_difference(state.twist[:, 1:], res['twist']),
                 relative_difference(state.accel[:, 1:], res['accel']))
    ours = (w.driving_torque, w.force_N, w.moment_Nm)
    imposed = {'joint motion': motion, **agreement(ours, (res['driving_torque'], res['force'],
                                                          res['moment']))}
    if rig.reactions_unique:
        imposed['bearing forces'], imposed['bearing moments'] = reaction_differences(
            w.reactions, res['reactions'])
    qpos, qvel, qacc = mjr.to_mujoco(state)
    tau2, f2, n2, react2, q2, res2, it2 = mjr.full(psi, speed, accel, qpos[0])
    q_own, sph_own = mjr.tree_coordinates(q2)
    scalar = lk.scalar_dofs
    positions = float(np.max(np.abs(q_own[:, scalar] - state.q[:, scalar])
                             / lk.col_scale[scalar]))
    if sph_own.size:
        positions = max(positions, float(np.max(np.abs(sph_own - state.sph))))
    own = {'joint motion': positions, **agreement(ours, (tau2, f2, n2))}
    if rig.reactions_unique:
        own['bearing forces'], own['bearing moments'] = reaction_differences(
            w.reactions, react2)
    out = {
        'scene': sc.name, 'links': len(sc.links), 'joints': len(sc.joints),
        'cuts': tuple(sc.joints[ji].name for ji in lk.cut_joints),
        'idle': tuple(s[0] for s in getattr(lk, 'idle_spins', ())),
        'nv': int(mjr.model.nv), 'samples': samples,
        'agreement_imposed': imposed, 'agreement_own': own,
        'spin_residual': float(np.max(res['spin_residual'])) / max(
            float(np.max(np.abs(w.driving_torque))), 1e-300),
        'inertia_error': mjr.inertia_error,
        'mujoco_residual': float(np.max(res2)), 'mujoco_iterations': float(np.mean(it2)),
        'ours_residual': float(np.max(state.residual)), 'ours_cond': float(np.max(state.cond)),
        'reactions_unique': rig.reactions_unique, 'driving_series': rig.driving_series,
    }
    if progress:
        progress(f'  timing {sc.name} ({len(sc.links)} moving links, spatial) ...')
    fns = [
        (lambda: rig.evaluate(psi), repeat),
        (lambda: _fresh_dynamics(rig, state, need), repeat),
        (lambda: mjr.full(psi, speed, accel, qpos[0]), slow),
        (lambda: mjr.inverse_only(qpos, qvel, qacc), slow),
        (lambda: mjr.inverse_rigid(qpos, qvel, qacc), slow),
    ]
    out['us'] = {n: s * 1e6 / samples for n, s in zip(TIMED, timer(fns))}
    out['repeats'] = (repeat, slow)
    return out


QUANTITIES = ('joint motion', 'driving torque', 'shaking force', 'shaking moment',
              'bearing forces', 'bearing moments')
"""The agreement figures' keys; ``driving torque`` is the driving effort of either kind,
printed as :func:`effort_label` says."""


def effort_label(series):
    """Return the printed name of a rig's driving effort (driving torque or force, SERIES)."""
    return SERIES[series][0]


def format_report(results, tol):
    """Return the printed spatial part of the comparison (one table per built-in)."""
    if not results:
        return ''
    rep, slow = results[0]['repeats']
    lines = [
        '',
        f'spatial built-ins (kind: spatial), {results[0]["samples"]} crank angles per cycle; '
        f'median of {rep} runs (MuJoCo: {slow}), timed in turn',
        "  MuJoCo model: the rig's own spanning tree (hinge, slide, hinge+slide, ball, two "
        'hinges), fullinertia in link',
        '  axes about the mass centre, no gravity (the spatial kind has none); spherical cut '
        'joints closed by connect;',
        "  an S-S coupler's idle spin follows the package's convention (its row (R v).n = 0, "
        'zero inertia about the line)',
        '  joint motion: imposed - MuJoCo body poses, twists, accelerations from the imposed '
        'joints (relative);',
        '  MuJoCo kinematics - its joint coordinates (rad, slides / length scale, ball '
        'rotation matrices) minus ours',
    ]
    for r in results:
        us = r['us']
        idle = ', '.join(r['idle']) or 'none'
        effort = effort_label(r.get('driving_series', 'driving_torque'))
        peak = effort.split()[-1]                     # the spin row's scale: torque or force
        lines += [
            '',
            f'{r["scene"]}: {r["links"]} moving links, {r["joints"]} joints, cut '
            f'{", ".join(r["cuts"])} (connect), idle spin: {idle}; MuJoCo nv {r["nv"]}',
            *agreement_rows(r, QUANTITIES, lambda q: effort if q == 'driving torque' else q),
        ]
        w = worst(r)
        lines += [
            f'  -> {"PASS" if w <= tol else "FAIL"} (worst {w:.1e}, limit {tol:.0e}); '
            f'inertia as compiled {r["inertia_error"]:.1e}; spin-row moment '
            f'{r["spin_residual"]:.1e} of the peak {peak}; MuJoCo Newton residual '
            f'{r["mujoco_residual"]:.1e}, {r["mujoco_iterations"]:.2f} iterations/angle',
            f'  us per crank angle: {"":<4}{"mech_balance":>14}{"MuJoCo":>12}{"ratio":>10}',
            *us_rows(us, 24, 'mj_inverse + rigid + reactions'),
        ]
    w = float(np.max([worst(r) for r in results]))
    lines.append(f'agreement over the {len(results)} spatial built-ins: worst {w:.1e} -> '
                 f'{"PASS" if w <= tol else "FAIL"} (limit {tol:.0e})')
    return '\n'.join(lines)


def run(timer, samples=360, repeat=50, slow=10, progress=print, names=SPATIAL_BUILTINS,
        mj=None):
    """Return :func:`compare` of every spatial built-in (arguments as there)."""
    out = []
    for name in names:
        if progress:
            progress(f'  comparing {name} (spatial) ...')
        out.append(compare(name, timer, samples, repeat, slow, progress, mj))
    return out
