"""
Follow mode's cycle table: a rig's published values at any crank angle, built once per design.

numpy only.  Fourier series of q(psi), q'(psi) and ``Y0 + Yw w + Y2 w^2 + Ya a``, verified
when built, else refused: `docs/node.md#follow-mode` (*The cycle table*).
"""

from dataclasses import dataclass
import math
import time

from mech_balance.core.rig import RigData
from mech_balance.rotations import TWO_PI, wrap_angle
import numpy as np

BOUND = 1e-10
"""Largest accepted accuracy, relative to each channel's scale (the node tests ask 1e-9)."""
GRIDS = (256, 1024, 4096)
"""Grid sizes tried in turn (angles per turn) until the verified accuracy meets the bound."""
FLOOR = 1e-6
"""A channel's scale is at least this fraction of its group's (near-zero channels)."""
HARMONIC_KEEP = 1e-3
"""Harmonics below this fraction of the bound (relative to the channel's scale) are dropped."""
CHECK_SPEEDS = (0.5, -3.7, 12.0, -41.0, 150.0)
"""Crank speeds of the check (rad/s), cycled over the check angles."""
CHECK_ACCELS = (0.0, 25.0, -180.0, 3.0, -900.0, 1.0e3)
"""Crank accelerations of the check (rad/s^2), cycled over the check angles."""


class TableRefused(ValueError):
    """The cycle table does not reproduce the exact model within its bound (the reason)."""


class _TooCoarse(TableRefused):
    """The accuracy on this grid exceeds the bound (a finer grid may meet it)."""


@dataclass(frozen=True)
class TableReport:
    """What a build found: grid angles, harmonics kept, accuracy, build time."""

    grid: int
    harmonics: int
    accuracy: float
    bound: float
    seconds: float
    condition: float

    def summary(self):
        """Return the one-line description logged by the node."""
        return (f'cycle table of {self.grid} angles per turn, {self.harmonics} harmonics, '
                f'verified accuracy {self.accuracy:.1e} relative (bound {self.bound:.0e}), '
                f'built in {self.seconds * 1e3:.0f} ms')


def _stack(samples):
    """Return ``(n, C)``: positions, velocities, efforts (if any), force, moment."""
    parts = [samples.joint_position, samples.joint_velocity]
    if samples.joint_effort is not None:
        parts.append(samples.joint_effort)
    parts += [samples.force_N, samples.moment_Nm]
    return np.hstack(parts).astype(float)


