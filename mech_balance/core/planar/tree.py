"""The spanning tree of a planar linkage (breadth first, crank first): cut joints, ancestry."""

from dataclasses import dataclass

from mech_balance.core.planar.algebra import rmat as _rmat, Tiles
import numpy as np

DENSE_TREE_MAX_BODIES = 8
"""Up to this many bodies a sum over the tree is one dense product, above it level by level."""


@dataclass
class _Joint:
    """A joint of the scene (its index) as the spanning tree uses it."""

    joint: int
    name: str
    joint_type: str

    @property
    def prismatic(self):
        """Return whether the joint slides (else it turns)."""
        return self.joint_type == 'prismatic'


@dataclass
class TreeJoint(_Joint):
    """A joint of the spanning tree: ``child`` hangs from ``parent``."""

    parent: int
    child: int
    p_parent: complex
    p_child: complex
    axis: complex
    axis_on_parent: bool
    angle: float


@dataclass
class CutJoint(_Joint):
    """A joint closing a loop: two equations g = 0 between bodies ``a`` and ``b``."""

    a: int
    b: int
    p_a: complex
    p_b: complex
    axis: complex
    angle: float


class SpanningTree:
    """The tree's compiled matrices and its sums (docs/core.md, "Module overviews")."""

    @staticmethod
    def _tree(ji, jt, parent, child, index, pts):
        a_is_parent = index[jt.link_a] == parent
        pa, pb = pts[jt.link_a][jt.point_a], pts[jt.link_b][jt.point_b]
        p_parent, p_child = (pa, pb) if a_is_parent else (pb, pa)
        return TreeJoint(ji, jt.name, jt.joint_type, parent, child, p_parent, p_child,
                         complex(*jt.axis), a_is_parent, jt.angle_rad)

    @staticmethod
    def _cut(ji, jt, ia, ib, pts):
        return CutJoint(ji, jt.name, jt.joint_type, ia, ib, pts[jt.link_a][jt.point_a],
                        pts[jt.link_b][jt.point_b], complex(*jt.axis), jt.angle_rad)

    def _compile(self):
        """Precompute the incidence and ancestry matrices that vectorize over bodies."""
        nb, nt = self.nb, self.nt
        self.par = np.array([tj.parent for tj in self.tree])
        self.ch = np.array([tj.child for tj in self.tree])
        rev = ~self.is_prismatic
        self.anc_rev = np.zeros((nb, nt))
        self.anc_pri = np.zeros((nb, nt))
        for b in range(nb):
            for t in self.anc[b]:
                (self.anc_rev if rev[t] else self.anc_pri)[b, t] = 1.0
        self.anc_all = self.anc_rev + self.anc_pri
        self._compile_levels()
        self.has_pri = bool(self.is_prismatic.any())
        self.p_par = np.array([tj.p_parent for tj in self.tree])[:, None]
        self.p_ch = np.array([tj.p_child for tj in self.tree])[:, None]
        self.axis_local = np.where(self.is_prismatic,
                                   np.array([tj.axis for tj in self.tree]), 0)[:, None]
        self.axis_on_par = np.array([tj.axis_on_parent for tj in self.tree])[:, None]
        offset = np.array([(tj.angle if tj.axis_on_parent else -tj.angle)
                           if tj.prismatic else 0.0 for tj in self.tree])
        self.phi_offset = (self.anc_pri @ offset)[:, None]
        # subtree sums (for the reaction recursion): sub[b, c] = 1 if c hangs below b or is b
        rc = [c for c in self.cuts if not c.prismatic]
        pc = [c for c in self.cuts if c.prismatic]
        self.cuts = rc + pc
        self.nr, self.npc = len(rc), len(pc)
        self.cut_a = np.array([c.a for c in self.cuts], dtype=int)
        self.cut_b = np.array([c.b for c in self.cuts], dtype=int)
        self.cut_pa = np.array([c.p_a for c in self.cuts])[:, None]
        self.cut_pb = np.array([c.p_b for c in self.cuts])[:, None]
        self.cut_ab = np.concatenate([self.cut_a, self.cut_b])
        self.cut_p_ab = np.concatenate([self.cut_pa, self.cut_pb]).astype(complex)
        self.cut_tiles = Tiles(p_ab=self.cut_p_ab)   # (the same, per batch size)
        ncut = len(self.cuts)
        self.cut_inc_a = np.zeros((nb, ncut))
        self.cut_inc_b = np.zeros((nb, ncut))
        self.cut_inc_a[self.cut_a, np.arange(ncut)] = 1.0
        self.cut_inc_b[self.cut_b, np.arange(ncut)] = 1.0
        self.cut_names = [c.name for c in self.cuts]
        self.cut_rounds_a = _rounds(self.cut_a)
        self.cut_rounds_b = _rounds(self.cut_b)
        self.tree_names = [tj.name for tj in self.tree]
        joints = {j.name: j for j in self.scene.joints}
        # reactions are reported as the force on the joint's link b from its link a
        self.tree_sign = np.array([1.0 if joints[tj.name].link_b == self.body_names[tj.child]
                                   else -1.0 for tj in self.tree])
        L = self.length_scale
        self.row_scale = np.concatenate([np.full(2 * self.nr, 1.0 / L),
                                         np.ones(self.npc), np.full(self.npc, 1.0 / L)])
        self.col_scale_all = np.where(self.is_prismatic, L, 1.0)
        self.col_scale = self.col_scale_all[self.unknown]
        # d(point on body b)/dq_t selectors for the cut ends: (ncut, nt)
        self.sel_rev = self.anc_rev[self.cut_b] - self.anc_rev[self.cut_a]
        self.sel_rev_a, self.sel_rev_b = self.anc_rev[self.cut_a], self.anc_rev[self.cut_b]
        self.sel_pri = self.anc_pri[self.cut_b] - self.anc_pri[self.cut_a]
        # the same as broadcastable (ncut, cols, 1) stacks, all columns and unknown ones only
        sel = (self.sel_rev_a, self.sel_rev_b, self.sel_rev)
        self.sel_rev_a3, self.sel_rev_b3, self.sel_rev3 = (
            np.ascontiguousarray(x[:, :, None]) for x in sel)
        self.sel_rev_a_u, self.sel_rev_b_u, self.sel_rev_u = (
            np.ascontiguousarray(x[:, self.unknown, None]) for x in sel)
        # all-revolute loops: the Jacobian's structural nonzeros (cut c, tree joint t) are
        # differences of two points of S = [pa; pb; J]: pb - J_t (t above b only), J_t - pa
        # (t above a only) or pb - pa (above both); i times that is the entry
        ncut = len(self.cuts)
        nz = []
        for c in range(ncut):
            for t in range(nt):
                above_b, above_a = self.anc_rev[self.cut_b[c], t], self.anc_rev[self.cut_a[c], t]
                if above_b and above_a:
                    nz.append((c, t, ncut + c, c))
                elif above_b:
                    nz.append((c, t, ncut + c, 2 * ncut + t))
                elif above_a:
                    nz.append((c, t, 2 * ncut + t, c))
        nz = np.array(nz, dtype=int).reshape(-1, 4)
        unk = nz[:, 1] > 0
        self.jac_nz = (nz[:, 0], nz[:, 1], nz[:, 2], nz[:, 3])
        self.jac_nz_u = (nz[unk, 0], nz[unk, 1] - 1, nz[unk, 2], nz[unk, 3])
        # the same, unknown columns first, then the crank column (values + J_psi in one go)
        order = np.concatenate([np.flatnonzero(unk), np.flatnonzero(~unk)])
        n_unk = int(unk.sum())
        self.jac_nz_split = (nz[unk, 0], nz[unk, 1] - 1, nz[order, 2], nz[order, 3], n_unk,
                             nz[~unk, 0])
        # the crank column's x and y rows as slices where a range, and whether they are all rows
        self.crank_row_slices = _as_slices(nz[~unk, 0], self.nr)
        self.crank_rows_all = bool(self.crank_row_slices) and \
            np.array_equal(np.sort(nz[~unk, 0]), np.arange(self.nr)) and not self.npc
        self.cut_angle = np.array([c.angle for c in self.cuts[self.nr:]])[:, None]
        self.cut_axis = np.array([c.axis for c in self.cuts[self.nr:]], dtype=complex)[:, None]
        # reaction recursion: bodies below each tree joint, and the cut loads summed over them
        self.below = np.ascontiguousarray(self.anc_all.T)                  # (nt, nb)
        self.minus_ones = np.full(self.nb, -1.0)   # minus the sum over the bodies
        self.below_cut_a = self.below @ self.cut_inc_a                     # (nt, ncut)
        self.below_cut_b = self.below @ self.cut_inc_b
        self.below_cut = self.below_cut_b - self.below_cut_a
        rev = ~self.is_prismatic
        rev[0] = False
        self.rev_passive = np.flatnonzero(rev)     # revolute tree joints other than the crank
        # the rows of the consistency figure: the crank's, then those (a slice if a range)
        self.check_rows = np.concatenate([[0], self.rev_passive]).astype(np.intp)
        self.rev_passive_rows = (_as_slices(self.rev_passive, 0) or (self.rev_passive,))[0]
        # the first row scale and its negative as 0-d arrays (quicker ufunc operands than scalars)
        first = float(self.row_scale[0]) if self.row_scale.size else 1.0
        self.scale0, self.neg_scale0 = np.array(first), np.array(-first)
        self.tree_flip = np.flatnonzero(self.tree_sign < 0)  # reported from child to parent
        self.tree_sign_col = self.tree_sign[:, None]
        rows = {n: (True, t) for t, n in enumerate(self.tree_names)}
        rows.update({n: (False, c) for c, n in enumerate(self.cut_names)})
        self.joint_rows = [(n, *rows[n]) for n in self.joint_names]

    def _compile_levels(self):
        """Precompute the tree's levels for ``_down`` (ancestor) and ``_up`` (subtree) sums."""
        nb, nt = self.nb, self.nt
        self.dense_tree = nb <= DENSE_TREE_MAX_BODIES
        joint_of_body = [nt] * nb                 # nt: the frame (a zero row)
        for t, tj in enumerate(self.tree):
            joint_of_body[tj.child] = t
        self.joint_of_body = np.array(joint_of_body)
        parent = [joint_of_body[tj.parent] for tj in self.tree]   # nt: hangs from the frame
        depth = [0] * nb
        for tj in self.tree:
            depth[tj.child] = depth[tj.parent] + 1
        by_depth = {}
        for t, tj in enumerate(self.tree):
            by_depth.setdefault(depth[tj.child], []).append(t)
        self.levels = []                          # (first joint, end, parent joints) per depth
        self.up_rounds = []                       # (children, parents) deepest first
        for d in sorted(by_depth):
            ts = by_depth[d]
            if ts != list(range(ts[0], ts[-1] + 1)):
                raise AssertionError('spanning tree is not breadth-first')  # pragma: no cover
            self.levels.append((ts[0], ts[-1] + 1, np.array([parent[t] for t in ts])))
        for d in sorted(by_depth, reverse=True):
            if d == 1:
                continue
            pending = list(by_depth[d])
            while pending:
                seen, now, later = set(), [], []
                for t in pending:
                    (later if parent[t] in seen else now).append(t)
                    seen.add(parent[t])
                self.up_rounds.append((np.array(now), np.array([parent[t] for t in now])))
                pending = later
        self.rev_col = (~self.is_prismatic).astype(float)[:, None]

    def _down(self, v):
        """Return ``(nb, ...)``: per body the sum of ``v`` ``(nt, ...)`` over the joints above."""
        if self.dense_tree:
            return _rmat(self.anc_all, v) if v.dtype == np.complex128 else self.anc_all @ v
        s = np.empty((self.nt + 1,) + v.shape[1:], dtype=v.dtype)
        s[self.nt] = 0.0
        start, end, _ = self.levels[0]
        s[start:end] = v[start:end]
        for start, end, parents in self.levels[1:]:
            np.add(s.take(parents, axis=0), v[start:end], out=s[start:end])
        return s.take(self.joint_of_body, axis=0)   # (take: quicker than an index array)

    def _down_rev(self, v):
        """Return :meth:`_down` over the revolute joints only (the link angles and rates)."""
        if self.dense_tree:
            return self.anc_rev @ v
        return self._down(v * self.rev_col if self.has_pri else v)

    def _up(self, x):
        """Return ``(nt, ...)``: per tree joint the sum of ``x`` ``(nb, ...)`` below it."""
        if self.dense_tree:
            if np.iscomplexobj(x):
                return _rmat(self.below, x)
            return self.below @ x
        sub = x.take(self.ch, axis=0)
        for kids, parents in self.up_rounds:
            sub[parents] += sub.take(kids, axis=0)
        return sub

    def _up_cut(self, load_b, load_a):
        """Return per tree joint the sum of cut loads on the bodies below it (b minus a)."""
        if self.dense_tree:
            if np.iscomplexobj(load_b):
                return _rmat(self.below_cut_b, load_b) - _rmat(self.below_cut_a, load_a)
            return self.below_cut_b @ load_b - self.below_cut_a @ load_a
        x = np.zeros((self.nb,) + load_b.shape[1:], dtype=load_b.dtype)
        for cuts, bodies in self.cut_rounds_b:
            x[bodies] += load_b.take(cuts, axis=0)
        for cuts, bodies in self.cut_rounds_a:
            x[bodies] -= load_a.take(cuts, axis=0)
        return self._up(x)

    def _jacobian_pattern(self):
        """Return the structural nonzeros ``(m, nu)`` of the loop Jacobian's unknown columns."""
        touched = (self.anc_all[self.cut_a] + self.anc_all[self.cut_b]) != 0  # (ncut, nt)
        nr = self.nr
        rows = [touched[:nr], touched[:nr], touched[nr:], touched[nr:]]
        return np.concatenate(rows)[:, self.unknown]


def _as_slices(rows, shift):
    """Return ``(slice of rows, slice of rows + shift)`` if ``rows`` is a range, else ``()``."""
    rows = np.asarray(rows)
    if rows.size and np.array_equal(rows, np.arange(rows[0], rows[0] + rows.size)):
        lo, hi = int(rows[0]), int(rows[0]) + rows.size
        return slice(lo, hi), slice(lo + shift, hi + shift)
    return ()


def _rounds(targets):
    """Return ``[(items, targets)]``: the items in rounds whose targets are distinct."""
    pending = list(range(len(targets)))
    out = []
    while pending:
        seen, now, later = set(), [], []
        for i in pending:
            (later if int(targets[i]) in seen else now).append(i)
            seen.add(int(targets[i]))
        out.append((np.array(now, dtype=int), np.array([targets[i] for i in now], dtype=int)))
        pending = later
    return out
