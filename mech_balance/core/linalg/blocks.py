"""Closed-form factors of block lower triangular matrices with 2 x 2 blocks (dyad Jacobians)."""

import contextlib
import math

from mech_balance.core.linalg.ordering import inversions
import numpy as np

_NO_ERRSTATE = contextlib.nullcontext()   # (reusable: it keeps no state)
_TINY_DET = 1e-150
"""Smallest |det| of a 2 x 2 block inverted without an errstate (its inverse stays finite)."""
_MAX = np.maximum.reduce


class BlockPlan:
    """
    A block lower triangular pattern with 2 x 2 diagonal blocks (a linkage of RRR dyads).

    ``rows``, ``cols`` list the structural nonzeros in the order a matrix's values come in;
    ``blocks`` the diagonal blocks ``((row, row), (col, col))`` in dependency order.  Raises
    ``ValueError`` if the pattern is not of that form.
    """

    def __init__(self, k, rows, cols, blocks):
        rows, cols = np.asarray(rows, dtype=int), np.asarray(cols, dtype=int)
        self.k, self.n = k, rows.size
        self.blocks = [(tuple(int(r) for r in rs), tuple(int(c) for c in cs))
                       for rs, cs in blocks]
        where_row = {r: (i, a) for i, (rs, _) in enumerate(self.blocks) for a, r in enumerate(rs)}
        where_col = {c: (i, b) for i, (_, cs) in enumerate(self.blocks) for b, c in enumerate(cs)}
        if sorted(where_row) != list(range(k)) or sorted(where_col) != list(range(k)):
            raise ValueError('blocks: every row and column must lie in exactly one block')
        nb = len(self.blocks)
        diag = np.full((2, 2, nb), -1)
        self.off = [([], []) for _ in range(nb)]      # per block row: (entry, col) earlier
        self.off_t = [([], []) for _ in range(nb)]    # per block column: (entry, row) later
        for e, (r, c) in enumerate(zip(rows.tolist(), cols.tolist())):
            (i, a), (j, b) = where_row[r], where_col[c]
            if i == j:
                diag[a, b, i] = e
            elif j < i:
                self.off[i][a].append((e, c))
                self.off_t[j][b].append((e, r))
            else:
                raise ValueError('rows, cols: an entry lies above the diagonal blocks')
        if np.any(diag < 0):
            raise ValueError('rows, cols: a diagonal block entry is missing')
        # (4, nb): entries of [[a, b], [c, d]] per block, and of its adjugate [[d, b], [c, a]]
        self.diag = diag.reshape(4, nb)
        self.adj = self.diag[[3, 1, 2, 0]]
        self.row_order = [r for rs, _ in self.blocks for r in rs]
        self.col_order = [c for _, cs in self.blocks for c in cs]
        self.perm_sign = -1.0 if (inversions(self.row_order)
                                  + inversions(self.col_order)) % 2 else 1.0
        self.entries = (rows, cols)
        # Z = J^-1 (columns in block row order): block i's rows reach back to its dependencies
        reach = []
        for i in range(nb):
            lo = 2 * i
            for a in (0, 1):
                for _, c in self.off[i][a]:
                    lo = min(lo, reach[where_col[c][0]])
            reach.append(lo)
        self.reach = reach                            # first Z column of each block's rows
        # per block: the earlier columns its rows reach, (col, entry row 0, entry row 1,
        # first and end Z column of that column's row), None where a row has no entry
        self.off_cols = []
        for i in range(nb):
            by_col = {}
            for a in (0, 1):
                for e, c in self.off[i][a]:
                    by_col.setdefault(c, [None, None])[a] = e
            cols_i = []
            for c, (e0, e1) in sorted(by_col.items()):
                j = where_col[c][0]
                cols_i.append((c, e0, e1, reach[j], 2 * j + 2))
            self.off_cols.append(cols_i)
        # column sums of |J| (its 1-norm): the entries of each column, padded (k, w)
        counts = np.bincount(cols, minlength=k)
        pad = np.full((k, int(counts.max())), rows.size)
        fill = [0] * k
        for e, c in enumerate(cols.tolist()):
            pad[c, fill[c]] = e
            fill[c] += 1
        self.col_pad = pad
        self.single = nb == 1 and rows.size == 4        # one dyad: closed form throughout
        # the (block, earlier column) pairs in block order, their entries (rows.size: none)
        pairs = [(i, c, e0, e1) for i in range(nb) for c, e0, e1, _, _ in self.off_cols[i]]
        pad = rows.size
        self.pair_block = np.array([q[0] for q in pairs], dtype=int)
        self.pair_entries = np.array([[pad if q[2] is None else q[2] for q in pairs],
                                      [pad if q[3] is None else q[3] for q in pairs]],
                                     dtype=int).reshape(2, -1)
        starts = np.searchsorted(self.pair_block, np.arange(nb + 1))
        self.block_pairs = [[(int(q), pairs[q][1]) for q in range(starts[i], starts[i + 1])]
                            for i in range(nb)]
        # each block reads one earlier unknown at most: the condition number in linear time
        self.tree_like = all(len(self.off_cols[i]) <= 1 for i in range(nb))
        # the solves take block j's two unknowns as (``flat``) rows 2 j, 2 j + 1: the column
        # of each flat row, and the flat row of each column
        self.col_of_flat = np.array([cs[a] for _, cs in self.blocks for a in (0, 1)],
                                    dtype=np.intp)
        self.flat_of_col = np.argsort(self.col_of_flat).astype(np.intp)
        # BlockFactored.solve: block i's rows -= w_q x[flat f] (f: the earlier unknown c);
        # solve_t, from the last block back: z[flat f] -= w_q . block i's rows
        self.forward = [(i, q, 2 * where_col[c][0] + where_col[c][1])
                        for i in range(nb) for q, c in self.block_pairs[i]]
        self.backward = [(i, q, f) for i, q, f in reversed(self.forward)]
        self.tree_edges = [(q, (i, where_col[c][1], where_col[c][0]))
                           for i in range(nb - 1, -1, -1) for q, c in self.block_pairs[i]]
        self.rows01 = np.array([[rs[0] for rs, _ in self.blocks],
                                [rs[1] for rs, _ in self.blocks]], dtype=int)
        if self.single:
            # inv holds D^-1 = [[0, 1], [2, 3]] in block order (col j, row a); J^-1[c, r] of
            # the original order is D^-1[position of c, position of r]
            (r0, r1), (c0, c1) = self.blocks[0]
            pos_r, pos_c = {r0: 0, r1: 1}, {c0: 0, c1: 1}
            self.inv_at = [[2 * pos_c[c] + pos_r[r] for r in (0, 1)] for c in (0, 1)]
            (a, b), (c, d) = self.inv_at
            # BlockFactored._solve_2: the inverse's columns (and its transpose's) as views
            self.column_slices = ((_pair(a, c), _pair(b, d)), (_pair(a, b), _pair(c, d)))


