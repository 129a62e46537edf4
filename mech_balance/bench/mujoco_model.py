"""
The MuJoCo side that the planar and the spatial comparisons share (``bench --compare mujoco``).

Installing and importing :mod:`mujoco`, the MJCF of a spanning tree closed by ``connect``
equalities, the cut sites and the timed ``mj_inverse`` kernel, and the agreement figures
and printed rows of both (docs/benchmarks.md#the-mujoco-models-in-detail).
"""

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


def xml_numbers(*values):
    """Return numbers as MJCF text, exactly (``repr`` of each, space-separated)."""
    return ' '.join(repr(float(x)) for x in values)


def relative_difference(ours, theirs):
    """
    Return max |theirs - ours| / max |ours| over the cycle.

    Complex numbers (planar vectors) by their moduli, real stacks of 3-vectors by their
    Euclidean norms.
    """
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

    ``cut_ends``: per cut joint ``(name, body b, site position on b, body a, on a)``, tree
    body indices and MJCF positions; site 1 goes on the moving end (b, unless b is the frame:
    sign -1).  ``body(t, tree_joint)`` returns the child body's opening tag, then its joint
    and inertial elements.
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
    """What the planar and the spatial MuJoCo models share: the cut sites, the timed kernel."""

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

    def inverse_only(self, qpos, qvel, qacc):
        """Run ``mj_inverse`` at every angle of ``(p, nq)``/``(p, nv)`` arrays (timed)."""
        mj, m, d = self.mj, self.model, self.data
        for i in range(qpos.shape[0]):
            d.qpos[:], d.qvel[:], d.qacc[:] = qpos[i], qvel[i], qacc[i]
            mj.mj_inverse(m, d)
