"""
Batched solves and inverses of many small matrices, batch on the last axis.

``numpy.linalg`` on a stack of 2x2 matrices costs about half a microsecond per matrix
(per-matrix LAPACK call overhead), which alone would exceed the per-angle budget of the
cycle analysis.  Here a stack is stored batch-last, ``(k, k, p)``, so every elementary
operation is one vectorized numpy call over all p angles:

* k <= 2: closed form;
* k > 2: an LU factorization with a *static* row order (partial pivoting on one
  representative matrix, :func:`pivot_order`) over a fixed sparsity pattern
  (:class:`LUPlan`): the loop Jacobian of a linkage has the same zero pattern at every crank
  angle, so the elimination and its fill-in are worked out once and each factorization or
  triangular solve is a short fixed sequence of vectorized updates on the nonzeros only.
  Its cost grows with the number of nonzeros, not with k^3 as dense elimination does.
  :func:`solve` (Newton steps) never forms an inverse; :func:`inverse` (for the exact 1-norm
  condition number and the cut-joint multipliers) builds it from the factors, touching only
  the column ranges of ``L^-1`` and ``U^-1 L^-1`` that can be nonzero.  Matrices whose
  static pivots turn out small are handed to LAPACK (partial pivoting).

Order (:func:`block_triangular_order`, worked out once per pattern)
    Rows and columns are permuted to the block lower triangular form of the pattern
    (Dulmage-Mendelsohn: a perfect matching of rows to columns, then the strongly connected
    components of the matched dependency graph in dependency order), and the static pivots
    are chosen inside each diagonal block only.  For a linkage the diagonal blocks are its
    Assur groups (a chain of four-bars: one 2 x 2 block per loop), so the factors have no
    fill outside the blocks and the numeric work grows linearly with the number of loops
    instead of with the fill-in of one global pivot order (quadratic for a chain).
"""

import contextlib
import math

from mech_balance.core.planar.algebra import matvec as _matvec, matvec_t as _matvec_t, \
    max_reduce as _MAX
import numpy as np

_NO_ERRSTATE = contextlib.nullcontext()   # (reusable: it keeps no state)
_MINUS_ONE = np.array(-1.0)   # (0-d: quicker as a ufunc operand than a Python scalar)
_TINY_DET = 1e-150
"""Smallest |det| of a 2 x 2 block inverted without an errstate (its inverse stays finite)."""
PIVOT_FLOOR = 1e-300
"""A pivot smaller than this (in magnitude) is treated as exactly singular."""
STATIC_PIVOT_RATIO = 1e-3
"""A static pivot smaller than this times its column's largest entry triggers LAPACK."""


def pivot_order(mat):
    """
    Return a row order for elimination without row swaps, from one ``(k, k)`` matrix.

    Partial pivoting on a representative matrix (e.g. the loop Jacobian at the assembly
    position); the same sparsity pattern makes the order good over the whole cycle, and
    the factorization falls back to LAPACK wherever it is not.
    """
    a = np.array(mat, dtype=float)
    k = a.shape[0]
    rows = list(range(k))
    for j in range(k):
        i = j + int(np.argmax(np.abs(a[j:, j])))
        a[[j, i]] = a[[i, j]]
        rows[j], rows[i] = rows[i], rows[j]
        if a[j, j] != 0.0:
            a[j + 1:] -= np.outer(a[j + 1:, j] / a[j, j], a[j])
    return np.array(rows)


def block_triangular_order(pattern, mat):
    """
    Return ``(row_order, col_order)``: a block lower triangular form with in-block pivots.

    ``pattern`` (bool ``(k, k)``) holds every entry that can be nonzero, ``mat`` is one
    representative matrix (its magnitudes choose the matching and the pivots).  The matched
    rows of the diagonal blocks come in dependency order (a block only needs the unknowns of
    the blocks before it); inside a block the rows follow partial pivoting on ``mat``.
    Returns ``None`` if the pattern has no perfect matching (structurally singular).
    """
    pattern = np.asarray(pattern, dtype=bool)
    mat = np.asarray(mat, dtype=float)
    a = np.abs(mat)
    k = pattern.shape[0]
    cols_of = [sorted(np.flatnonzero(pattern[i]).tolist(), key=lambda j: -a[i, j])
               for i in range(k)]
    row_of = [-1] * k                      # column -> matched row

    def augment(row, seen):                # Kuhn's augmenting path, largest entries first
        for c in cols_of[row]:
            if c not in seen:
                seen.add(c)
                if row_of[c] < 0 or augment(row_of[c], seen):
                    row_of[c] = row
                    return True
        return False

    for r in range(k):
        if not augment(r, set()):
            return None
    # dependency graph on columns: column c (its matched row) needs the other columns of the row
    needs = [[j for j in np.flatnonzero(pattern[row_of[c]]).tolist() if j != c]
             for c in range(k)]
    blocks = _tarjan(needs)                # dependencies first
    row_order, col_order = [], []
    for block in blocks:
        rows = [row_of[c] for c in block]
        sub = mat[np.ix_(rows, block)]
        order = pivot_order(sub) if len(block) > 1 else [0]
        row_order += [rows[i] for i in order]
        col_order += list(block)
    return np.array(row_order), np.array(col_order)