def _pair(i, j):
    """Return the index of ``stack[[i, j], 0]`` as a view: a slice of step ``j - i``."""
    step = j - i
    stop = j + (1 if step > 0 else -1)
    return slice(i, stop if stop >= 0 else None, step), 0


class BlockFactored:
    """The closed-form ``J = D (I + N)`` of a :class:`BlockPlan` matrix (as :class:`Factored`)."""

    def __init__(self, plan, values):
        self.plan, self.values = plan, values
        self.k, self.p = plan.k, values.shape[1]
        dv = values.take(plan.diag, axis=0)            # (4, nb, p): a, b, c, d
        det = dv[0] * dv[3]
        det -= dv[1] * dv[2]
        self.det = det
        self._inv = self._pair_weights = self._pair_weight_rows = None
        adet = np.abs(det)
        # clean: every block well away from singular, so nothing below can divide by zero,
        # overflow or meet inf and nan (no errstate needed: a third of the cost)
        self.clean = np.count_nonzero(adet >= _TINY_DET) == adet.size
        if self.clean:
            self._factor(values, dv, adet)
        else:                                # singular somewhere (or nan): inf and nan there
            with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
                self._factor(values, dv, adet)

    def _factor(self, values, dv, adet):
        """Set the inverted blocks, the weights and (one block) the condition numbers."""
        plan, det = self.plan, self.det
        inv = values.take(plan.adj, axis=0)        # d, b, c, a
        inv /= det
        np.negative(inv[1:3], out=inv[1:3])        # d, -b, -c, a over det
        self.inv = inv
        self.weights = None
        self._cond = self._single_cond(dv[:, 0], adet[0], self.clean) if plan.single else None
        if not plan.single and plan.pair_block.size:
            padded = np.empty((plan.n + 1, self.p))
            padded[:-1] = values
            padded[-1] = 0.0
            v0 = padded.take(plan.pair_entries[0], axis=0)
            v1 = padded.take(plan.pair_entries[1], axis=0)
            ip = inv.take(plan.pair_block, axis=1)    # (4, pairs, p)
            # pair-major (pairs, 2, p): each pair's two weights one contiguous (2, p) block
            w = np.empty((v0.shape[0], 2, v0.shape[1])).transpose(1, 0, 2)
            np.multiply(ip[0], v0, out=w[0])
            w[0] += ip[1] * v1
            np.multiply(ip[2], v0, out=w[1])
            w[1] += ip[3] * v1
            self.weights = w                           # (2, pairs, p): D_i^-1 J_ic

    def _solve_2(self, rhs, transposed):
        """Return the solution of a single 2 x 2 system (or of its transpose)."""
        # the inverse's two columns, each a (2, p) view: x = col0 rhs0 + col1 rhs1
        s0, s1 = self.plan.column_slices[transposed]
        inv = self.inv
        x = np.multiply(inv[s0], rhs[0])
        x += np.multiply(inv[s1], rhs[1])
        return x

    def solve(self, rhs):
        """Return ``x`` ``(k, p)`` with ``mat x = rhs``: ``(I + N) x = D^-1 rhs``."""
        rhs = np.asarray(rhs, dtype=float)
        if self.plan.single:
            return self._solve_2(rhs, False)
        plan, p = self.plan, rhs.shape[1]
        with self._quiet():
            inv = self.inv
            r0, r1 = rhs.take(plan.rows01[0], axis=0), rhs.take(plan.rows01[1], axis=0)
            xb = np.empty((len(plan.blocks), 2, p))       # block order: D^-1 rhs
            y = np.multiply(inv[0], r0, out=xb[:, 0])
            y += inv[1] * r1
            y = np.multiply(inv[2], r0, out=xb[:, 1])
            y += inv[3] * r1
            blocks, flat, w = list(xb), list(xb.reshape(self.k, p)), self.pair_weight_rows
            tmp = np.empty((2, p))
            t0, t1 = tmp
            # (I + N) x = D^-1 rhs, block by block (each product of one shape: a broadcast
            # would take numpy's general iterator, slower than the two)
            for i, q, f in plan.forward:
                (w0, w1), xf = w[q], flat[f]
                np.multiply(w0, xf, out=t0)
                np.multiply(w1, xf, out=t1)
                np.subtract(blocks[i], tmp, out=blocks[i])
        return xb.reshape(self.k, p).take(plan.flat_of_col, axis=0)

    def solve_t(self, rhs):
        """Return ``x`` ``(k, p)`` with ``mat^T x = rhs``: ``(I + N^T) z = rhs``, ``D^T x = z``."""
        rhs = np.asarray(rhs, dtype=float)
        if self.plan.single:
            return self._solve_2(rhs, True)
        inv, plan, p = self.inv, self.plan, rhs.shape[1]
        zb = rhs.take(plan.col_of_flat, axis=0).reshape(len(plan.blocks), 2, p)   # blocks
        with self._quiet():
            blocks, flat, w = list(zb), list(zb.reshape(self.k, p)), self.pair_weights
            tmp, t = np.empty((2, p)), np.empty(p)
            for i, q, f in plan.backward:                # from the last block back
                np.multiply(w[q], blocks[i], out=tmp)
                np.add(tmp[0], tmp[1], out=t)
                np.subtract(flat[f], t, out=flat[f])
            z0, z1 = zb[:, 0], zb[:, 1]
            x = np.empty((self.k, p))
            y = inv[0] * z0                             # D^-T = [[d, -c], [-b, a]] / det
            y += inv[2] * z1
            x[plan.rows01[0]] = y
            np.multiply(inv[1], z0, out=y)
            y += inv[3] * z1
            x[plan.rows01[1]] = y
        return x

    def _quiet(self):
        """Return an errstate for inf and nan where a block is singular, else a no-op."""
        return _NO_ERRSTATE if self.clean else np.errstate(invalid='ignore', over='ignore')

    @property
    def pair_weight_rows(self):
        """Return each pair's weights as a tuple of two ``(p,)`` row views (made once)."""
        if self._pair_weight_rows is None:
            self._pair_weight_rows = [tuple(pw) for pw in self.pair_weights]
        return self._pair_weight_rows

    @property
    def pair_weights(self):
        """Return each pair's weights ``(w_0, w_1)`` as a list of ``(2, p)`` views (made once)."""
        if self._pair_weights is None:
            self._pair_weights = list(self.weights.transpose(1, 0, 2))
        return self._pair_weights

    def _inverse_blocks(self, colsum=None):
        """Return ``Z = J^-1`` in block row order (``colsum``: add the column sums of ``|Z|``)."""
        k, p = self.k, self.p
        z = np.empty((k, k, p)) if colsum is not None else np.zeros((k, k, p))
        tmp = np.empty((k, p))
        m = np.empty((2, p))
        with np.errstate(invalid='ignore', over='ignore'):   # singular blocks: inf, nan
            self._fill_z(z, tmp, m, colsum)
        return z

    def _fill_z(self, z, tmp, m, colsum):
        """Fill in the rows of ``Z`` block by block (:meth:`_inverse_blocks`)."""
        plan, inv = self.plan, self.inv
        for i, (_, (c0, c1)) in enumerate(plan.blocks):
            lo, own = plan.reach[i], 2 * i
            z[c0, own], z[c0, own + 1] = inv[0, i], inv[1, i]
            z[c1, own], z[c1, own + 1] = inv[2, i], inv[3, i]
            cols = plan.off_cols[i]
            covered = len(cols) == 1 and cols[0][3] == lo and cols[0][4] == own
            if lo < own and not covered:
                z[c0, lo:own] = 0.0
                z[c1, lo:own] = 0.0
            for (q, c), (_, _, _, clo, chi) in zip(plan.block_pairs[i], cols):
                np.negative(self.weights[:, q], out=m)   # the weights of row c of Z
                src = z[c, clo:chi]
                for row, ci in ((0, c0), (1, c1)):
                    if covered:
                        np.multiply(m[row], src, out=z[ci, clo:chi])
                    else:
                        z[ci, clo:chi] += np.multiply(m[row], src, out=tmp[:chi - clo])
            if colsum is not None:
                b = own + 2
                colsum[lo:b] += np.abs(z[c0, lo:b], out=tmp[:b - lo])
                colsum[lo:b] += np.abs(z[c1, lo:b], out=tmp[:b - lo])

    @staticmethod
    def _single_cond(entries, adet, checked=False):
        """Return the 1-norm condition numbers of one 2 x 2 block (caller's errstate)."""
        m = np.abs(entries)
        sums = np.empty((2, 2, m.shape[1]))   # (column sums, row sums): one maximum
        np.add(m[:2], m[2:], out=sums[0])   # |a| + |c|, |b| + |d|: the column sums
        np.add(m[::2], m[1::2], out=sums[1])   # |a| + |b|, |c| + |d|: those of the adjugate
        norms = np.maximum(sums[:, 0], sums[:, 1])
        n1 = np.multiply(norms[0], norms[1])
        n1 /= adet
        if not checked and math.isnan(n1.dot(n1)):   # (a dot product: one pass finds a nan)
            n1[np.isnan(n1)] = np.inf       # 0/0: singular (x/0 is inf already)
        return n1

    def cond(self):
        """Return the exact 1-norm condition numbers ``(p,)`` (``inf`` where singular)."""
        if self._cond is None:
            plan = self.plan
            mags = np.empty((plan.n + 1, self.p))
            np.abs(self.values, out=mags[:-1])
            mags[-1] = 0.0
            norm = _MAX(np.add.reduce(mags.take(plan.col_pad, axis=0), axis=1), axis=0)
            if plan.tree_like:
                norm_inv = self._norm_inv_tree()
            else:
                colsum = np.zeros((self.k, self.p))
                self._inverse_blocks(colsum)
                norm_inv = colsum.max(axis=0)
            with np.errstate(invalid='ignore'):
                cond = norm * norm_inv
            self._cond = np.where(np.isfinite(cond), cond, np.inf)
        return self._cond

    def _norm_inv_tree(self):
        """Return ``||J^-1||_1`` ``(p,)`` in linear time: each block reads one earlier unknown."""
        plan = self.plan
        nb = len(plan.blocks)
        ub = np.ones((nb, 2, self.p))                     # 1 + U per unknown, block order
        u = ub.transpose(1, 0, 2)                         # (2, nb, p)
        with self._quiet():
            if self.weights is not None:
                aw = list(np.abs(self.weights.transpose(1, 0, 2)))   # per pair (2, p)
                blocks, flat = list(ub), list(ub.reshape(self.k, self.p))
                tmp, t = np.empty((2, self.p)), np.empty(self.p)
                for q, (child, row, parent) in plan.tree_edges:
                    # sum over the child's own rows and everything below them, per |Z[row]|
                    np.multiply(aw[q], blocks[child], out=tmp)
                    np.add(tmp[0], tmp[1], out=t)
                    dst = flat[2 * parent + row]
                    np.add(dst, t, out=dst)
            ai = np.abs(self.inv)                          # (4, nb, p): |D^-1| entries
            col0 = ai[0] * u[0]
            col0 += ai[2] * u[1]
            col1 = ai[1] * u[0]
            col1 += ai[3] * u[1]
            np.maximum(col0, col1, out=col0)
        return col0.max(axis=0)

    def sign(self):
        """Return the signs of the determinants ``(p,)``."""
        if self.det.shape[0] == 1:   # one block: no product to form
            sign = np.sign(self.det[0])
            return sign if self.plan.perm_sign > 0.0 else np.negative(sign, out=sign)
        return np.prod(np.sign(self.det), axis=0) * self.plan.perm_sign

    def inverse(self):
        """Return ``(inv, cond)``: the ``(k, k, p)`` inverses and 1-norm condition numbers."""
        if self._inv is None:
            z = self._inverse_blocks()
            inv = np.empty_like(z)
            inv[:, self.plan.row_order] = z           # Z's columns are in block row order
            self._inv = inv
        return self._inv, self.cond()

    @property
    def mat(self):
        """Return the dense ``(k, k, p)`` stack."""
        rows, cols = self.plan.entries
        mat = np.zeros((self.k, self.k, self.p))
        mat[rows, cols] = self.values
        return mat
