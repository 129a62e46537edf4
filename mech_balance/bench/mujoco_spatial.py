"""
The spatial part of ``mech-balance bench --compare mujoco``: the spatial built-ins in MuJoCo.

The MuJoCo model of a spatial rig (:class:`SpatialMujocoRig`)
    The rig's own spanning tree (:class:`~mech_balance.core.spatial.kinematics.Linkage`,
    breadth first from the frame, crank first): one body per link, its MuJoCo frame *the
    link's own axes* (origin and axes of the scene's link), placed in its tree parent at the
    package's zero of the tree joint (``R = Z``, ``p = s_parent - Z s_child``), the joint at
    the child's joint point.  Revolute: a hinge about ``Z^T a``; prismatic: a slide along
    ``F^T a`` (``F`` the fixed rotation ``Rot(a, angle) Z``); cylindrical: hinge then slide
    about/along ``Z^T a``; universal: two hinges, ``U^T a`` then the child's axis (MuJoCo
    composes a body's joints from the right, ``R = R_p U Rot(U^T a, q1) Rot(b, q2)``, which
    is the package's ``Rot(a, q1) U Rot(b, q2)``); spherical: a ball (quaternion = the
    package's relative rotation).  Every hinge and slide value is then the package's tree
    coordinate itself; a ball's velocity is the relative angular velocity in the child's axes
    (``M^T`` times the package's, which is in the parent's), its acceleration the rate of
    that.  Mass properties: ``inertial`` with ``pos`` = mass centre and ``fullinertia`` =
    the scene's six numbers (link axes, about the mass centre; MuJoCo diagonalizes it).  No
    geoms, no limits, gravity as the scene has it (none: the spatial kind has no gravity).

Cut joints
    The built-ins' trees cut only spherical joints (each loop closes at a ball), so every cut
    joint is a ``connect`` equality between a site on its link b (site 1) and one on its
    link a (site 2) at the joint point.  A scene that cuts any other joint type is refused
    here (its closure would need ``weld``-type rows, not implemented).

Idle freedoms (an S-S coupler's spin about the line through its balls)
    The package fixes the spin by a convention row ``(R v) . n = 0`` and requires the link's
    inertia about the line to be zero (a slender rod).  MuJoCo's compiler refuses a moving
    body with a zero principal moment, so such a link is compiled with a placeholder
    ``fullinertia = I + delta u u^T`` (u the principal axis of the zero moment) and the
    compiled ``body_inertia`` is then set to the scene's tensor in MuJoCo's principal axes
    ``body_iquat`` (which also diagonalize the scene's: u is an eigenvector of both, the
    zero moment comes back exactly); :attr:`inertia_error`
    reports the largest difference between MuJoCo's inertia tensor and the scene's.  The
    mass matrix is then singular in the spin direction, which ``mj_inverse`` does not need
    (``M qacc`` is a product).  With imposed motion the spin is the package's; MuJoCo's own
    kinematics adds the same row (its vectors read from the compiled linkage).

Rigid multipliers, driving effort, reactions, shaking wrench (as the planar comparison)
    ``gen = qfrc_inverse + qfrc_constraint = M qacc + c``; the passive dofs carry no applied
    force, so ``J_u^T lambda = gen_u`` over the passive columns of ``efc_J`` with the spin
    convention's rows below it (square, as the package's system: the spin row's multiplier
    ``mu`` is the moment the convention would have to exert about the S-S line, zero for a
    link without inertia about it; :func:`compare` reports its largest value),
    ``tau = gen_crank - J_crank^T (lambda, mu)``.  ``lambda`` written to ``efc_force``
    feeds ``mj_rnePostConstraint``: ``cfrc_int`` of a body is the wrench on it from its tree
    parent (about the subtree centre of mass of its root), which gives the tree joints'
    reactions (moment moved to the joint point on the scene's link b, as the package
    reports it - a cylindrical or prismatic joint's two points part along its axis, and
    ``xanchor`` is a slide's zero position; negated for a tree joint whose child is the
    scene's link a); the connect forces are the cut joints' reactions.  The load
    on the frame is ``cfrc_int`` of the bodies hinged to the world plus the connect forces of
    cuts to the world; the shaking wrench is its reaction, the moment about the scene's
    ``moment_point_m``.

What is timed, per crank angle (as the planar comparison)
    mech_balance: the full pipeline is :meth:`SpatialRig.evaluate` of all angles at once
    (every output: kinematics, shaking wrench, driving effort, bearing reactions); dynamics
    alone is :func:`~mech_balance.core.spatial.dynamics.inverse_dynamics` of the solved
    state (its per-state caches cleared before each run).  MuJoCo: the full pipeline is a
    Python loop over the angles (Newton on the connect and spin rows from a Taylor
    predictor, velocities, accelerations with ``mj_comVel`` and ``mj_jacDot``,
    ``mj_inverse``, the multipliers, ``mj_rnePostConstraint``, every reaction and the
    frame load); ``mj_inverse`` alone with the package's motion copied in; and the same
    plus the multipliers, reactions and frame load (the same outputs).
"""