def _tarjan(needs):
    """Return the strongly connected components of a graph, every dependency first."""
    n = len(needs)
    index, low, on_stack = [-1] * n, [0] * n, [False] * n
    stack, out, counter = [], [], [0]
    for root in range(n):
        if index[root] >= 0:
            continue
        work = [(root, 0)]
        while work:
            v, i = work.pop()
            if i == 0:
                index[v] = low[v] = counter[0]
                counter[0] += 1
                stack.append(v)
                on_stack[v] = True
            recurse = False
            for j in range(i, len(needs[v])):
                w = needs[v][j]
                if index[w] < 0:
                    work.append((v, j + 1))
                    work.append((w, 0))
                    recurse = True
                    break
                if on_stack[w]:
                    low[v] = min(low[v], index[w])
            if recurse:
                continue
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack[w] = False
                    comp.append(w)
                    if w == v:
                        break
                out.append(sorted(comp))
            if work:
                u = work[-1][0]
                low[u] = min(low[u], low[v])
    return out


class LUPlan:
    """
    The symbolic LU factorization of a ``(k, k)`` sparsity pattern in a static order.

    ``pattern`` (bool ``(k, k)``, original order) must contain every entry that can be
    nonzero; ``row_order`` is the static pivot order (:func:`pivot_order`) and ``col_order``
    an optional column order (:func:`block_triangular_order` gives both): the factors are
    those of ``mat[row_order][:, col_order]``.  They are stored as one ``(nnz, p)`` array
    of the nonzeros of L (unit diagonal, not stored) and U, fill-in included; the index
    lists below drive the numeric phase.
    """

    def __init__(self, pattern, row_order=None, col_order=None):
        pattern = np.asarray(pattern, dtype=bool)
        k = pattern.shape[0]
        if pattern.shape != (k, k):
            raise ValueError(f'pattern: got shape {pattern.shape}, expected (k, k)')
        self.k = k
        self.row_order = np.arange(k) if row_order is None else np.asarray(row_order)
        self.col_order = np.arange(k) if col_order is None else np.asarray(col_order)
        self.natural_cols = bool(np.array_equal(self.col_order, np.arange(k)))
        a = pattern[np.ix_(self.row_order, self.col_order)] | np.eye(k, dtype=bool)
        for j in range(k):  # symbolic elimination: row i gains row j's pattern
            rows = np.flatnonzero(a[j + 1:, j]) + j + 1
            a[np.ix_(rows, np.arange(j, k))] |= a[j, j:]
        rr, cc = np.nonzero(a)
        self.nnz = rr.size
        slot = np.full((k, k), -1)
        slot[rr, cc] = np.arange(self.nnz)
        self.src_row = self.row_order[rr]   # where each stored entry comes from in mat
        self.src_col = self.col_order[cc]
        self.diag = slot[np.arange(k), np.arange(k)]
        self.l_rows, self.l_idx, self.u_cols, self.u_idx, self.update = [], [], [], [], []
        for j in range(k):
            rows = np.flatnonzero(a[j + 1:, j]) + j + 1
            cols = np.flatnonzero(a[j, j + 1:]) + j + 1
            self.l_rows.append(rows)
            self.l_idx.append(slot[j + 1:, j][rows - j - 1])
            self.u_cols.append(cols)
            self.u_idx.append(slot[j, cols])
            self.update.append(slot[np.ix_(rows, cols)].ravel())
        # triangular solves as plain row updates (slices, no gathers): per pivot j the
        # (row, slot) pairs of L's column j and of U's row j
        self.l_pairs = [list(zip(r.tolist(), i.tolist())) for r, i in
                        zip(self.l_rows, self.l_idx)]
        self.u_pairs = [list(zip(c.tolist(), i.tolist())) for c, i in
                        zip(self.u_cols, self.u_idx)]
        self.diag_list = self.diag.tolist()
        self.pivot_col = self.col_order.tolist()   # original column of each pivot
        # inverse: Z = U^-1 L^-1 (pivot order), whose row j is nonzero only in columns
        # lo[j]..hi[j]: L^-1 row i spans env[i]..i, and U^-1 mixes in the rows below
        env = list(range(k))
        for j in range(k):
            for i in self.l_rows[j].tolist():
                env[i] = min(env[i], env[j])
        lo, hi = env[:], list(range(k))
        for j in range(k - 1, -1, -1):
            for c in self.u_cols[j].tolist():
                lo[j], hi[j] = min(lo[j], lo[c]), max(hi[j], hi[c])
        self.env, self.z_lo, self.z_hi = env, lo, hi
        self.perm_sign = -1.0 if (_inversions(self.row_order)
                                  + _inversions(self.col_order)) % 2 else 1.0
        self._slot = slot
        self._pivot_row = np.argsort(self.row_order)     # original row -> pivot position
        self._pivot_pos = np.argsort(self.col_order)     # original column -> pivot position
        self.entries = None

    def set_entries(self, rows, cols):
        """
        Fix the order in which :class:`Factored` gets the nonzeros of a matrix.

        ``rows``, ``cols`` (original indices, every structural nonzero once): a matrix is
        then passed as its ``(len(rows), p)`` values, never as a dense ``(k, k, p)`` stack.
        """
        rows, cols = np.asarray(rows, dtype=int), np.asarray(cols, dtype=int)
        pr, pc = self._pivot_row[rows], self._pivot_pos[cols]
        slots = self._slot[pr, pc]
        if np.any(slots < 0):
            raise ValueError("rows, cols: an entry lies outside the plan's pattern")
        self.entries = (rows, cols)
        self.entry_slot = slots
        by_col = np.argsort(pc, kind='stable')     # entries grouped by pivot column
        self.entry_by_col = by_col
        counts = np.bincount(pc, minlength=self.k)
        if np.any(counts == 0):
            raise ValueError('rows, cols: a column has no entry (structurally singular)')
        self.entry_col_start = np.concatenate([[0], np.cumsum(counts)[:-1]])
        # the entries of each pivot column, padded with a zero entry (index len(rows)): (k, w)
        width = int(counts.max())
        pad = np.full((self.k, width), rows.size)
        for j in range(self.k):
            own = by_col[self.entry_col_start[j]:self.entry_col_start[j] + counts[j]]
            pad[j, :own.size] = own
        self.entry_col_pad = pad


