"""
The live twin's numerics: a rig's joints and shaking wrench at given crank angles.

numpy only; :mod:`mech_balance.ros.streamer` publishes what these evaluate.  Clock and
follow mode: `docs/node.md` (*Topics and services*, *Follow mode*).
"""

from collections import deque
from dataclasses import dataclass
from functools import partial
import math
import threading
from typing import NamedTuple

from mech_balance.core.rig import rig_for
from mech_balance.ros import cycle_table
from mech_balance.ros.params import defaults
from mech_balance.rotations import TWO_PI, wrap_angle
from mech_balance.schema import registry
import numpy as np

BATCH_SECONDS = 0.25
"""Clock mode: ticks evaluated per core call, in seconds of publishing."""
MIN_BATCH = 16
"""Clock mode: fewest ticks per core call (low rates)."""
MAX_BATCH = 4096
"""Clock mode: most ticks per core call (high rates)."""


class TwinModel:
    """A rig as the publisher sees it: ``evaluate(psi, speed, accel)`` returns a RigData."""

    def __init__(self, rig):
        self.rig = rig
        self.scene = rig.scene
        self.joint_names = tuple(rig.joint_names)
        self.crank_joint = rig.crank_joint
        self.crank_index = self.joint_names.index(rig.crank_joint)
        self.moment_point = rig.moment_point
        self.moment_point_m = tuple(float(v) for v in rig.moment_point_m)
        self.kind = registry.kind_of(rig).name
        self.has_effort = bool({'driving_torque', 'bearing_reactions'} & set(rig.outputs))
        self.outputs = ('shaking_wrench', 'driving_torque') if self.has_effort else \
            ('shaking_wrench',)
        self.angular = ~np.array(rig.joint_prismatic, dtype=bool)
        self._table_lock = threading.Lock()
        self._table = None          # the CycleTable, once built and verified
        self.table_status = None    # None: not built yet; else what follow mode evaluates

    def with_design(self, scene):
        """Return the twin of another design (inertia) of the same geometry."""
        return TwinModel(self.rig.with_scene(scene))

    def published_angular(self):
        """Return which published joint positions are angles (wrapped to (-pi, pi])."""
        return self.angular

    def cycle_table(self):
        """Return the verified CycleTable, built at the first call, or None (see table_status)."""
        with self._table_lock:
            if self.table_status is None:
                try:
                    self._table = cycle_table.CycleTable.build(self.evaluate,
                                                               self.published_angular())
                    self.table_status = self._table.report.summary()
                except cycle_table.TableRefused as exc:
                    self.table_status = f'exact core per sample (no cycle table: {exc})'
            return self._table

    def follow_evaluate(self, psi, speed, accel=0.0):
        """Return follow mode's RigData: the cycle table's once built, else :meth:`evaluate`."""
        table = self._table
        if table is None:
            return self.evaluate(psi, speed, accel)
        s = table.evaluate(psi, speed, accel)
        # the body poses (the recording's) from the core, only when they are read
        s.poses = partial(self._poses, s.crank_angle_rad, s.crank_speed_rad_s,
                          s.crank_accel_rad_s2)
        return s

    def _poses(self, psi, speed, accel):
        return self.rig.at(psi, speed, accel, outputs=self.outputs).bodies

    def evaluate(self, psi, speed, accel=0.0):
        """Return the RigData at ``psi`` ``(n,)`` as published: angles wrapped, no -0.0."""
        s = self.rig.at(psi, speed, accel, outputs=self.outputs)
        position = s.joint_position + 0.0
        position[:, self.angular] = wrap_angle(position[:, self.angular])
        s.joint_position, s.joint_velocity = position, s.joint_velocity + 0.0
        s.force_N, s.moment_Nm = s.force_N + 0.0, s.moment_Nm + 0.0
        if s.joint_effort is not None:
            s.joint_effort = s.joint_effort + 0.0
        return s


def withhold_nonfinite(samples):
    """Return ``(samples, ok)``: rows with a non-finite value zeroed, and the mask of good rows."""
    names = [n for n in ('joint_position', 'joint_velocity', 'joint_effort', 'force_N',
                         'moment_Nm') if getattr(samples, n) is not None]
    ok = np.isfinite(np.concatenate([getattr(samples, n) for n in names], axis=1)).all(axis=1)
    if not ok.all():
        for name in names:
            values = np.array(getattr(samples, name), dtype=float)
            values[~ok] = 0.0
            setattr(samples, name, values)
    return samples, ok


def model_for(scene):
    """Return the :class:`TwinModel` of a scene of any kind."""
    return TwinModel(rig_for(scene))


