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
"""

import numpy as np

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


class LUPlan:
    """
    The symbolic LU factorization of a ``(k, k)`` sparsity pattern in a static row order.

    ``pattern`` (bool ``(k, k)``, original row order) must contain every entry that can be
    nonzero; ``row_order`` is the static pivot order (:func:`pivot_order`).  The factors
    are stored as one ``(nnz, p)`` array of the nonzeros of L (unit diagonal, not stored)
    and U, fill-in included; the index lists below drive the numeric phase.
    """

    def __init__(self, pattern, row_order=None):
        pattern = np.asarray(pattern, dtype=bool)
        k = pattern.shape[0]
        if pattern.shape != (k, k):
            raise ValueError(f'pattern: got shape {pattern.shape}, expected (k, k)')
        self.k = k
        self.row_order = np.arange(k) if row_order is None else np.asarray(row_order)
        a = pattern[self.row_order] | np.eye(k, dtype=bool)
        for j in range(k):  # symbolic elimination: row i gains row j's pattern
            rows = np.flatnonzero(a[j + 1:, j]) + j + 1
            a[np.ix_(rows, np.arange(j, k))] |= a[j, j:]
        rr, cc = np.nonzero(a)
        self.nnz = rr.size
        slot = np.full((k, k), -1)
        slot[rr, cc] = np.arange(self.nnz)
        self.src_row = self.row_order[rr]   # where each stored entry comes from in mat
        self.src_col = cc
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
            pivot = lu[plan.diag[j]]
            weak |= ~(np.abs(pivot) > STATIC_PIVOT_RATIO * col_max[j])
            li = plan.l_idx[j]
            if li.size:
                low = lu[li] / pivot
                lu[li] = low
                ui = plan.u_idx[j]
                if ui.size:
                    lu[plan.update[j]] -= (low[:, None, :] * lu[ui][None, :, :]).reshape(-1, p)
    return lu, weak


def _substitute(lu, plan, y):
    """Solve L U x = y in place for ``y`` ``(k, p)`` (rows already in pivot order)."""
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


def _inverse_lu(lu, plan, p):
    """Return the ``(k, k, p)`` inverse from the factors, working on nonzero ranges only."""
    k = plan.k
    z = np.zeros((k, k, p))
    z[np.arange(k), np.arange(k)] = 1.0
    tmp = np.empty((k, p))
    env, lo, hi = plan.env, plan.z_lo, plan.z_hi
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
            zj[lo[j]:hi[j] + 1] /= lu[plan.diag_list[j]]
    inv = np.empty_like(z)
    inv[:, plan.row_order] = z                       # J^-1 = Z P
    return inv


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
    plan = _plan_for(k, plan)
    lu, weak = factor(mat, plan)
    x = _substitute(lu, plan, rhs[plan.row_order])
    if np.any(weak):
        x[:, weak] = _lapack(mat[:, :, weak], rhs[:, weak])
    return x


def inverse(mat, plan=None, with_sign=False):
    """
    Return the inverses of a batch-last stack ``(k, k, p)`` and the 1-norm condition numbers.

    Returns ``(inv, cond)`` with ``inv`` of shape ``(k, k, p)`` and ``cond`` of shape ``(p,)``
    (``inf`` where a matrix is singular; its ``inv`` entries are then ``nan``).  ``plan`` is
    an :class:`LUPlan` (or a static row order) for k > 2; matrices whose static pivots are
    small are inverted again with LAPACK's partial pivoting.  With ``with_sign`` the signs
    of the determinants come third, from the same factorization (see :func:`det_sign`).
    """
    mat = np.asarray(mat, dtype=float)
    if mat.ndim != 3 or mat.shape[0] != mat.shape[1]:
        raise ValueError(f'mat: got shape {mat.shape}, expected (k, k, p)')
    k, _, p = mat.shape
    if k == 0:  # no unknowns (an open chain): an empty, perfectly conditioned system
        inv, cond, sign = np.zeros((0, 0, p)), np.ones(p), np.ones(p)
        return (inv, cond, sign) if with_sign else (inv, cond)
    if k == 2:
        inv, cond, det = _inverse_2(mat)
        return (inv, cond, np.sign(det)) if with_sign else (inv, cond)
    if k == 1:
        with np.errstate(divide='ignore', invalid='ignore'):
            inv = 1.0 / mat
        sign = np.sign(mat[0, 0]) if with_sign else None
    else:
        plan = _plan_for(k, plan)
        lu, weak = factor(mat, plan)
        inv = _inverse_lu(lu, plan, p)
        sign = _lu_sign(lu, plan, mat, weak) if with_sign else None
        if np.any(weak):
            inv[:, :, weak] = np.moveaxis(_lapack_inv(mat[:, :, weak]), 0, -1)
    norm = np.max(np.sum(np.abs(mat), axis=0), axis=0)
    with np.errstate(invalid='ignore'):
        norm_inv = np.max(np.sum(np.abs(inv), axis=0), axis=0)
        cond = norm * norm_inv
    cond = np.where(np.isfinite(cond), cond, np.inf)
    return (inv, cond, sign) if with_sign else (inv, cond)


_DENSE_PLANS = {}


def det_sign(mat, plan=None):
    """
    Return the sign of the determinant of each matrix of a batch-last ``(k, k, p)`` stack.

    k <= 2 in closed form; otherwise from the static-order LU (the permutation's sign times
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
    return _lu_sign(lu, plan, mat, weak)


def _lu_sign(lu, plan, mat, weak):
    """Return det signs from static-order LU factors (LAPACK where ``weak``)."""
    order = plan.row_order
    k = plan.k
    inversions = sum(1 for i in range(k) for j in range(i + 1, k) if order[i] > order[j])
    sign = np.prod(np.sign(lu[plan.diag]), axis=0) * (-1.0 if inversions % 2 else 1.0)
    if weak.any():
        sign[weak] = np.sign(np.linalg.det(np.ascontiguousarray(
            np.moveaxis(mat[:, :, weak], -1, 0))))
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
