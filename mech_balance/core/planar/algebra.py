"""
Planar vector algebra on complex-coded vectors and batch-last stacks.

A planar vector is a complex number x + i*y; seed 000's 90-degree rotation operator E is
multiplication by 1j, so ``a^T E b = -cross(a, b)``.  Stacks are batch-last: one row per
body or joint, one column per crank angle.  Shared by the kinematics, the dynamics and the
forward dynamics (one home for each of these one-liners).
"""

import numpy as np


def cross(a, b):
    """Return the scalar cross product a x b of complex-coded planar vectors."""
    # Im(conj(a) b) = a.x b.y - a.y b.x, in two vectorized operations instead of four
    return (a.conjugate() * b).imag


def dot(a, b):
    """Return the scalar product of complex-coded planar vectors."""
    return (a.conjugate() * b).real


def rmat(mat, z):
    """Return ``mat @ z`` for a real matrix and a complex batch-last stack ``z``."""
    # numpy has no BLAS path for real @ complex (it loops in C, ~50x slower): multiply the
    # interleaved real and imaginary parts as one real matrix instead
    z = np.ascontiguousarray(z)
    return np.dot(mat, z.view(np.float64)).view(np.complex128)


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