@dataclass(frozen=True)
class ClockSchedule:
    """Clock-mode ticks: tick k at ``epoch_ns + k period_ns``, crank at angle0 + speed t_k."""

    epoch_ns: int
    period_ns: int
    angle0_rad: float
    speed_rad_s: float

    def __post_init__(self):
        """Check the period and the angles."""
        if not (isinstance(self.period_ns, int) and self.period_ns > 0):
            raise ValueError(f'period_ns: got {self.period_ns!r}, expected an integer > 0')
        if not (math.isfinite(self.angle0_rad) and math.isfinite(self.speed_rad_s)):
            raise ValueError(f'angle0_rad, speed_rad_s: got {self.angle0_rad!r}, '
                             f'{self.speed_rad_s!r}, expected finite numbers')

    def time_ns(self, k):
        """Return the stamp of tick ``k`` (int ns on the node's clock)."""
        return self.epoch_ns + int(k) * self.period_ns

    def turned(self, k0, count):
        """Return the unreduced crank angles of ticks ``k0 .. k0 + count - 1``, rad."""
        k = np.arange(k0, k0 + count, dtype=np.int64)
        return self.angle0_rad + self.speed_rad_s * ((k * self.period_ns) * 1e-9)

    def angles(self, k0, count):
        """Return the published crank angles of ticks ``k0 ..``, in [0, 2 pi) rad."""
        return np.mod(self.turned(k0, count), TWO_PI)

    def first_index_at_or_after(self, now_ns):
        """Return the first tick whose stamp is not before ``now_ns``."""
        return -((self.epoch_ns - int(now_ns)) // self.period_ns)

    def rebased(self, epoch_ns, speed_rad_s=None, period_ns=None):
        """Return a schedule from ``epoch_ns`` on, continuing the crank angle there."""
        turned = self.angle0_rad + self.speed_rad_s * ((int(epoch_ns) - self.epoch_ns) * 1e-9)
        return ClockSchedule(int(epoch_ns), self.period_ns if period_ns is None else period_ns,
                             float(np.mod(turned, TWO_PI)),
                             self.speed_rad_s if speed_rad_s is None else speed_rad_s)


def batch_size(period_ns):
    """Return the ticks per core call for a tick period (:data:`BATCH_SECONDS` of them)."""
    return int(min(MAX_BATCH, max(MIN_BATCH, math.ceil(BATCH_SECONDS * 1e9 / period_ns))))


FOLLOW = {k[len('follow.'):]: v for k, v in defaults().items() if k.startswith('follow.')}
"""The ``follow.*`` parameters' defaults (:mod:`mech_balance.ros.params`), by short name."""


class StreamRejected(ValueError):
    """An encoder reading that contradicts the accepted history (its stamp or its step)."""


class CrankSample(NamedTuple):
    """One accepted encoder sample: the angle as sent, the turned angle, speed, accel."""

    stamp_ns: int
    angle_rad: float
    turned_rad: float
    speed_rad_s: float
    accel_rad_s2: float


class CrankEstimator:
    """
    Crank speed and acceleration from an encoder stream (follow mode; `docs/node.md#follow-mode`).

    Causal least squares at the newest sample over the last ``window`` turned angles (or the
    encoder's velocities).  :meth:`update` raises ``ValueError`` naming what the rig cannot
    have produced; after ``resync_after`` :class:`StreamRejected` in a row the history is
    dropped and the reading primes a new fit (``resyncs``, ``last_resync``).
    """

    def __init__(self, window=FOLLOW['window'], max_speed=FOLLOW['max_speed'],
                 max_gap_s=FOLLOW['max_gap'], use_encoder_velocity=FOLLOW['use_encoder_velocity'],
                 resync_after=FOLLOW['resync_after']):
        window = int(window)
        if window < 2:
            raise ValueError(f'window: got {window}, expected an integer >= 2')
        if not (max_speed > 0.0 and max_gap_s > 0.0):
            raise ValueError(f'max_speed, max_gap_s: got {max_speed!r}, {max_gap_s!r}, '
                             'expected numbers > 0')
        self.window = window
        self.max_speed = float(max_speed)
        self.max_gap_ns = int(max_gap_s * 1e9)
        self.use_encoder_velocity = bool(use_encoder_velocity)
        self.resync_after = max(1, int(resync_after))
        self.resyncs = 0
        self.last_resync = ''
        self.rejected_in_a_row = 0
        self.just_resynced = False
        self.reset()

    def reset(self):
        """Forget the history (the next sample primes a new fit)."""
        self._t = deque(maxlen=self.window)      # ns
        self._psi = deque(maxlen=self.window)    # turned angle, rad
        self._vel = deque(maxlen=self.window)    # encoder velocity or None
        self._last = None                        # last accepted CrankSample or raw tuple

    def update(self, stamp_ns, position, velocity=None):
        """Return the :class:`CrankSample` of an encoder reading, or None while priming."""
        self.just_resynced = False
        try:
            sample = self._update(stamp_ns, position, velocity)
        except StreamRejected as exc:
            self.rejected_in_a_row += 1
            if self.rejected_in_a_row < self.resync_after:
                raise
            self.resyncs += 1
            self.last_resync = (f'{self.rejected_in_a_row} consecutive messages rejected '
                                f'(the last: {exc})')
            self.reset()
            sample = self._update(stamp_ns, position, velocity)
            self.just_resynced = True
        self.rejected_in_a_row = 0
        return sample

    def _update(self, stamp_ns, position, velocity):
        stamp_ns = int(stamp_ns)
        position = float(position)
        if not math.isfinite(position):
            raise ValueError(f'position: got {position!r}, expected a finite crank angle')
        if velocity is not None:
            velocity = float(velocity)
            if not math.isfinite(velocity):
                raise ValueError(f'velocity: got {velocity!r}, expected a finite crank '
                                 'speed or none')
            if abs(velocity) > self.max_speed:  # the limit of the position steps below
                raise ValueError(f'velocity: got {velocity:.6g} rad/s, expected at most '
                                 f'follow.max_speed = {self.max_speed:g} rad/s in magnitude '
                                 '(a crank speed the rig cannot have)')
        last = self._last
        if last is not None and stamp_ns <= last[0]:
            raise StreamRejected(f'stamp: {stamp_ns * 1e-9:.9f} s is not after the previous '
                                 f'{last[0] * 1e-9:.9f} s, expected increasing stamps')
        if last is not None and stamp_ns - last[0] > self.max_gap_ns:
            self.reset()
            last = None
        if last is None:
            turned = position
        else:
            t_prev, raw_prev, turned_prev, speed_prev = last
            dt = (stamp_ns - t_prev) * 1e-9
            guess = 0.0 if speed_prev is None else speed_prev * dt
            # the turn since the last sample: the 2 pi branch nearest the prediction
            step = guess + wrap_angle(position - raw_prev - guess)
            if abs(step) > self.max_speed * dt:
                raise StreamRejected(
                    f'position: {position:.6g} rad after {raw_prev:.6g} rad in {dt:.3g} s '
                    f'needs a crank speed of {abs(step) / dt:.4g} rad/s, expected at most '
                    f'follow.max_speed = {self.max_speed:g} rad/s (a jump the linkage cannot '
                    'make)')
            turned = turned_prev + step
        self._t.append(stamp_ns)
        self._psi.append(turned)
        self._vel.append(velocity)
        speed, accel = self._estimate(velocity)
        self._last = (stamp_ns, position, turned, speed)
        if speed is None:
            return None
        return CrankSample(stamp_ns, position, turned, speed, accel)

    def _estimate(self, velocity):
        # plain Python on the few samples of the window (numpy's call overhead would be
        # most of the cost: this runs once per encoder message)
        n = len(self._t)
        t_new = self._t[-1]
        tau = [(t - t_new) * 1e-9 for t in self._t]
        if velocity is not None and self.use_encoder_velocity:
            vel = [v for v in self._vel if v is not None]
            if len(vel) < 2 or len(vel) != n:
                return velocity, 0.0
            return velocity, _slope(tau, vel)
        if n < 2:
            return None, None
        psi_new = self._psi[-1]
        if n == 2:
            return float((self._psi[0] - psi_new) / tau[0]), 0.0
        # least-squares quadratic psi(tau) about the newest stamp, tau scaled by the window
        # span (x = tau / span in [-1, 0]), in the polynomials orthogonal on the samples:
        # 1, u = x - mean, u^2 - alpha u - beta
        span = -tau[0]
        x = [t / span for t in tau]
        mean = sum(x) / n
        s2 = s3 = 0.0
        for v in x:
            u = v - mean
            uu = u * u
            s2 += uu
            s3 += uu * u
        alpha, beta = s3 / s2, s2 / n
        d1 = d2 = p2p2 = 0.0
        for v, p in zip(x, self._psi):
            u, y = v - mean, p - psi_new
            p2 = u * u - alpha * u - beta
            d1 += u * y
            d2 += p2 * y
            p2p2 += p2 * p2
        d1, d2 = d1 / s2, d2 / p2p2
        slope = d1 + d2 * (-2.0 * mean - alpha)   # d psi / dx at the newest stamp (x = 0)
        return float(slope / span), float(2.0 * d2 / span ** 2)


def _slope(x, y):
    """Return the least-squares slope of ``y`` against ``x`` (plain sequences)."""
    n = len(x)
    xm, ym = sum(x) / n, sum(y) / n
    xc = [v - xm for v in x]
    return float(sum(a * (b - ym) for a, b in zip(xc, y)) / sum(v * v for v in xc))