def _inversions(order):
    """Return the number of inversions of a permutation (its sign's parity)."""
    order = [int(i) for i in order]
    return sum(1 for i in range(len(order)) for j in range(i + 1, len(order))
               if order[i] > order[j])


def factor(mat, plan):
    """
    Return ``(lu, weak)``: the ``(nnz, p)`` LU nonzeros of a ``(k, k, p)`` stack and a mask.

    ``weak`` ``(p,)`` marks the matrices whose static pivots are small (or zero): their
    factors are not used (:func:`solve` and :func:`inverse` go to LAPACK for them).
    """
    p = mat.shape[2]
    lu = mat[plan.src_row, plan.src_col]           # (nnz, p), a copy
    col_max = np.max(np.abs(mat), axis=0)          # (k, p): largest entry of each column
    weak = np.zeros(p, dtype=bool)
    with np.errstate(divide='ignore', invalid='ignore'):  # weak matrices are redone
        for j in range(plan.k):
            pivot = lu[plan.diag_list[j]]
            weak |= ~(np.abs(pivot) > STATIC_PIVOT_RATIO * col_max[plan.pivot_col[j]])
            li = plan.l_idx[j]
            if li.size:
                low = lu[li] / pivot
                lu[li] = low
                ui = plan.u_idx[j]
                if ui.size:
                    lu[plan.update[j]] -= (low[:, None, :] * lu[ui][None, :, :]).reshape(-1, p)
    return lu, weak


