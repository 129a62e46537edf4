"""The MuJoCo side the planar and spatial comparisons share (``bench --compare mujoco``)."""

import numpy as np

MUJOCO_PIN = '4.0.0'
"""The MuJoCo version the comparison was written and checked against."""
INSTALL_HINT = (f'mech-balance bench --compare mujoco: the optional benchmark dependency '
                f'"mujoco" is not installed; install it with `make bench-mujoco` (or '
                f'`pip install mujoco=={MUJOCO_PIN}`)')
WRENCH = ('driving torque', 'shaking force', 'shaking moment')
"""The agreement figures of both kinds (``driving torque``: the driving effort of either)."""
TIMED = ('ours_full', 'ours_dyn', 'mj_full', 'mj_inverse', 'mj_dyn')
"""The timed figures of a comparison, in the order of its functions (docs/benchmarks.md)."""


class MujocoMissing(RuntimeError):
    """MuJoCo is not installed."""


def import_mujoco():
    """Return the :mod:`mujoco` module or raise :class:`MujocoMissing`."""
    try:
        import mujoco
    except ImportError as exc:
        raise MujocoMissing(INSTALL_HINT) from exc
    return mujoco


def solve(a, b):
    """Return the solution of a small dense system (Cramer's rule for 2 x 2, else LAPACK)."""
    if a.shape[0] == 2:
        (a00, a01), (a10, a11) = a.tolist()
        b0, b1 = b.tolist()
        det = a00 * a11 - a01 * a10
        return np.array([(a11 * b0 - a01 * b1) / det, (a00 * b1 - a10 * b0) / det])
    return np.linalg.solve(a, b)


def xml_numbers(*values):
    """Return numbers as MJCF text, exactly (``repr`` of each, space-separated)."""
    return ' '.join(repr(float(x)) for x in values)


def relative_difference(ours, theirs):
    """Return max |theirs - ours| / max |ours| over the cycle (vectors by their norms)."""
    ours, theirs = np.asarray(ours), np.asarray(theirs)
    if ours.ndim >= 2 and ours.shape[-1] == 3 and not np.iscomplexobj(ours):
        size = norms
    else:
        size = np.abs
    scale = float(np.max(size(ours)))
    return float(np.max(size(theirs - ours))) / (scale if scale > 0.0 else 1.0)


def norms(x):
    """Return the Euclidean norms of a stack of vectors (the last axis)."""
    return np.sqrt(np.sum(np.asarray(x) ** 2, axis=-1))


def agreement(ours, theirs):
    """Return ``{quantity: relative difference}`` of the driving effort and shaking wrench."""
    return dict(zip(WRENCH, map(relative_difference, ours, theirs)))


def worst(r):
    """Return the worst agreement figure of one comparison (planar or spatial)."""
    # np.max, not max: a nan figure is the worst (max() would skip it by order)
    return float(np.max([*r['agreement_imposed'].values(), *r['agreement_own'].values()]))


def agreement_rows(r, quantities=WRENCH, label=str):
    """Return the agreement table of one comparison: a header, a row per quantity."""
    rows = [f'  {"":<18}{"imposed motion":>16}{"MuJoCo kinematics":>20}']
    for q in quantities:
        a, b = r['agreement_imposed'].get(q), r['agreement_own'].get(q)
        missing = 'not unique' if q.startswith('bearing') else '-'
        rows.append(f'  {label(q):<18}' + (f'{a:>16.1e}' if a is not None else f'{missing:>16}')
                    + (f'{b:>20.1e}' if b is not None else f'{"-":>20}'))
    return rows


def us_rows(us, width, same_outputs):
    """Return the printed rows of microseconds per crank angle, both engines and their ratio."""
    rows = (('full pipeline', 'ours_full', 'mj_full', ''),
            ('dynamics alone', 'ours_dyn', 'mj_inverse', '   (mj_inverse)'),
            ('dynamics, same outputs', 'ours_dyn', 'mj_dyn', f'   ({same_outputs})'))
    return [f'  {label:<{width}}{us[ours]:>14.3f}{us[mj]:>12.2f}{us[mj] / us[ours]:>9.1f}x{note}'
            for label, ours, mj, note in rows]