class CycleTable:
    """
    A design's published values as Fourier series in the crank angle (:meth:`build`).

    :meth:`evaluate` returns a :class:`RigData` within :attr:`accuracy`, with the solver
    diagnostics of the grid cell and no body poses (the caller may set ``poses``).
    """

    def __init__(self, template, joints, angular, coef, harmonics, interval, report):
        self._names = template.joint_names
        self._effort = template.joint_effort is not None
        self._j = joints
        self._angular = angular
        self._wrapped = slice(0, joints) if angular.all() else \
            np.flatnonzero(angular) if angular.any() else None
        self._coef = coef                          # (4 (2 M + 2), C)
        self._m = np.arange(1, harmonics + 1, dtype=float)
        # per grid cell: residual, condition (one more: x n / 2 pi may round up to n)
        self._cells = tuple(np.append(v, v[:1]) for v in interval)
        self._cell = len(interval[0]) / TWO_PI
        self.report = report
        self.accuracy = report.accuracy

    @classmethod
    def build(cls, evaluate, angular, bound=BOUND, grids=GRIDS):
        """
        Return the verified table of ``evaluate(psi, speed, accel)`` (the exact model).

        ``angular`` ``(n_joints,)``: which positions are angles.  Raises
        :class:`TableRefused` (the reason) where the table cannot be trusted.
        """
        t0 = time.perf_counter()
        angular = np.asarray(angular, dtype=bool)
        last = None
        for n in grids:
            try:
                return cls._build(evaluate, angular, n, bound, t0)
            except _TooCoarse as exc:
                last = exc
        raise TableRefused(str(last))

    @classmethod
    def _build(cls, evaluate, angular, n, bound, t0):
        psi = np.arange(n) * (TWO_PI / n)
        combos = ((0.0, 0.0), (1.0, 0.0), (-1.0, 0.0), (0.0, 1.0))
        try:
            runs = [evaluate(np.concatenate([psi, [TWO_PI]]), w, a) for w, a in combos]
        except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
            raise TableRefused(f'the core fails at a grid angle: {exc}') from None
        template = runs[0]
        j = template.joint_position.shape[1]
        if angular.shape != (j,):
            raise TableRefused(f'angular: got shape {angular.shape}, expected ({j},)')
        for r in runs:
            near = r.near_singular
            if near is not None and np.any(near):
                at = float(r.crank_angle_rad[np.flatnonzero(near)[0]])
                raise TableRefused(f'the rig is near-singular at crank angle {at:.6g} rad')
        y = [_stack(r) for r in runs]
        if not all(np.all(np.isfinite(v)) for v in y):
            raise TableRefused('a published value is not finite at a grid angle')
        y0, yp, ym, ya = y
        sets = [y0, 0.5 * (yp - ym), 0.5 * (yp + ym) - y0, ya - y0]
        # positions: independent of the speed and acceleration; unwrapped, less whole turns
        pos = y0[:, :j].copy()
        pos[:, angular] = np.unwrap(pos[:, angular], axis=0)
        turns = np.where(angular, np.round((pos[-1] - pos[0]) / TWO_PI), 0.0)
        pos -= np.concatenate([psi, [TWO_PI]])[:, None] * turns
        if np.any(np.abs(pos[-1] - pos[0]) > 1e-9 * np.maximum(1.0, np.abs(pos[0]))):
            raise TableRefused('a joint position is not periodic over one crank turn')
        sets[0] = np.hstack([pos, y0[:, j:]])
        for s in sets[1:]:
            s[:, :j] = 0.0  # positions do not move with (w, a): checked below
        # Fourier coefficients (real basis: 1, cos m psi, sin m psi) of every set
        spectra = [np.fft.rfft(s[:-1], axis=0) / n for s in sets]
        # each channel's scale: its largest published magnitude (positions as published)
        scale = _floored(np.max([np.max(np.abs(v), axis=0) for v in y], axis=0), j,
                         template.joint_effort is not None)
        amp = np.max([np.abs(c) for c in spectra], axis=0)[1:] / scale   # (n/2, C)
        big = np.flatnonzero(np.max(amp, axis=1) > HARMONIC_KEEP * bound)
        harmonics = int(big[-1]) + 1 if big.size else 0
        harmonics = min(harmonics, n // 2 - 1)
        blocks = []
        for k, c in enumerate(spectra):   # rows: 1, cos m psi, sin m psi, psi (whole turns)
            per_turn = np.zeros((1, c.shape[1]))
            if k == 0:
                per_turn[0, :j] = turns
            blocks.append(np.vstack([c[:1].real, 2.0 * c[1:harmonics + 1].real,
                                     -2.0 * c[1:harmonics + 1].imag, per_turn]))
        coef = np.vstack(blocks)
        cells = _cells(runs, n)
        report = TableReport(n, harmonics, float('nan'), bound, 0.0,
                             float(np.max(cells[1])) if cells[1].size else float('nan'))
        table = cls(template, j, angular, coef, harmonics, cells, report)
        accuracy = table._verify(evaluate, n)
        report = TableReport(n, harmonics, accuracy, bound, time.perf_counter() - t0,
                             report.condition)
        table.report, table.accuracy = report, accuracy
        if not accuracy <= bound:
            raise _TooCoarse(f'verified accuracy {accuracy:.2e} exceeds the bound '
                             f'{bound:.0e} on {n} angles per turn')
        return table

    def _verify(self, evaluate, n):
        """Return the largest relative difference from ``evaluate`` off the grid."""
        k = np.arange(n)
        psi = (k + 0.5) * (TWO_PI / n) + TWO_PI * (k % 3 - 1)   # mid-grid, whole turns off
        speed = np.array(CHECK_SPEEDS)[k % len(CHECK_SPEEDS)]
        accel = np.array(CHECK_ACCELS)[k % len(CHECK_ACCELS)]
        try:
            exact = evaluate(psi, speed, accel)
        except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
            raise TableRefused(f'the core fails at a check angle: {exc}') from None
        want, got = _stack(exact), _stack(self.evaluate(psi, speed, accel))
        if not np.all(np.isfinite(want)):
            raise TableRefused('a published value is not finite at a check angle')
        diff = np.abs(got - want)
        j = self._j
        diff[:, :j] = np.where(self._angular, np.abs(wrap_angle(got[:, :j] - want[:, :j])),
                               diff[:, :j])
        scale = _floored(np.max(np.abs(want), axis=0), j, self._effort)
        rel = np.max(diff, axis=0) / np.maximum(scale, 1e-300)
        rel[scale == 0.0] = np.where(np.max(diff[:, scale == 0.0], axis=0) > 0.0,
                                     math.inf, 0.0)
        return float(np.max(rel))

    def evaluate(self, psi, speed, accel=0.0):
        """Return the published samples at crank angles ``psi`` ``(n,)``, rad/s, rad/s^2."""
        psi = np.array(psi, dtype=float, ndmin=1)
        n = psi.shape[0]
        if n == 1:
            return self._one(psi, _column(speed, 1), _column(accel, 1))
        w, a = _column(speed, n), _column(accel, n)
        x = np.mod(psi, TWO_PI)
        m = self._m.shape[0]
        # g[i, k, :] = factor k of sample i (1, w, w^2, a) times the basis at psi_i:
        # 1, cos m x (m = 1 .. M), sin m x, x (x = psi reduced to [0, 2 pi))
        g = np.empty((n, 4, 2 * m + 2))
        basis = g[:, 0, :]
        cos, sin = basis[:, 1:m + 1], basis[:, m + 1:2 * m + 1]
        np.multiply.outer(x, self._m, out=cos)
        np.sin(cos, out=sin)
        np.cos(cos, out=cos)
        basis[:, 0], basis[:, -1] = 1.0, x   # whole turns: x, not psi (no large angles)
        f = np.empty((n, 3, 1))
        f[:, 0, 0], f[:, 1, 0], f[:, 2, 0] = w, w * w, a
        np.multiply(basis[:, None, :], f, out=g[:, 1:, :])
        out = g.reshape(n, -1) @ self._coef
        sel = self._wrapped
        if sel is not None:
            out[:, sel] = wrap_angle(out[:, sel])
        out += 0.0
        return self._data(psi, w, a, out, (x * self._cell).astype(np.intp))

    def _one(self, psi, w, a):
        """Return :meth:`evaluate` of one sample (follow mode's usual case), in fewer calls."""
        x = float(psi[0]) % TWO_PI
        m = self._m.shape[0]
        g = np.empty((4, 2 * m + 2))
        basis = g[0]
        cos, sin = basis[1:m + 1], basis[m + 1:2 * m + 1]
        np.multiply(self._m, x, out=cos)
        np.sin(cos, out=sin)
        np.cos(cos, out=cos)
        basis[0], basis[-1] = 1.0, x
        speed, accel = float(w[0]), float(a[0])
        np.multiply(basis, np.array(((speed,), (speed * speed,), (accel,))), out=g[1:])
        out = g.reshape(1, -1) @ self._coef
        sel = self._wrapped
        if sel is not None:  # the few angles of one sample: wrap_angle's float path
            row = out[0]
            row[sel] = [wrap_angle(v) for v in row[sel].tolist()]
        out += 0.0
        cell = int(x * self._cell)
        return self._data(psi, w, a, out, slice(cell, cell + 1))

    def _data(self, psi, w, a, out, cell):
        """Return the RigData of the table's ``out`` rows, the diagnostics of ``cell``."""
        j = self._j
        e = 3 * j if self._effort else 2 * j
        return RigData(psi, w, a, out[:, :j], out[:, j:2 * j],
                       out[:, 2 * j:e] if self._effort else None, out[:, e:e + 3],
                       out[:, e + 3:e + 6], joint_names=self._names,
                       residual=self._cells[0][cell], condition=self._cells[1][cell],
                       near_singular=np.zeros(psi.shape[0], dtype=bool))


def _column(value, n):
    """Return ``value`` (a number or ``(n,)``) as a fresh ``(n,)`` float array."""
    v = np.array(value, dtype=float, ndmin=1)
    return v if v.shape == (n,) else np.broadcast_to(v.reshape(-1), (n,)).copy()


def _floored(scale, joints, effort):
    """Return channel scales, each at least FLOOR of its group's."""
    scale = np.array(scale, dtype=float)
    bounds = np.cumsum([0, joints, joints] + ([joints] if effort else []) + [3, 3])
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        if hi > lo:
            scale[lo:hi] = np.maximum(scale[lo:hi], FLOOR * np.max(scale[lo:hi]))
    return np.maximum(scale, 1e-300)


def _cells(runs, n):
    """Return ``(residual, condition)`` per grid cell: the worse of its two ends."""
    out = []
    for name in ('residual', 'condition'):
        values = [getattr(r, name) for r in runs]
        if any(v is None or np.size(v) != n + 1 for v in values):
            out.append(np.zeros(n))
            continue
        v = np.max(values, axis=0)
        out.append(np.maximum(v[:-1], v[1:]))
    return tuple(out)