from mech_balance import schema as scene_mod
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


def _f(x):
    return repr(float(x))


def _vec(v):
    return ' '.join(_f(x) for x in v)


def _norms(x):
    return np.sqrt(np.sum(np.asarray(x) ** 2, axis=-1))


def relative_difference(ours, theirs):
    """Return max |theirs - ours| / max |ours| over the cycle (3-vectors: Euclidean norms)."""
    ours, theirs = np.asarray(ours, dtype=float), np.asarray(theirs, dtype=float)
    if ours.ndim >= 2 and ours.shape[-1] == 3:
        scale, diff = float(np.max(_norms(ours))), float(np.max(_norms(theirs - ours)))
    else:
        scale, diff = float(np.max(np.abs(ours))), float(np.max(np.abs(theirs - ours)))
    return diff / (scale if scale > 0.0 else 1.0)


def _quat(mj, rot):
    q = np.empty(4)
    mj.mju_mat2Quat(q, np.ascontiguousarray(rot, dtype=float).ravel())
    return q


class SpatialMujocoRig:
    """A spatial rig as a MuJoCo model: its spanning tree plus ``connect`` loop closures."""

    def __init__(self, rig, mj=None):
        if mj is None:
            import mujoco as mj  # the optional dependency (bench.mujoco tells how to get it)
        self.mj = mj
        self.rig = rig
        lk = self.linkage = rig.linkage
        sc = rig.scene
        bad = [sc.joints[ji] for ji in lk.cut_joints if sc.joints[ji].joint_type != 'spherical']
        if bad:
            raise ValueError(
                f'scene {sc.name!r}: the spatial MuJoCo comparison closes loops at spherical '
                f'cut joints only (connect equalities); the spanning tree cuts '
                + ', '.join(f'{j.name} ({j.joint_type})' for j in bad))
        self.xml, placeholders = self._mjcf(sc)
        self.model = mj.MjModel.from_xml_string(self.xml)
        m = self.model
        for name, tensor in placeholders:   # zero principal moments (module docstring)
            body = m.body(name).id
            frame = np.empty(9)
            mj.mju_quat2Mat(frame, m.body_iquat[body])
            frame = frame.reshape(3, 3)
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
        ncut = len(lk.cut_joints)
        self.site1 = [m.site(f'cut{k}_1').id for k in range(ncut)]
        self.site2 = [m.site(f'cut{k}_2').id for k in range(ncut)]
        self.body1 = [int(m.site_bodyid[s]) for s in self.site1]
        self.body2 = [int(m.site_bodyid[s]) for s in self.site2]
        self.roots = [b for b in range(1, m.nbody) if m.body_parentid[b] == 0]
        self.world_cuts = [k for k, b in enumerate(self.body2) if b == 0]
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
        self._jac1 = np.zeros((3, m.nv))
        self._jac2 = np.zeros((3, m.nv))
        self._jacr = np.zeros((3, m.nv))

    # ------------------------------------------------------------------ model

    def _mjcf(self, sc):
        lk = self.linkage
        children = {b: [] for b in range(lk.nb)}
        for i, t in enumerate(lk.tree):
            children[t.parent].append((i, t))
        names = lk.body_names
        sites = {b: [] for b in range(lk.nb)}
        self.cut_sign = []
        body_of = {n: i for i, n in enumerate(names)}
        for k, ji in enumerate(lk.cut_joints):
            jt = sc.joints[ji]
            ends = [(jt.link_b, jt.point_b), (jt.link_a, jt.point_a)]
            if body_of[jt.link_b] == 0:
                ends.reverse()
            self.cut_sign.append(1.0 if ends[0][0] == jt.link_b else -1.0)
            for n, (link, point) in enumerate(ends, start=1):
                pos = lk._points[link][point]
                sites[body_of[link]].append(f'<site name="cut{k}_{n}" pos="{_vec(pos)}"/>')
        links = {lk_.name: lk_ for lk_ in sc.links}
        placeholders = []

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
            return (f'<inertial pos="{_vec(link.com_m)}" mass="{_f(link.mass_kg)}" '
                    f'fullinertia="{_vec(six)}"/>')

        def body(i, t, pad):
            c = t.child
            name = names[c]
            if t.joint_type == 'spherical':
                rel, pos = np.eye(3), t.s_parent - t.s_child
            else:
                rel, pos = t.fixed, t.s_parent - t.fixed @ t.s_child
            quat = _quat(self.mj, rel)
            text = [f'{pad}<body name="{name}" pos="{_vec(pos)}" quat="{_vec(quat)}">']
            jpos = _vec(t.s_child)
            if t.joint_type == 'spherical':
                kinds = [('ball', None)]
            else:
                local = t.fixed.T @ t.axis
                kinds = {'revolute': [('hinge', local)], 'prismatic': [('slide', local)],
                         'cylindrical': [('hinge', local), ('slide', local)],
                         'universal': [('hinge', local), ('hinge', t.axis_child)]
                         }[t.joint_type]
            for k, (kind, axis) in enumerate(kinds):
                ax = '' if axis is None else f' axis="{_vec(axis)}"'
                text.append(f'{pad}  <joint name="t{i}_{k}" type="{kind}" pos="{jpos}"{ax}/>')
            text.append(pad + '  ' + inertial(name))
            text += [pad + '  ' + s for s in sites[c]]
            for i2, t2 in children[c]:
                text += body(i2, t2, pad + '  ')
            return text + [f'{pad}</body>']

        lines = ['<mujoco model="mech_balance_spatial">',
                 '  <compiler angle="radian"/>',
                 '  <option gravity="0 0 0" jacobian="dense"/>',
                 '  <worldbody>']
        lines += ['    ' + s for s in sites[0]]
        for i, t in children[0]:
            lines += body(i, t, '    ')
        lines += ['  </worldbody>', '  <equality>']
        lines += [f'    <connect name="{sc.joints[ji].name}" site1="cut{k}_1" site2="cut{k}_2"/>'
                  for k, ji in enumerate(lk.cut_joints)]
        lines += ['  </equality>', '</mujoco>']
        return '\n'.join(lines), placeholders

    def _first_inverse(self):
        """
        Run ``mj_inverse`` once at ``qpos0``; return MuJoCo's warnings (caught, not printed).

        MuJoCo prints a warning the first time it meets it in an ``MjData``; a zero principal
        moment (idle rod) makes ``mj_factorM`` warn that the mass matrix is singular, which
        the inverse dynamics does not need.  Catching it here keeps the report clean; the
        text is kept in :attr:`warnings`.
        """
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
        worst = 0.0
        for link in sc.links:
            b = m.body(link.name).id
            frame = np.empty(9)
            mj.mju_quat2Mat(frame, m.body_iquat[b])
            frame = frame.reshape(3, 3)
            tensor = frame @ np.diag(m.body_inertia[b]) @ frame.T
            ours = np.array(link.inertia_matrix(), dtype=float)
            worst = max(worst, float(np.max(np.abs(tensor - ours)) / np.max(np.abs(ours))),
                        abs(float(m.body_mass[b]) - link.mass_kg) / link.mass_kg,
                        float(np.max(np.abs(m.body_ipos[b] - link.com_m))) / self.length)
        return worst

    # ------------------------------------------------------------------ the package's motion

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
                mat = np.empty(9)
                mj.mju_quat2Mat(mat, qpos[k, adr:adr + 4] / np.linalg.norm(qpos[k, adr:adr + 4]))
                sph[k, si] = mat.reshape(3, 3)
            si += 1
        return q, sph

    # ------------------------------------------------------------------ rigid inverse dynamics

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

        Keys: ``driving_torque``, ``force``, ``moment``, ``reactions`` (joint -> (force,
        moment)), ``spin_residual`` (the spin rows' largest multiplier, N m), ``origin``,
        ``rot``, ``twist``, ``accel`` (MuJoCo's bodies, for the motion check).
        """
        mj, m, d = self.mj, self.model, self.data
        qpos, qvel, qacc = self.to_mujoco(state)
        n = state.size
        out = {k: [] for k in ('driving_torque', 'force', 'moment', 'spin_residual',
                               'origin', 'rot', 'twist', 'accel')}
        react = {jt.name: ([], []) for jt in self.linkage.scene.joints}
        for i in range(n):
            d.qpos[:], d.qvel[:], d.qacc[:] = qpos[i], qvel[i], qacc[i]
            mj.mj_inverse(m, d)
            tau, _, fsh, nsh, resid, rc = self._rigid(reactions=True)
            for key, val in zip(('driving_torque', 'force', 'moment', 'spin_residual'),
                                (tau, fsh, nsh, resid)):
                out[key].append(val)
            for key, val in zip(('origin', 'rot', 'twist', 'accel'), self._motion()):
                out[key].append(val)
            for name, (f, mom) in rc.items():
                react[name][0].append(f)
                react[name][1].append(mom)
        out = {k: np.array(v) for k, v in out.items()}
        out['reactions'] = {k: (np.array(f), np.array(mom)) for k, (f, mom) in react.items()}
        return out

    def inverse_only(self, qpos, qvel, qacc):
        """Run ``mj_inverse`` at every angle of the ``(n, nq)``/``(n, nv)`` arrays (timed)."""
        mj, m, d = self.mj, self.model, self.data
        for i in range(qpos.shape[0]):
            d.qpos[:], d.qvel[:], d.qacc[:] = qpos[i], qvel[i], qacc[i]
            mj.mj_inverse(m, d)

    def inverse_rigid(self, qpos, qvel, qacc):
        """``mj_inverse`` plus the rigid multipliers and the shaking wrench (same outputs)."""
        mj, m, d = self.mj, self.model, self.data
        for i in range(qpos.shape[0]):
            d.qpos[:], d.qvel[:], d.qacc[:] = qpos[i], qvel[i], qacc[i]
            mj.mj_inverse(m, d)
            self._rigid(reactions=True)

    # ------------------------------------------------------------------ MuJoCo's own motion

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
        """
        Return MuJoCo's own solution over crank angles ``psi``, one angle at a time.

        Newton on the connect and spin rows from a Taylor predictor off the previous angle
        (the first from ``qpos_start``), velocities and accelerations from the same rows,
        ``mj_inverse``, the rigid multipliers and every bearing reaction (the package's
        full cycle computes them too).  Returns ``(tau, force, moment, reactions, qpos,
        residual, iterations)``, ``reactions`` as in :meth:`dynamics`.
        """
        mj, m, d = self.mj, self.model, self.data
        p = psi.size
        crank, passive = self.crank, self.passive
        crank_adr = m.jnt_qposadr[self.tree_jnt[0][0]]
        tau, fsh, nsh = np.empty(p), np.empty((p, 3)), np.empty((p, 3))
        q_out, res_out, iters = np.empty((p, m.nq)), np.empty(p), np.zeros(p, dtype=int)
        qpos = np.array(qpos_start, dtype=float)
        slope, curve, step = np.zeros(m.nv), np.zeros(m.nv), np.zeros(m.nv)
        qvel, qacc = np.zeros(m.nv), np.zeros(m.nv)
        # the input's coordinate and rates at each angle (a prismatic input: its Scotch-yoke
        # slide, Linkage.input_motion); the predictor's slope and curve stay d/dpsi
        x, xd, xdd = (np.broadcast_to(v, psi.shape) for v in
                      self.linkage.input_coordinate(psi, speed, accel))
        react = {name: (np.empty((p, 3)), np.empty((p, 3))) for name, *_ in
                 self.tree_reactions}
        react.update({name: (np.empty((p, 3)), np.zeros((p, 3))) for name in self.cut_names})
        for i in range(p):
            if i:
                h = psi[i] - psi[i - 1]
                step[:] = h * slope + 0.5 * h * h * curve
                step[crank] = 0.0
                mj.mj_integratePos(m, qpos, step, 1.0)
            qpos[crank_adr] = x[i]
            for it in range(NEWTON_MAX_ITER + 1):
                d.qpos[:] = qpos
                r, jac = self._closure()
                res = float(np.max(np.abs(r)))
                if not res > NEWTON_TOL or it == NEWTON_MAX_ITER:
                    break
                step[:] = 0.0
                step[passive] = -np.linalg.solve(jac[:, passive], r)
                mj.mj_integratePos(m, qpos, step, 1.0)
                iters[i] += 1
            res_out[i] = res
            j_u, j_c = jac[:, passive], jac[:, crank]
            qvel[crank], qacc[crank] = xd[i], xdd[i]
            qvel[passive] = np.linalg.solve(j_u, -xd[i] * j_c)
            d.qvel[:] = qvel
            mj.mj_comVel(m, d)
            qacc[passive] = np.linalg.solve(j_u, -xdd[i] * j_c - self._bias(qvel))
            d.qacc[:] = qacc
            mj.mj_inverse(m, d)
            tau[i], _, fsh[i], nsh[i], _, rc = self._rigid(reactions=True)
            for name, (f, mom) in rc.items():
                react[name][0][i] = f
                react[name][1][i] = mom
            q_out[i] = qpos
            slope[:] = qvel / speed
            curve[:] = (qacc - slope * accel) / speed ** 2
        return tau, fsh, nsh, react, q_out, res_out, iters


# ---------------------------------------------------------------------------- comparison


def _fresh_dynamics(rig, state, need):
    """Return the package's inverse dynamics of a solved state, its per-state caches cleared."""
    for key in ('_motion', '_spin'):
        if key in state.__dict__:
            delattr(state, key)
    return sdyn.inverse_dynamics(rig.linkage, state, rig.inertia, rig.moment_point_m, need)


def reaction_differences(ours, theirs):
    """
    Return ``(forces, moments)``: the bearing reactions' worst relative differences.

    Forces: per joint, to that joint's cycle peak.  Moments (about each joint point): to the
    largest peak over the joints (a spherical joint's moment is zero).
    """
    forces = max(relative_difference(f, theirs[j][0]) for j, (f, _) in ours.items())
    peak = max(float(np.max(_norms(mo))) for _, mo in ours.values())
    moments = max(float(np.max(_norms(theirs[j][1] - mo))) for j, (_, mo) in ours.items())
    return forces, moments / (peak if peak > 0.0 else 1.0)


def compare(scene, timer, samples=360, repeat=50, slow=10, progress=None, mj=None):
    """
    Return the agreement and timing figures of one spatial scene (name or scene), one process.

    ``timer(fns)`` returns the median seconds of each ``(function, runs)`` pair, timed in
    turn (the planar comparison's); the package's figures take ``repeat`` runs, MuJoCo's
    ``slow``.

    Keys: ``agreement_imposed`` and ``agreement_own`` (quantity -> worst relative
    difference; ``driving torque`` is the driving effort of either kind), ``positions``
    (MuJoCo's own joint coordinates against the package's: rad, slides / length scale, ball
    rotation matrices), ``us`` (microseconds per angle), the spin residual, the inertia
    check, Newton figures, the counts of the model, and ``driving_series`` (the rig's
    :attr:`~mech_balance.core.rig.Rig.driving_series`, which names the effort printed).
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
    imposed = {'joint motion': motion,
               'driving torque': relative_difference(w.driving_torque, res['driving_torque']),
               'shaking force': relative_difference(w.force_N, res['force']),
               'shaking moment': relative_difference(w.moment_Nm, res['moment'])}
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
    own = {'joint motion': positions,
           'driving torque': relative_difference(w.driving_torque, tau2),
           'shaking force': relative_difference(w.force_N, f2),
           'shaking moment': relative_difference(w.moment_Nm, n2)}
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
    names = ('ours_full', 'ours_dyn', 'mj_full', 'mj_inverse', 'mj_dyn')
    secs = timer(fns)
    out['us'] = {n: s * 1e6 / samples for n, s in zip(names, secs)}
    out['repeats'] = (repeat, slow)
    return out


def worst(r):
    """Return the worst agreement figure of one :func:`compare` result."""
    # np.max, not max: a nan figure is the worst (max() would skip it by order)
    return float(np.max([*r['agreement_imposed'].values(), *r['agreement_own'].values()]))


QUANTITIES = ('joint motion', 'driving torque', 'shaking force', 'shaking moment',
              'bearing forces', 'bearing moments')
"""The agreement figures' keys; ``driving torque`` is the driving effort of either kind,
printed as :func:`effort_label` says."""


def effort_label(series):
    """
    Return the printed name of a rig's driving effort, its series ``series``' label.

    ``series`` is :attr:`~mech_balance.core.rig.Rig.driving_series`: ``driving torque`` for a
    revolute input, ``driving force`` for a prismatic one (:data:`SERIES`).
    """
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
            f'  {"":<18}{"imposed motion":>16}{"MuJoCo kinematics":>20}',
        ]
        for q in QUANTITIES:
            a = r['agreement_imposed'].get(q)
            b = r['agreement_own'].get(q)
            label = effort if q == 'driving torque' else q
            lines.append(f'  {label:<18}' + (f'{a:>16.1e}' if a is not None else
                                             f'{"not unique":>16}' if q.startswith('bearing')
                                             else f'{"-":>16}')
                         + (f'{b:>20.1e}' if b is not None else f'{"-":>20}'))
        w = worst(r)
        lines += [
            f'  -> {"PASS" if w <= tol else "FAIL"} (worst {w:.1e}, limit {tol:.0e}); '
            f'inertia as compiled {r["inertia_error"]:.1e}; spin-row moment '
            f'{r["spin_residual"]:.1e} of the peak {peak}; MuJoCo Newton residual '
            f'{r["mujoco_residual"]:.1e}, {r["mujoco_iterations"]:.2f} iterations/angle',
            f'  us per crank angle: {"":<4}{"mech_balance":>14}{"MuJoCo":>12}{"ratio":>10}',
            f'  {"full pipeline":<24}{us["ours_full"]:>14.3f}{us["mj_full"]:>12.2f}'
            f'{us["mj_full"] / us["ours_full"]:>9.1f}x',
            f'  {"dynamics alone":<24}{us["ours_dyn"]:>14.3f}{us["mj_inverse"]:>12.2f}'
            f'{us["mj_inverse"] / us["ours_dyn"]:>9.1f}x   (mj_inverse)',
            f'  {"dynamics, same outputs":<24}{us["ours_dyn"]:>14.3f}{us["mj_dyn"]:>12.2f}'
            f'{us["mj_dyn"] / us["ours_dyn"]:>9.1f}x   (mj_inverse + rigid + reactions)',
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
