"""
Planar vector algebra on complex-coded vectors and batch-last stacks.

A planar vector is x + i*y; seed 000's rotation operator E is multiplication by 1j, so
``a^T E b = -cross(a, b)``.  Stacks: one row per body or joint, one column per crank angle.
"""

import numpy as np


def cross(a, b):
    """Return the scalar cross product a x b of complex-coded planar vectors."""
    # Im(conj(a) b) = a.x b.y - a.y b.x, in two vectorized operations instead of four
    return (a.conjugate() * b).imag


def dot(a, b):
    """Return the scalar product of complex-coded planar vectors."""
    return (a.conjugate() * b).real


max_reduce = np.maximum.reduce
"""``np.maximum.reduce``: the ufunc's own reduction, without ``ndarray.max``'s Python wrapper."""


def rmat(mat, z):
    """Return ``mat @ z`` for a real matrix and a complex batch-last stack ``z``."""
    # numpy has no BLAS path for real @ complex (it loops in C, ~50x slower): multiply the
    # interleaved real and imaginary parts as one real matrix instead
    z = np.ascontiguousarray(z)
    return np.dot(mat, z.view(np.float64)).view(np.complex128)


TILE_LIMIT = 1 << 16
"""Largest ``k * p`` a :class:`Tiles` materializes (beyond it the columns broadcast)."""


class Tiles:
    """Constant columns ``(k, 1)`` tiled to ``(k, p)`` for the last batch size (faster ufuncs)."""

    def __init__(self, **columns):
        self.columns = {name: _frozen(np.array(col)) for name, col in columns.items()}
        self.rows = max((c.shape[0] for c in self.columns.values()), default=0)
        self._last = (None, self.columns)

    def at(self, p):
        """Return ``{name: (k, p) array}`` (or the ``(k, 1)`` columns for large batches)."""
        last, tiles = self._last           # (one read: another thread may replace it)
        if last == p:
            return tiles
        if self.rows * p > TILE_LIMIT:
            return self.columns
        tiles = {name: _frozen(np.ascontiguousarray(np.broadcast_to(col, (col.shape[0], p))))
                 for name, col in self.columns.items()}
        self._last = (p, tiles)
        return tiles


def _frozen(a):
    """Return ``a`` marked read-only (a shared constant)."""
    a.setflags(write=False)
    return a