def factor_values(values, plan):
    """Return ``(lu, weak)`` like :func:`factor`, from the nonzeros (``set_entries``)."""
    p = values.shape[1]
    if plan.nnz == values.shape[0] and np.array_equal(plan.entry_slot, np.arange(plan.nnz)):
        lu = values.copy()
    else:
        lu = np.zeros((plan.nnz, p))
        lu[plan.entry_slot] = values
    mags = np.empty((values.shape[0] + 1, p))     # |entries| and a zero row for the padding
    np.abs(values, out=mags[:-1])
    mags[-1] = 0.0
    col_mags = mags[plan.entry_col_pad]            # (k, width, p), pivot column order
    col_max = col_mags.max(axis=1)
    weak = np.zeros(p, dtype=bool)
    with np.errstate(divide='ignore', invalid='ignore'):  # weak matrices are redone
        for j in range(plan.k):
            pivot = lu[plan.diag_list[j]]
            weak |= ~(np.abs(pivot) > STATIC_PIVOT_RATIO * col_max[j])
            li = plan.l_idx[j]
            if li.size:
                low = lu[li] / pivot
                lu[li] = low
                ui = plan.u_idx[j]
                if ui.size:
                    lu[plan.update[j]] -= (low[:, None, :] * lu[ui][None, :, :]).reshape(-1, p)
    return lu, weak, col_mags


def dense_from_values(values, plan):
    """Return the ``(k, k, p)`` stack of the nonzeros ``values`` (:meth:`LUPlan.set_entries`)."""
    rows, cols = plan.entries
    mat = np.zeros((plan.k, plan.k, values.shape[1]))
    mat[rows, cols] = values
    return mat


def _substitute(lu, plan, y):
    """Solve L U x = y in place for ``y`` ``(k, p)`` (pivot row order in, pivot column out)."""
    tmp = np.empty(y.shape[1:])
    with np.errstate(divide='ignore', invalid='ignore'):  # singular: nan, reported by cond
        for j, pairs in enumerate(plan.l_pairs):
            yj = y[j]
            for i, slot in pairs:
                y[i] -= np.multiply(lu[slot], yj, out=tmp)
        for j in range(plan.k - 1, -1, -1):
            yj = y[j]
            for c, slot in plan.u_pairs[j]:
                yj -= np.multiply(lu[slot], y[c], out=tmp)
            yj /= lu[plan.diag_list[j]]
    return y


def _substitute_t(lu, plan, y):
    """Solve (L U)^T x = y in place (pivot column order in, pivot row order out)."""
    tmp = np.empty(y.shape[1:])
    with np.errstate(divide='ignore', invalid='ignore'):
        for j in range(plan.k):                      # U^T: lower triangular, by columns
            yj = y[j]
            yj /= lu[plan.diag_list[j]]
            for c, slot in plan.u_pairs[j]:
                y[c] -= np.multiply(lu[slot], yj, out=tmp)
        for j in range(plan.k - 1, -1, -1):          # L^T: unit upper triangular, by rows
            yj = y[j]
            for i, slot in plan.l_pairs[j]:
                yj -= np.multiply(lu[slot], y[i], out=tmp)
    return y


def _inverse_z(lu, plan, p, colsum=None):
    """
    Return ``Z = U^-1 L^-1`` ``(k, k, p)`` from the factors, on nonzero ranges only.

    With ``colsum`` ``(k, p)`` (zeros), also the column sums of ``|Z|`` (the 1-norm), each
    row added as soon as it is final, on its nonzero range only; the entries of ``Z``
    outside the ranges are then left unset (the returned array is scratch).
    """
    k = plan.k
    lo, hi = plan.z_lo, plan.z_hi
    if colsum is None:
        z = np.zeros((k, k, p))
    else:                      # only the ranges are ever read or written: zero just those
        z = np.empty((k, k, p))
        for j in range(k):
            z[j, lo[j]:hi[j] + 1] = 0.0
    z[np.arange(k), np.arange(k)] = 1.0
    tmp = np.empty((k, p))
    env = plan.env
    with np.errstate(divide='ignore', invalid='ignore'):
        for j, pairs in enumerate(plan.l_pairs):     # Z <- L^-1 (lower triangular)
            a = env[j]
            zj = z[j, a:j + 1]
            t = tmp[:j + 1 - a]
            for i, slot in pairs:
                z[i, a:j + 1] -= np.multiply(lu[slot], zj, out=t)
        for j in range(k - 1, -1, -1):               # Z <- U^-1 Z
            zj = z[j]
            for c, slot in plan.u_pairs[j]:
                a, b = lo[c], hi[c] + 1
                zj[a:b] -= np.multiply(lu[slot], z[c, a:b], out=tmp[:b - a])
            a, b = lo[j], hi[j] + 1
            zj[a:b] /= lu[plan.diag_list[j]]
            if colsum is not None:
                colsum[a:b] += np.abs(zj[a:b], out=tmp[:b - a])
    return z


