"""Batched solves of small matrices ``(k, k, p)``: docs/core.md#the-planar-core-coreplanar."""

from mech_balance.core.linalg.ordering import LUPlan
import numpy as np

PIVOT_FLOOR = 1e-300
"""A pivot smaller than this (in magnitude) is treated as exactly singular."""
STATIC_PIVOT_RATIO = 1e-3
"""A static pivot smaller than this times its column's largest entry triggers LAPACK."""


def matvec(mat, vec):
    """Return mat @ vec for batch-last (m, k, p) and (k, p) stacks."""
    if mat.shape[0] == 2 and mat.shape[1] == 2:
        return np.array([mat[0, 0] * vec[0] + mat[0, 1] * vec[1],
                         mat[1, 0] * vec[0] + mat[1, 1] * vec[1]])
    return np.einsum('ikp,kp->ip', mat, vec)


def matvec_t(mat, vec):
    """Return mat^T @ vec for batch-last (k, m, p) and (k, p) stacks."""
    if mat.shape[0] == 2 and mat.shape[1] == 2:
        out = mat[0] * vec[0]
        out += mat[1] * vec[1]
        return out
    return np.einsum('kip,kp->ip', mat, vec)


def factor(mat, plan):
    """Return ``(lu, weak)``: the ``(nnz, p)`` LU nonzeros and the mask of weak pivots ``(p,)``."""
    lu = mat[plan.src_row, plan.src_col]           # (nnz, p), a copy
    col_max = np.max(np.abs(mat), axis=0)          # (k, p): largest entry of each column
    return lu, _eliminate(lu, plan, col_max.take(plan.pivot_col, axis=0))


def _eliminate(lu, plan, col_max):
    """Eliminate in place on ``lu`` ``(nnz, p)``; return the weak mask (pivot vs ``col_max``)."""
    p = lu.shape[1]
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
    return weak


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
    return lu, _eliminate(lu, plan, col_max), col_mags


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
    """Return ``Z = U^-1 L^-1`` on nonzero ranges (``colsum``: add the column sums of ``|Z|``)."""
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


class Factored:
    """
    One factorization of a batch-last stack ``(k, k, p)``, reused for every solve.

    ``plan``: an :class:`LUPlan`, a static row order, or ``None`` (dense); ``values``: the
    nonzeros of :meth:`LUPlan.set_entries` instead of ``mat``.  Singular: ``nan``/``inf``.
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
            return matvec(self._inv, rhs)
        plan = self.plan
        y = _substitute(self.lu, plan, rhs[plan.row_order])
        if plan.natural_cols:
            x = y
        else:
            x = np.empty_like(y)
            x[plan.col_order] = y
        return self._redo_weak(x, rhs, False)

    def _redo_weak(self, x, rhs, transposed):
        """Return ``x`` with the weak angles' solutions replaced by LAPACK's."""
        if self.any_weak:
            w = self.weak
            mat = self._weak_mat()
            x[:, w] = _lapack(mat.transpose(1, 0, 2) if transposed else mat, rhs[:, w])
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
            return matvec_t(self._inv, rhs)
        x = np.empty(rhs.shape)                      # pivot row order back to the original
        x[self.plan.row_order] = _substitute_t(self.lu, self.plan, rhs[self.plan.col_order])
        return self._redo_weak(x, rhs, True)

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
    """Return ``x`` with ``mat x = rhs`` for a stack ``(k, k, p)`` (closed form for k <= 2)."""
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
    """Return ``(inv (k, k, p), cond (p,)[, det signs])`` (cond ``inf`` where singular)."""
    fac = Factored(mat, plan)
    inv, cond = fac.inverse()
    return (inv, cond, fac.sign()) if with_sign else (inv, cond)


_DENSE_PLANS = {}


def det_sign(mat, plan=None):
    """Return the sign of the determinant of each matrix of a batch-last ``(k, k, p)`` stack."""
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