def mjcf(name, linkage, cut_ends, body, header=()):
    """
    Return ``(MJCF text, cut signs)``: a spanning tree closed by ``connect`` equalities.

    ``cut_ends``: per cut joint ``(name, body b, site on b, body a, on a)``; ``body(t,
    tree_joint)``: the child body's opening tag, joint and inertial elements.
    """
    sites = {b: [] for b in range(linkage.nb)}
    signs = []
    for k, (_, b, pos_b, a, pos_a) in enumerate(cut_ends):
        signs.append(1.0 if b else -1.0)
        ends = [(b, pos_b), (a, pos_a)] if b else [(a, pos_a), (b, pos_b)]
        for n, (on, pos) in enumerate(ends, start=1):
            sites[on].append(f'<site name="cut{k}_{n}" pos="{pos}"/>')
    children = {b: [] for b in range(linkage.nb)}
    for t, tj in enumerate(linkage.tree):
        children[tj.parent].append((t, tj))

    def below(parent, pad):
        lines = [pad + s for s in sites[parent]]
        for t, tj in children[parent]:
            head, *inner = body(t, tj)
            lines += [pad + head, *(pad + '  ' + s for s in inner),
                      *below(tj.child, pad + '  '), pad + '</body>']
        return lines

    lines = [f'<mujoco model="{name}">', *header,
             '  <option gravity="0 0 0" jacobian="dense"/>', '  <worldbody>',
             *below(0, '    '), '  </worldbody>', '  <equality>']
    lines += [f'    <connect name="{cut[0]}" site1="cut{k}_1" site2="cut{k}_2"/>'
              for k, cut in enumerate(cut_ends)]
    return '\n'.join(lines + ['  </equality>', '</mujoco>']), signs


class MujocoModel:
    """
    What the planar and the spatial MuJoCo models share: the cut sites, MuJoCo's own motion.

    Subclasses give ``crank``, ``crank_qpos``, ``passive``, ``tol``, ``max_iter``,
    :meth:`_closure` and :meth:`_bias`.
    """

    def _find_cuts(self, ncut):
        """Look up the cut sites and their bodies, and the bodies hinged to the world."""
        m = self.model
        self.site1 = [m.site(f'cut{k}_1').id for k in range(ncut)]
        self.site2 = [m.site(f'cut{k}_2').id for k in range(ncut)]
        self.body1 = [int(m.site_bodyid[s]) for s in self.site1]
        self.body2 = [int(m.site_bodyid[s]) for s in self.site2]
        self.roots = [b for b in range(1, m.nbody) if m.body_parentid[b] == 0]
        self.world_cuts = [k for k, b in enumerate(self.body2) if b == 0]
        self._jac1 = np.zeros((3, m.nv))
        self._jac2 = np.zeros((3, m.nv))

    def _solution(self, psi, speed, accel, coordinate, qpos, rigid):
        """Return MuJoCo's ``(qpos (p, nq), residual (p,), Newton iterations (p,))``."""
        mj, m, d = self.mj, self.model, self.data
        p = psi.size
        crank, passive = self.crank, self.passive
        q_out, res_out, iters = np.empty((p, m.nq)), np.empty(p), np.zeros(p, dtype=int)
        qpos = np.array(qpos, dtype=float)
        slope, curve, step = np.zeros(m.nv), np.zeros(m.nv), np.zeros(m.nv)
        qvel, qacc = np.zeros(m.nv), np.zeros(m.nv)
        x, xd, xdd = (np.broadcast_to(v, psi.shape) for v in coordinate)
        for i in range(p):
            if i:
                h = psi[i] - psi[i - 1]
                step[:] = h * slope + 0.5 * h * h * curve
                step[crank] = 0.0
                mj.mj_integratePos(m, qpos, step, 1.0)
            qpos[self.crank_qpos] = x[i]
            for it in range(self.max_iter + 1):
                d.qpos[:] = qpos
                r, jac = self._closure()
                res = max(map(abs, r.tolist()))
                if not res > self.tol or it == self.max_iter:
                    break
                step[:] = 0.0
                step[passive] = -solve(jac[:, passive], r)
                mj.mj_integratePos(m, qpos, step, 1.0)
                iters[i] += 1
            res_out[i] = res
            j_u, j_c = jac[:, passive], jac[:, crank]
            qvel[crank], qacc[crank] = xd[i], xdd[i]
            qvel[passive] = solve(j_u, -xd[i] * j_c)
            d.qvel[:] = qvel
            mj.mj_comVel(m, d)
            qacc[passive] = solve(j_u, -xdd[i] * j_c - self._bias(qvel))
            d.qacc[:] = qacc
            mj.mj_inverse(m, d)
            rigid(i)
            q_out[i] = qpos
            slope[:] = qvel / speed             # dq/dpsi and d2q/dpsi2 for the predictor
            curve[:] = (qacc - slope * accel) / speed ** 2
        return q_out, res_out, iters

    def _inverse(self, qpos, qvel, qacc, rigid):
        """Run ``mj_inverse`` and then ``rigid(i)`` at every angle of the dof arrays."""
        mj, m, d = self.mj, self.model, self.data
        for i in range(qpos.shape[0]):
            d.qpos[:], d.qvel[:], d.qacc[:] = qpos[i], qvel[i], qacc[i]
            mj.mj_inverse(m, d)
            rigid(i)

    def inverse_only(self, qpos, qvel, qacc):
        """Run ``mj_inverse`` at every angle of ``(p, nq)``/``(p, nv)`` arrays (timed)."""
        mj, m, d = self.mj, self.model, self.data
        for i in range(qpos.shape[0]):
            d.qpos[:], d.qvel[:], d.qacc[:] = qpos[i], qvel[i], qacc[i]
            mj.mj_inverse(m, d)