def _inverse_lu(lu, plan, p):
    """Return the ``(k, k, p)`` inverse of the original matrix from the factors."""
    z = _inverse_z(lu, plan, p)
    inv = np.empty_like(z)
    if plan.natural_cols:
        inv[:, plan.row_order] = z                   # J^-1 = Z P
    else:
        inv[np.ix_(plan.col_order, plan.row_order)] = z   # J^-1 = Q Z P
    return inv


class Factored:
    """
    One factorization of a batch-last stack ``(k, k, p)``, reused for every solve.

    k <= 2 in closed form (the inverse itself); larger k by the static-order sparse LU of
    ``plan`` (an :class:`LUPlan`, a static row order, or ``None`` for a dense plan), with
    LAPACK for the matrices whose static pivots are weak.  :meth:`solve` and
    :meth:`solve_t` never form the inverse; :meth:`inverse` (for the exact 1-norm condition
    number) builds it once.  Singular matrices give ``nan``/``inf`` entries.
    """

    def __init__(self, mat, plan=None, values=None):
        self._inv = self._cond = self._sign = self._norm = None
        if values is not None:         # the nonzeros in the order of plan.set_entries
            if not isinstance(plan, LUPlan) or plan.entries is None:
                raise ValueError('plan: values need an LUPlan with set_entries')
            self._mat, self.values, self.plan = None, values, plan
            self.k, self.p = plan.k, values.shape[1]
            self.lu, self.weak, self._col_mags = factor_values(values, plan)
            self.any_weak = bool(self.weak.any())
            return
        mat = np.asarray(mat, dtype=float)
        if mat.ndim != 3 or mat.shape[0] != mat.shape[1]:
            raise ValueError(f'mat: got shape {mat.shape}, expected (k, k, p)')
        self._mat = mat
        self.k, _, self.p = mat.shape
        if self.k == 2:
            self._inv, self._cond, det = _inverse_2(mat)
            self._sign = np.sign(det)
        elif self.k == 1:
            with np.errstate(divide='ignore', invalid='ignore'):
                self._inv = 1.0 / mat
            self._sign = np.sign(mat[0, 0])
        elif self.k == 0:  # no unknowns (an open chain): empty, perfectly conditioned
            self._inv, self._cond, self._sign = np.zeros((0, 0, self.p)), np.ones(self.p), \
                np.ones(self.p)
        else:
            self.plan = _plan_for(self.k, plan)
            self.lu, self.weak = factor(mat, self.plan)
            self.any_weak = bool(self.weak.any())

    def solve(self, rhs):
        """Return ``x`` ``(k, p)`` with ``mat x = rhs``."""
        rhs = np.asarray(rhs, dtype=float)
        if self.k <= 2:
            return _matvec(self._inv, rhs)
        plan = self.plan
        y = _substitute(self.lu, plan, rhs[plan.row_order])
        if plan.natural_cols:
            x = y
        else:
            x = np.empty_like(y)
            x[plan.col_order] = y
        if self.any_weak:
            w = self.weak
            x[:, w] = _lapack(self._weak_mat(), rhs[:, w])
        return x

    @property
    def mat(self):
        """Return the dense ``(k, k, p)`` stack (built from the nonzeros if given so)."""
        if self._mat is None:
            self._mat = dense_from_values(self.values, self.plan)
        return self._mat

    def _weak_mat(self):
        """Return the dense matrices of the weak angles only."""
        if self._mat is None:
            return dense_from_values(self.values[:, self.weak], self.plan)
        return self._mat[:, :, self.weak]

    def solve_t(self, rhs):
        """Return ``x`` ``(k, p)`` with ``mat^T x = rhs``."""
        rhs = np.asarray(rhs, dtype=float)
        if self.k <= 2:
            return _matvec_t(self._inv, rhs)
        plan = self.plan
        y = _substitute_t(self.lu, plan, rhs[plan.col_order])
        x = np.empty_like(y)
        x[plan.row_order] = y
        if self.any_weak:
            w = self.weak
            x[:, w] = _lapack(self._weak_mat().transpose(1, 0, 2), rhs[:, w])
        return x

    def inverse(self):
        """Return ``(inv, cond)``: the ``(k, k, p)`` inverses and 1-norm condition numbers."""
        if self._inv is None:
            z = self._z()
            inv = np.empty_like(z)
            if self.plan.natural_cols:
                inv[:, self.plan.row_order] = z              # J^-1 = Z P
            else:
                inv[np.ix_(self.plan.col_order, self.plan.row_order)] = z   # J^-1 = Q Z P
            self._inv = inv
        return self._inv, self.cond()

    def _z(self):
        """Return the inverse in pivot order, ``Z = (P J Q)^-1`` (LAPACK where weak)."""
        if getattr(self, '_zinv', None) is None:
            z = _inverse_z(self.lu, self.plan, self.p)
            if self.any_weak:
                fixed = np.moveaxis(_lapack_inv(self._weak_mat()), 0, -1)   # (k, k, w)
                z[:, :, self.weak] = fixed[np.ix_(self.plan.col_order, self.plan.row_order)]
            self._zinv = z
        return self._zinv

    def cond(self):
        """Return the exact 1-norm condition numbers ``(p,)`` (``inf`` where singular)."""
        if self._cond is None:
            if self._norm is None:
                if self._mat is None:   # ||J||_1: the largest column sum of |entries|
                    self._norm = self._col_mags.sum(axis=1).max(axis=0)
                else:
                    self._norm = np.max(np.sum(np.abs(self.mat), axis=0), axis=0)
            # the 1-norm is the largest column sum of |.|: a permutation does not change it
            with np.errstate(invalid='ignore'):
                if self._inv is None and getattr(self, '_zinv', None) is None:
                    colsum = np.zeros((self.k, self.p))
                    _inverse_z(self.lu, self.plan, self.p, colsum)   # scratch: norms only
                    norm_inv = colsum.max(axis=0)
                    if self.any_weak:
                        w = self.weak
                        fixed = np.moveaxis(_lapack_inv(self._weak_mat()), 0, -1)
                        norm_inv[w] = np.max(np.sum(np.abs(fixed), axis=0), axis=0)
                else:
                    inv = self._inv if self._inv is not None else self._z()
                    norm_inv = np.max(np.sum(np.abs(inv), axis=0), axis=0)
                cond = self._norm * norm_inv
            self._cond = np.where(np.isfinite(cond), cond, np.inf)
        return self._cond

    def sign(self):
        """Return the signs of the determinants ``(p,)`` (see :func:`det_sign`)."""
        if self._sign is None:
            self._sign = _lu_sign(self.lu, self.plan, self._weak_mat() if self.any_weak
                                  else None, self.weak)
        return self._sign


