"""Vector helpers of the spatial core over stacks: batch-first ``(..., 3)`` or ``(3, ...)``."""

import numpy as np


def unit(v):
    """Return ``v`` scaled to unit length."""
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def component_major(a):
    """Return a batch-first ``(n, nb, k...)`` array as a contiguous ``(k..., nb, n)``."""
    nd = a.ndim
    return np.ascontiguousarray(a.transpose(tuple(range(2, nd)) + (1, 0)))


def cross_c(a, b):
    """Return ``a x b`` of component-major vectors ``(3, ...)`` (broadcast)."""
    out = np.empty(a.shape if np.shape(a) == np.shape(b) else np.broadcast(a, b).shape)
    np.multiply(a[1], b[2], out=out[0])
    out[0] -= a[2] * b[1]
    np.multiply(a[2], b[0], out=out[1])
    out[1] -= a[0] * b[2]
    np.multiply(a[0], b[1], out=out[2])
    out[2] -= a[1] * b[0]
    return out


def dot_c(a, b):
    """Return the dot products of component-major vectors ``(3, ...)`` (broadcast)."""
    out = a[0] * b[0]
    out += a[1] * b[1]
    out += a[2] * b[2]
    return out


def cross(a, b):
    """Return ``a x b`` over the last axis (broadcast); numpy's cross without its overhead."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    sa = np.shape(a)
    out = np.empty(sa if sa == np.shape(b) else np.broadcast(a, b).shape)
    np.subtract(a1 * b2, a2 * b1, out=out[..., 0])
    np.subtract(a2 * b0, a0 * b2, out=out[..., 1])
    np.subtract(a0 * b1, a1 * b0, out=out[..., 2])
    return out


def mv(mat, vec):
    """Return ``mat @ vec`` over stacks: ``(..., k, k)`` times ``(..., k)`` (broadcast)."""
    vec = np.asarray(vec)
    out = mat[..., 0] * vec[..., None, 0]
    for j in range(1, mat.shape[-1]):
        out += mat[..., j] * vec[..., None, j]
    return out


def dot(a, b):
    """Return the dot products over the last axis (broadcast)."""
    return (a * b).sum(-1)


def sin_vers_one(q):
    """Return ``(n, 3)`` rows ``[sin q, 1 - cos q, 1]`` (the weights of a rotation basis)."""
    out = np.empty((q.shape[0], 3))
    np.sin(q, out=out[:, 0])
    np.cos(q, out=out[:, 1])
    np.subtract(1.0, out[:, 1], out=out[:, 1])
    out[:, 2] = 1.0
    return out


def perp_pair(axis):
    """Return two unit vectors normal to ``axis`` and to each other (deterministic)."""
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    e1 = cross(axis, helper)
    e1 /= np.linalg.norm(e1)
    return e1, cross(axis, e1)
