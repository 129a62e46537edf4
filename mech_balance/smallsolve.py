"""
Batched inverses of many small matrices, batch on the last axis.

``numpy.linalg.inv`` on a stack of 2x2 matrices costs about half a microsecond per matrix
(per-matrix LAPACK call overhead), which alone would exceed the per-angle budget of the
cycle analysis.  Here a stack is stored batch-last, ``(k, k, p)``, so every elementary
operation is one vectorized numpy call over all p angles: closed form for k <= 2,
Gauss-Jordan elimination with partial pivoting otherwise.
"""

import numpy as np

PIVOT_FLOOR = 1e-300
"""A pivot smaller than this (in magnitude) is treated as exactly singular."""


def inverse(mat, row_order=None):
    """
    Return the inverses of a batch-last stack ``(k, k, p)`` and the 1-norm condition numbers.

    Returns ``(inv, cond)`` with ``inv`` of shape ``(k, k, p)`` and ``cond`` of shape ``(p,)``
    (``inf`` where a matrix is singular; its ``inv`` entries are then ``nan``).
    ``row_order`` is a fixed pivot order for k > 2 (see :func:`pivot_order`); matrices whose
    pivots in that order are small are inverted again with LAPACK's partial pivoting.
    """
    mat = np.asarray(mat, dtype=float)
    if mat.ndim != 3 or mat.shape[0] != mat.shape[1]:
        raise ValueError(f'mat: got shape {mat.shape}, expected (k, k, p)')
    k = mat.shape[0]
    if k == 2:
        return _inverse_2(mat)
    if k == 1:
        with np.errstate(divide='ignore', invalid='ignore'):
            inv = 1.0 / mat
    else:
        inv = _inverse_static(mat, row_order)
    norm = np.max(np.sum(np.abs(mat), axis=0), axis=0)
    with np.errstate(invalid='ignore'):
        norm_inv = np.max(np.sum(np.abs(inv), axis=0), axis=0)
        cond = norm * norm_inv
    cond = np.where(np.isfinite(cond), cond, np.inf)
    return inv, cond


STATIC_PIVOT_RATIO = 1e-3
"""A static pivot smaller than this times its column's largest entry triggers LAPACK."""


def pivot_order(mat):
    """
    Return a row order for Gauss-Jordan without row swaps, from one ``(k, k)`` matrix.

    Partial pivoting on a representative matrix (e.g. the loop Jacobian at the assembly
    position); the same sparsity pattern makes the order good over the whole cycle, and
    :func:`inverse` falls back to LAPACK wherever it is not.
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


def _inverse_static(mat, row_order):
    k, _, p = mat.shape
    order = np.arange(k) if row_order is None else row_order
    a = mat[order].copy()
    inv = np.broadcast_to(np.eye(k)[order][:, :, None], (k, k, p)).copy()
    col_max = np.max(np.abs(mat), axis=0)          # (k, p): largest entry of each column
    weak = np.zeros(p, dtype=bool)
    for j in range(k):
        pivot = a[j, j].copy()
        weak |= ~(np.abs(pivot) > STATIC_PIVOT_RATIO * col_max[j])
        pivot[pivot == 0.0] = 1.0
        r = 1.0 / pivot
        a[j] *= r
        inv[j] *= r
        f = a[:, j].copy()
        f[j] = 0.0
        a -= f[:, None, :] * a[j][None, :, :]
        inv -= f[:, None, :] * inv[j][None, :, :]
    if np.any(weak):
        sub = np.ascontiguousarray(np.moveaxis(mat[:, :, weak], -1, 0))
        fixed = np.full(sub.shape, np.nan)
        for i, m in enumerate(sub):
            try:
                fixed[i] = np.linalg.inv(m)
            except np.linalg.LinAlgError:
                pass
        inv[:, :, weak] = np.moveaxis(fixed, 0, -1)
    return inv


def _inverse_2(mat):
    a, b, c, d = mat[0, 0], mat[0, 1], mat[1, 0], mat[1, 1]
    det = a * d - b * c
    with np.errstate(divide='ignore', invalid='ignore'):
        r = 1.0 / det
    r[np.abs(det) <= PIVOT_FLOOR] = np.nan
    inv = np.empty_like(mat)
    inv[0, 0] = d * r
    inv[0, 1] = -b * r
    inv[1, 0] = -c * r
    inv[1, 1] = a * r
    # 1-norm condition: the 1-norm of the inverse is the 1-norm of the adjugate / |det|
    abs_m = np.abs(mat)
    n1 = np.maximum(abs_m[0, 0] + abs_m[1, 0], abs_m[0, 1] + abs_m[1, 1])
    n1_adj = np.maximum(abs_m[1, 1] + abs_m[1, 0], abs_m[0, 1] + abs_m[0, 0])
    with np.errstate(invalid='ignore'):
        cond = n1 * n1_adj * np.abs(r)
    cond[~np.isfinite(cond)] = np.inf
    return inv, cond


def matvec(mat, vec):
    """Return ``mat @ vec`` for batch-last ``(m, k, p)`` and ``(k, p)`` -> ``(m, p)``."""
    return np.einsum('ikp,kp->ip', mat, vec)


def matvec_t(mat, vec):
    """Return ``mat.T @ vec`` for batch-last ``(k, m, p)`` and ``(k, p)`` -> ``(m, p)``."""
    return np.einsum('kip,kp->ip', mat, vec)