def solve(mat, rhs, plan=None):
    """
    Return ``x`` with ``mat x = rhs`` for a stack ``(k, k, p)`` and ``rhs`` ``(k, p)``.

    Closed form for k <= 2, else the static-pivot LU of ``plan`` (a dense plan in natural
    row order if ``None``), with LAPACK for the matrices whose static pivots are weak.
    Singular matrices give ``nan``/``inf`` entries.
    """
    mat = np.asarray(mat, dtype=float)
    rhs = np.asarray(rhs, dtype=float)
    k = mat.shape[0]
    if k == 2:
        a, b, c, d = mat[0, 0], mat[0, 1], mat[1, 0], mat[1, 1]
        x = np.empty(rhs.shape)
        with np.errstate(divide='ignore', invalid='ignore'):
            r = 1.0 / (a * d - b * c)
            x[0] = d * rhs[0]
            x[0] -= b * rhs[1]
            x[1] = a * rhs[1]
            x[1] -= c * rhs[0]
            x *= r
        return x
    if k == 1:
        with np.errstate(divide='ignore', invalid='ignore'):
            return rhs / mat[0]
    return Factored(mat, plan).solve(rhs)


def inverse(mat, plan=None, with_sign=False):
    """
    Return the inverses of a batch-last stack ``(k, k, p)`` and the 1-norm condition numbers.

    Returns ``(inv, cond)`` with ``inv`` of shape ``(k, k, p)`` and ``cond`` of shape ``(p,)``
    (``inf`` where a matrix is singular; its ``inv`` entries are then ``nan``).  ``plan`` is
    an :class:`LUPlan` (or a static row order) for k > 2; matrices whose static pivots are
    small are inverted again with LAPACK's partial pivoting.  With ``with_sign`` the signs
    of the determinants come third, from the same factorization (see :func:`det_sign`).
    """
    fac = Factored(mat, plan)
    inv, cond = fac.inverse()
    return (inv, cond, fac.sign()) if with_sign else (inv, cond)


