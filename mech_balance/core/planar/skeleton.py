"""The traced branch of a planar linkage: nodes over one crank turn, quintic Hermite predictor."""

import math

import numpy as np

TWO_PI = 2.0 * math.pi


class Skeleton:
    """Branch nodes over one crank turn and a quintic Hermite predictor between them."""

    # quintic Hermite basis in powers of t: rows (value0, slope0, curv0, value1, slope1, curv1)
    _BASIS = np.array([
        [1, 0, 0, -10, 15, -6],
        [0, 1, 0, -6, 8, -3],
        [0, 0, 0.5, -1.5, 1.5, -0.5],
        [0, 0, 0, 10, -15, 6],
        [0, 0, 0, -4, 7, -3],
        [0, 0, 0, 0.5, -1, 0.5],
    ])

    def __init__(self, psi, q, qd, qdd, cond, turns):
        self.psi, self.q, self.qd, self.qdd, self.cond, self.turns = psi, q, qd, qdd, cond, turns
        self.h = np.diff(psi)
        self.offset = psi - psi[0]
        h = self.h
        data = np.stack([q[:, :-1], qd[:, :-1] * h, qdd[:, :-1] * h * h,
                         q[:, 1:], qd[:, 1:] * h, qdd[:, 1:] * h * h], axis=-1)
        # (6, nt, segments) power-series coefficients of each segment in t in [0, 1]
        self.coef = np.ascontiguousarray(np.moveaxis(data @ self._BASIS, -1, 0))
        self.last = self.h.size - 1
        # the crank row is the crank angle itself: only the other rows are interpolated
        self.coef_u = np.ascontiguousarray(self.coef[:, 1:])
        self.wrap_step_u = (TWO_PI * turns[1:])[:, None] if np.any(turns[1:]) else None
        self._turn_table = None
        self._dense = None     # (_dense_prediction: shared by the two checks at build)

    TURN_TABLE_SIZE = 256
    """Angles per turn of :meth:`turn_reference`'s table (the coordinates, nearest angle)."""

    def turn_table_error(self):
        """Return the largest distance (rad) of :meth:`turn_reference` from :meth:`predict`."""
        table = self._table()
        psi, q = self._dense_prediction()
        err = np.abs(self.turn_reference(psi) - q)
        slope = np.abs(np.diff(table, axis=1)).max(initial=0.0)
        return float(err.max(initial=0.0) + slope / 16.0)

    def _dense_prediction(self):
        """Return ``(psi, q)``: the predictor's coordinates but the crank's, 16 per table step."""
        if self._dense is None:
            n = 16 * self.TURN_TABLE_SIZE
            psi = self.psi[0] + np.arange(n + 1) * (TWO_PI / n)
            self._dense = (psi, self.predict(psi)[1:])
        return self._dense

    def affine_reference(self):
        """
        Return ``(slope, offset, error)``: the straight line in psi nearest each coordinate.

        ``slope`` ``(nt - 1, 1)``: whole turns per crank turn; ``error``: the largest distance
        of the line from :meth:`predict` (well below pi: the line tells the whole turns).
        """
        psi, q = self._dense_prediction()
        slope = (np.zeros((q.shape[0], 1)) if self.wrap_step_u is None
                 else self.wrap_step_u / TWO_PI)
        rest = q - slope * psi
        offset = 0.5 * (rest.max(axis=1) + rest.min(axis=1))[:, None]
        err = np.abs(rest - offset).max(initial=0.0)
        step = np.abs(np.diff(q, axis=1)).max(initial=0.0)
        return slope, offset, float(err + step)

    def _table(self):
        if self._turn_table is None:
            n = self.TURN_TABLE_SIZE
            psi = self.psi[0] + np.arange(n + 1) * (TWO_PI / n)
            psi[-1] = self.psi[0] + TWO_PI
            q = self.predict(psi[:-1])[1:]
            # the last column is the first one turn on (the coordinates' whole turns added)
            end = q[:, :1] + (0.0 if self.wrap_step_u is None else self.wrap_step_u)
            self._turn_table = np.ascontiguousarray(np.concatenate([q, end], axis=1))
        return self._turn_table

    def turn_reference(self, psi):
        """Return the coordinates but the crank's ``(nt - 1, p)`` at the nearest table angle."""
        table, n = self._table(), self.TURN_TABLE_SIZE
        u = np.subtract(psi, self.psi[0])
        u *= n / TWO_PI
        np.rint(u, out=u)
        turns, index = np.divmod(u.astype(np.int64), n)   # index in [0, n) whatever psi
        out = table.take(index, axis=1)
        if self.wrap_step_u is not None:
            out += self.wrap_step_u * turns
        return out

    def wraps(self, psi):
        """Return how many whole turns ``psi`` lies beyond the skeleton's start."""
        return np.floor((np.asarray(psi) - self.psi[0]) / TWO_PI)

    def locate(self, psi):
        """Return the interval index, the offset into the turn and the whole turns."""
        x = np.subtract(psi, self.psi[0])
        turns = np.multiply(x, 1.0 / TWO_PI)
        np.floor(turns, out=turns)
        x -= turns * TWO_PI
        # x >= 0 = offset[0] (rounding can leave -0.5 ulp), so the index is >= 0; x may
        # round up to 2 pi: cap at the last
        np.maximum(x, 0.0, out=x)
        k = np.searchsorted(self.offset, x, side='right')
        k -= 1
        return np.minimum(k, self.last, out=k), x, turns

    def predict(self, psi):
        """Return predicted tree coordinates ``(nt, p)`` at crank angles ``psi``."""
        psi = np.asarray(psi, dtype=float)
        k, x, turns = self.locate(psi)
        x -= self.offset[k]
        x /= self.h[k]                   # t in [0, 1] along the segment
        q = np.empty((self.q.shape[0], psi.size))
        q[0] = psi                       # the crank joint's coordinate is the crank angle
        c = self.coef_u.take(k, axis=2)   # (take: a third of the fancy index's cost)
        qu = np.multiply(c[5], x, out=q[1:])
        for j in (4, 3, 2, 1):           # Horner, in place
            qu += c[j]
            qu *= x
        qu += c[0]
        if self.wrap_step_u is not None:
            qu += self.wrap_step_u * turns
        return q
