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


def inverse(mat):
    """
    Return the inverses of a batch-last stack ``(k, k, p)`` and the 1-norm condition numbers.

    Returns ``(inv, cond)`` with ``inv`` of shape ``(k, k, p)`` and ``cond`` of shape ``(p,)``
    (``inf`` where a matrix is singular; its ``inv`` entries are then ``nan``).
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
        inv = _inverse_gauss_jordan(mat)
    norm = np.max(np.sum(np.abs(mat), axis=0), axis=0)
    with np.errstate(invalid='ignore'):
        norm_inv = np.max(np.sum(np.abs(inv), axis=0), axis=0)
        cond = norm * norm_inv
    cond = np.where(np.isfinite(cond), cond, np.inf)
    return inv, cond


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


def _inverse_gauss_jordan(mat):
    k, _, p = mat.shape
    aug = np.concatenate([mat, np.broadcast_to(np.eye(k)[:, :, None], (k, k, p))], axis=1)
    aug = aug.copy()
    cols = np.arange(p)
    singular = np.zeros(p, dtype=bool)
    for j in range(k):
        piv = j + np.argmax(np.abs(aug[j:, j, :]), axis=0)
        if np.any(piv != j):
            row_j = aug[j].copy()
            aug[j] = aug[piv, :, cols].T
            aug[piv, :, cols] = row_j.T
        pivot = aug[j, j].copy()
        bad = np.abs(pivot) <= PIVOT_FLOOR
        singular |= bad
        pivot[bad] = 1.0
        aug[j] /= pivot
        factors = aug[:, j, :].copy()
        factors[j] = 0.0
        aug -= factors[:, None, :] * aug[j][None, :, :]
    inv = aug[:, k:, :]
    inv[:, :, singular] = np.nan
    return inv


def matvec(mat, vec):
    """Return ``mat @ vec`` for batch-last ``(m, k, p)`` and ``(k, p)`` -> ``(m, p)``."""
    return np.einsum('ikp,kp->ip', mat, vec)


def matvec_t(mat, vec):
    """Return ``mat.T @ vec`` for batch-last ``(k, m, p)`` and ``(k, p)`` -> ``(m, p)``."""
    return np.einsum('kip,kp->ip', mat, vec)