_DENSE_PLANS = {}


def det_sign(mat, plan=None):
    """
    Return the sign of the determinant of each matrix of a batch-last ``(k, k, p)`` stack.

    k <= 2 in closed form; otherwise from the static-order LU (the permutations' sign times
    the signs of U's diagonal), with LAPACK for the matrices whose static pivots are small.
    """
    mat = np.asarray(mat, dtype=float)
    k, _, p = mat.shape
    if k == 0:
        return np.ones(p)
    if k == 1:
        return np.sign(mat[0, 0])
    if k == 2:
        return np.sign(mat[0, 0] * mat[1, 1] - mat[0, 1] * mat[1, 0])
    plan = _plan_for(k, plan)
    lu, weak = factor(mat, plan)
    return _lu_sign(lu, plan, mat[:, :, weak], weak)


def _lu_sign(lu, plan, weak_mat, weak):
    """Return det signs from static-order LU factors (LAPACK on ``weak_mat`` where weak)."""
    sign = np.prod(np.sign(lu[plan.diag]), axis=0) * plan.perm_sign
    if weak.any():
        sign[weak] = np.sign(np.linalg.det(np.ascontiguousarray(
            np.moveaxis(weak_mat, -1, 0))))
    return sign


def _plan_for(k, plan):
    """Return ``plan`` if it is an :class:`LUPlan`, else a dense plan for that row order."""
    if isinstance(plan, LUPlan):
        if plan.k != k:
            raise ValueError(f'plan: got a plan for k = {plan.k}, expected k = {k}')
        return plan
    order = tuple(range(k)) if plan is None else tuple(int(i) for i in plan)
    if order not in _DENSE_PLANS:
        if len(_DENSE_PLANS) > 64:
            _DENSE_PLANS.clear()
        _DENSE_PLANS[order] = LUPlan(np.ones((k, k), dtype=bool), np.array(order))
    return _DENSE_PLANS[order]


def _lapack_inv(mat):
    """Return LAPACK inverses of a batch-last stack as ``(w, k, k)``, nan where singular."""
    sub = np.ascontiguousarray(np.moveaxis(mat, -1, 0))
    fixed = np.full(sub.shape, np.nan)
    for i, m in enumerate(sub):
        try:
            fixed[i] = np.linalg.inv(m)
        except np.linalg.LinAlgError:
            pass
    return fixed


def _lapack(mat, rhs):
    """Return LAPACK solutions ``(k, w)`` of a batch-last stack, nan where singular."""
    return np.einsum('wij,jw->iw', _lapack_inv(mat), rhs)


def _inverse_2(mat):
    a, b, c, d = mat[0, 0], mat[0, 1], mat[1, 0], mat[1, 1]
    det = a * d - b * c
    abs_m = np.abs(mat)
    # 1-norm condition: the 1-norm of the inverse is the 1-norm of the adjugate / |det|
    n1 = np.maximum(abs_m[0, 0] + abs_m[1, 0], abs_m[0, 1] + abs_m[1, 1])
    n1 *= np.maximum(abs_m[1, 1] + abs_m[1, 0], abs_m[0, 1] + abs_m[0, 0])
    with np.errstate(divide='ignore', invalid='ignore'):
        r = 1.0 / det
        r[np.abs(det) <= PIVOT_FLOOR] = np.nan
        cond = n1 * np.abs(r)
    cond[~np.isfinite(cond)] = np.inf
    inv = np.empty_like(mat)
    np.multiply(d, r, out=inv[0, 0])
    np.multiply(b, -r, out=inv[0, 1])
    np.multiply(c, -r, out=inv[1, 0])
    np.multiply(a, r, out=inv[1, 1])
    return inv, cond, det


class BlockPlan:
    """
    A block lower triangular pattern with 2 x 2 diagonal blocks (a linkage of RRR dyads).

    ``rows``, ``cols`` (original indices) list the structural nonzeros in the order a
    matrix's values come in (as :meth:`LUPlan.set_entries`); ``blocks`` the diagonal blocks
    ``((row, row), (col, col))`` in dependency order: an entry outside the blocks must lie
    in an earlier block's columns.  Each diagonal block is inverted in closed form, all blocks
    at once (:class:`BlockFactored`), and the solves run block by block: no pivoting, no
    fill-in, no LAPACK fallback (a singular block gives ``inf`` in the condition number).
    Raises ``ValueError`` if the pattern is not of that form.
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
        self.perm_sign = -1.0 if (_inversions(self.row_order)
                                  + _inversions(self.col_order)) % 2 else 1.0
        self.entries = (rows, cols)
        # Z = J^-1 with its columns in block row order: block i's rows of Z are nonzero only
        # in the columns of block i and the blocks it depends on (all before it)
        pos_row = {r: p for p, r in enumerate(self.row_order)}
        self.block_of_col = where_col
        self.pos_row = pos_row
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
        # the (block, earlier column) pairs in block order, with their entries (rows.size:
        # none, a zero row) and each block's range of pairs
        pairs = [(i, c, e0, e1) for i in range(nb) for c, e0, e1, _, _ in self.off_cols[i]]
        pad = rows.size
        self.pair_block = np.array([q[0] for q in pairs], dtype=int)
        self.pair_entries = np.array([[pad if q[2] is None else q[2] for q in pairs],
                                      [pad if q[3] is None else q[3] for q in pairs]],
                                     dtype=int).reshape(2, -1)
        starts = np.searchsorted(self.pair_block, np.arange(nb + 1))
        self.block_pairs = [[(int(q), pairs[q][1]) for q in range(starts[i], starts[i + 1])]
                            for i in range(nb)]
        # blocks that read one earlier unknown only: (pair, child block, row, parent block)
        # from the last block back (the condition number in linear time)
        self.tree_like = all(len(self.off_cols[i]) <= 1 for i in range(nb))
        # the solves work on the unknowns in block order, block j's two as rows 2 j, 2 j + 1
        # (``flat``): each substitution then updates a block's two rows at once.  The
        # column of each flat row, and the flat row of each column:
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
        self.cols01 = np.array([[cs[0] for _, cs in self.blocks],
                                [cs[1] for _, cs in self.blocks]], dtype=int)
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
    """
    The closed-form block factorization of a :class:`BlockPlan` matrix given by its values.

    ``J = D (I + N)``: D the diagonal blocks (inverted in closed form, all at once), N the
    weights ``D_i^-1 J_ic`` of each earlier column c in block i's unknowns (a 2-vector per
    angle and pair, all pairs at once).  The same interface as :class:`Factored`:
    :meth:`solve`, :meth:`solve_t`, :meth:`cond` (exact 1-norm), :meth:`sign`,
    :meth:`inverse`, :attr:`mat`.
    """

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
        inv[1:3] *= _MINUS_ONE                     # d, -b, -c, a over det
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
        plan = self.plan
        if plan.single:
            return self._solve_2(rhs, False)
        p = rhs.shape[1]
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
        plan = self.plan
        if plan.single:
            return self._solve_2(rhs, True)
        p = rhs.shape[1]
        inv = self.inv
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
        """
        Return ``Z = J^-1`` ``(k, k, p)``, columns in block row order (ranges only).

        Block i's rows: ``Z_i = D_i^-1 E_i - sum_c (D_i^-1 J_ic) Z_c`` over the earlier
        columns c its rows reach, each ``D_i^-1 J_ic`` a 2-vector per angle.  With
        ``colsum`` ``(k, p)`` (zeros) the column sums of ``|Z|`` are added row by row and
        the entries outside the ranges are left unset.
        """
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
        """
        Return the 1-norm condition numbers of one 2 x 2 block (under the caller's errstate).

        ``entries`` ``(4, p)``: a, b, c, d; ``adet`` ``|det|``; the 1-norm of the inverse is
        that of the adjugate over ``|det|``.  ``checked``: every ``|det|`` is at least
        :data:`_TINY_DET` (so no 0/0 to look for).
        """
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
        """
        Return ``||J^-1||_1`` ``(p,)`` when every block reads one earlier unknown only.

        Then block i's rows of ``Z = J^-1`` are ``-w_i`` times the row of the unknown c it
        reads, so ``|Z|`` below a block's own rows is that row's ``|Z|`` times products of
        ``|w|``: the column sums are the own entries ``|D_b^-1|`` times ``1 + U``, with U
        summed once from the last block back (``U_r`` of an unknown r: the sum over the blocks
        reading r of ``|w_0| + |w_1| + |w_0| U_c0 + |w_1| U_c1``).  Exact, and linear in k.
        """
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
