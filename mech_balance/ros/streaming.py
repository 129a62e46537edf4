"""
The live twin's numerics: a rig's joints and shaking wrench at given crank angles.

numpy only (no ROS): the rig node's publisher part (:mod:`mech_balance.ros.publisher`)
wires these pieces to topics, :mod:`mech_balance.ros.conversions` turns their arrays into
messages.

:func:`model_for`
    A scene's :class:`TwinModel` (its :class:`~mech_balance.core.rig.Rig`, of any kind):
    ``evaluate(psi, speed, accel)`` returns :class:`Samples`, every joint's position,
    velocity and effort and the shaking wrench, evaluated by the core in one vectorized
    call over a batch of crank angles.
:class:`ClockSchedule`
    Clock mode: tick ``k`` is stamped ``t_k = epoch + k * period`` and has the crank at
    ``psi_k = psi_0 + omega (t_k - epoch)``.  The tick angles are known ahead, so the core
    is evaluated on the exact angles of the next batch of ticks before they are due (no
    interpolation: a published sample is the core's at its stamped angle).
:class:`CrankEstimator`
    Follow mode: crank speed and acceleration from an encoder's positions (and velocities,
    if it sends them) by a causal least-squares polynomial fit over the last samples, with
    the checks that reject input the rig cannot have produced.
:class:`Streamer`
    The two threads that publish: clock-mode ticks on schedule from precomputed batches,
    or follow-mode samples evaluated in batches as encoder messages arrive (by the
    design's verified cycle table, :mod:`mech_balance.ros.cycle_table`, once it is built,
    unless ``follow.exact``).

Joint values and efforts: the rig's own (:mod:`mech_balance.core.planar.rig`,
:mod:`mech_balance.core.spatial.rig`).

Shaking wrench: :mod:`mech_balance.conventions` (force and moment the rig exerts on its
frame, frame axes); planar rigs about the crank pivot (force x, y, moment z), spatial rigs
about their scene's ``moment_point_m`` (the RGGR: the origin O of its frame, seed 002's foot
of the common normal on the output axis), all six components.
"""

from collections import Counter, deque
from dataclasses import dataclass
from functools import partial
import math
import threading
import time
from typing import NamedTuple

from mech_balance.core.rig import rig_for, RigData
from mech_balance.ros import cycle_table
from mech_balance.ros.guard import Guard
from mech_balance.rotations import wrap_angle
from mech_balance.schema import registry
import numpy as np

TWO_PI = 2.0 * math.pi

BATCH_SECONDS = 0.25
"""Clock mode: ticks evaluated per core call, in seconds of publishing."""
MIN_BATCH = 16
"""Clock mode: fewest ticks per core call (low rates)."""
MAX_BATCH = 4096
"""Clock mode: most ticks per core call (high rates)."""
MAX_LAG_S = 0.5
"""Clock mode: a tick later than this is skipped (counted) instead of published late."""
CLOCK_JUMP_S = 5.0
"""Clock mode: a tick later than this is a jump of the clock (``use_sim_time`` switched, a
simulation resumed), not an overload: the schedule restarts from now and no tick is counted
as skipped."""
STALL_SHARE = 0.5
"""Clock mode: a tick late by more than CLOCK_JUMP_S is a stall of the publishing thread
(not a jump of the clock) when at least this share of the clock's advance since the last
step also passed on the monotonic clock."""
NO_CLOCK_WARN_S = 3.0
"""Clock mode: the node's clock reading 0 (``use_sim_time`` true and no ``/clock`` message)
for this long is reported, and again every :data:`NO_CLOCK_REPEAT_S`."""
NO_CLOCK_REPEAT_S = 30.0
"""Interval between two reports of a clock that still reads 0."""
MAX_WAIT_S = 0.005
"""Longest single wait of the publishing thread (bounds its reaction to sim-time jumps)."""
MAX_FOLLOW_BATCH = 256
"""Follow mode: most encoder samples evaluated in one core call."""
MAX_PENDING = 10000
"""Follow mode: encoder samples waiting for evaluation before the oldest are dropped."""
STATS_WINDOW = 4096
"""Per-callback times kept for the median (the most recent ones)."""


# ------------------------------------------------------------------------------ samples


Samples = RigData
"""A batch of samples ready to publish: the Rig protocol's :class:`RigData`."""


class TwinModel:
    """
    A rig as the publisher sees it: ``evaluate(psi, speed, accel)`` returns :class:`Samples`.

    Any :class:`~mech_balance.core.rig.Rig`; the outputs evaluated are the shaking wrench and,
    when the scene asks for the driving torque (or the bearing reactions), the joint efforts.
    """

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

    # ------------------------------------------------------------------ follow mode

    def cycle_table(self):
        """
        Return the verified :class:`~mech_balance.ros.cycle_table.CycleTable`, or None.

        Built on the first call (any thread; later calls wait for it, then return it at
        once); None when the table was refused (:attr:`table_status` says why: follow mode
        then evaluates the core per sample).
        """
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
        """
        Return the :class:`Samples` of follow mode: the cycle table's once it is built.

        The exact :meth:`evaluate` until then (never waits for the build) and where the
        table was refused.
        """
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
        """
        Return the :class:`Samples` at crank angles ``psi`` ``(n,)`` (rad), rad/s, rad/s^2.

        As published: revolute joint positions wrapped to (-pi, pi], no -0.0 anywhere.
        """
        s = self.rig.at(psi, speed, accel, outputs=self.outputs)
        position = s.joint_position + 0.0
        position[:, self.angular] = wrap_angle(position[:, self.angular])
        s.joint_position, s.joint_velocity = position, s.joint_velocity + 0.0
        s.force_N, s.moment_Nm = s.force_N + 0.0, s.moment_Nm + 0.0
        if s.joint_effort is not None:
            s.joint_effort = s.joint_effort + 0.0
        return s


def finite_rows(samples):
    """Return a ``(n,)`` mask of the samples whose every published value is finite."""
    parts = [samples.joint_position, samples.joint_velocity, samples.force_N, samples.moment_Nm]
    if samples.joint_effort is not None:
        parts.append(samples.joint_effort)
    return np.isfinite(np.concatenate(parts, axis=1)).all(axis=1)


def withhold_nonfinite(samples):
    """
    Return ``(samples, ok)``: rows with a non-finite value zeroed, and the mask of good rows.

    The last check before publishing: a row that is not ``ok`` is never sent (its payload
    is None); it is zeroed only so that serializing the batch stays on the fast path.
    """
    ok = finite_rows(samples)
    if not ok.all():
        for name in ('joint_position', 'joint_velocity', 'joint_effort', 'force_N',
                     'moment_Nm'):
            values = getattr(samples, name)
            if values is not None:
                values = np.array(values, dtype=float)
                values[~ok] = 0.0
                setattr(samples, name, values)
    return samples, ok


def model_for(scene):
    """Return the :class:`TwinModel` of a scene of any kind."""
    return TwinModel(rig_for(scene))


# ------------------------------------------------------------------------------ clock


@dataclass(frozen=True)
class ClockSchedule:
    """
    Clock-mode ticks: tick k at ``epoch_ns + k period_ns`` with the crank at psi_k.

    ``psi_k = angle0_rad + speed_rad_s (k period_ns 1e-9)``, published reduced to
    [0, 2 pi); :meth:`turned` is the unreduced angle (for the recorder's timeline).
    """

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


# ------------------------------------------------------------------------------ follow


FOLLOW_WINDOW = 7
"""Encoder samples in the least-squares fit (default of ``follow.window``)."""
MAX_SAMPLE_GAP_S = 0.5
"""A longer gap between encoder stamps restarts the estimator (default ``follow.max_gap``)."""
MAX_CRANK_SPEED = 200.0
"""Fastest crank the rig can have, rad/s (default of ``follow.max_speed``)."""
RESYNC_AFTER = 10
"""Consecutive messages rejected for their stamp or step after which the estimator
re-synchronizes on the incoming stream (default of ``follow.resync_after``)."""


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
    Crank speed and acceleration from an encoder stream (follow mode).

    Each sample's position is kept as sent (the core is evaluated at it); the turned angle
    is unwrapped from the prediction of the last estimate, so encoders that wrap the angle
    and encoders that do not are both followed.  Estimates (causal, at the newest sample):

    * speed: the encoder's velocity if it sends one and ``use_encoder_velocity``; otherwise
      the slope at the newest stamp of a least-squares quadratic in time through the last
      ``window`` turned angles (a line through two; the first sample only primes);
    * acceleration: twice the quadratic's leading coefficient or, with encoder velocities,
      the slope of a least-squares line through the last ``window`` velocities.

    The fit is exact for motion at constant acceleration and averages white encoder noise
    over the window (the speed's noise falls as window^-1.5).  :meth:`update` raises
    ``ValueError`` naming the problem for a sample the rig cannot have produced: a
    non-finite value, a stamp not after the previous one, or a step that needs a crank
    faster than ``max_speed``, or an encoder velocity beyond ``max_speed``.  A gap longer
    than ``max_gap_s`` restarts the fit.

    Re-synchronization: a reading rejected for its stamp or its step
    (:class:`StreamRejected`) may be right and the history wrong (one message stamped far in
    the future, an encoder re-zeroed).  After ``resync_after`` such rejections in a row the
    history is dropped and the reading primes a new fit; ``resyncs`` counts these and
    ``last_resync`` says why (the node logs it).
    """

    def __init__(self, window=FOLLOW_WINDOW, max_speed=MAX_CRANK_SPEED,
                 max_gap_s=MAX_SAMPLE_GAP_S, use_encoder_velocity=True,
                 resync_after=RESYNC_AFTER):
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


# ------------------------------------------------------------------------------ streamer


class TickStats:
    """
    Wall time of the publishing step of each sample (for ``mech-balance bench``).

    Kept since the last change of mode, rate or speed; the median is over the most recent
    :data:`STATS_WINDOW` steps.
    """

    def __init__(self):
        self.count = 0
        self.skipped = 0
        self.withheld = 0   # samples with a non-finite value, never published
        self.late_max_s = 0.0
        self.first_tick = None  # clock mode: the first tick index sent, the last one passed
        self.last_tick = None
        self.rebased = 0        # clock mode: schedules started again (a clock jump)
        self._times = deque(maxlen=STATS_WINDOW)
        self.batch_seconds = deque(maxlen=64)
        self.batch_sizes = deque(maxlen=64)

    def add(self, seconds):
        """Record one publishing step."""
        self.count += 1
        self._times.append(seconds)

    def summary(self):
        """
        Return count, skipped ticks, the median and 99th percentile publishing step.

        ``prepare_per_sample_s`` is the compute per sample: the core's evaluation and the
        preparation (serialization) of both messages, amortized over the batches.
        """
        times = np.array(self._times) if self._times else np.zeros(1)
        per_tick = (sum(self.batch_seconds) / sum(self.batch_sizes)) if self.batch_sizes \
            else float('nan')
        return {'published': self.count, 'skipped': self.skipped, 'withheld': self.withheld,
                'step_median_s': float(np.median(times)),
                'step_p99_s': float(np.percentile(times, 99)),
                'late_max_s': self.late_max_s,
                'ticks_due': 0 if self.first_tick is None else
                self.last_tick - self.first_tick + 1, 'rebased': self.rebased,
                'prepare_per_sample_s': per_tick}


class Streamer:
    """
    The publishing threads of the rig node (no ROS inside: callables are passed in).

    ``now_ns()`` reads the node's clock; ``prepare(samples, stamps_ns)`` turns an evaluated
    batch into one payload per sample (the node: both messages, serialized);
    ``publish(payload)`` sends one; ``warn(text)`` reports a problem;
    ``record(samples, turned_rad, stamps_ns)`` (optional) receives every evaluated batch;
    ``guard`` (a :class:`mech_balance.ros.guard.Guard`, optional) counts and reports what
    the threads catch: an exception skips one step, never ends a thread.  A sample with a
    non-finite value is withheld (counted in ``stats.withheld``, warned), never published.

    Clock mode: one thread publishes tick k at its stamp from prepared batches, a second
    evaluates and prepares the next batch while the current one is published, so that a
    tick costs only the publishing of its payload.  Follow mode: encoder samples queued by
    :meth:`push` are evaluated in batches (as many as arrived while the last batch was
    evaluated), prepared and published.
    """

    def __init__(self, now_ns, prepare, publish, warn, record=None, guard=None):
        self._now_ns = now_ns
        self._guard = guard if guard is not None else Guard(warn)
        self._zero_clock_since = None   # monotonic time since the clock reads 0
        self._zero_clock_warned = None
        self._prepare = prepare
        self._publish = publish
        self._warn = warn
        self._record = record
        self._cond = threading.Condition()
        self._generation = 0
        self._mode = None
        self._model = None
        self._schedule = None
        self._batches = deque()        # (k0, payloads), contiguous, ascending
        self._next_k = None
        self._pending = deque()        # CrankSample, follow mode
        self.follow_exact = False      # follow mode: the exact core, never the cycle table
        self._stopped = False
        self._refill = threading.Event()  # wakes the precompute thread (not every tick)
        self.stats = TickStats()
        self.published_total = 0        # since the start, across restarts
        self.unanswered = Counter()     # follow mode: samples queued, never published, why
        self._last_step = None          # (node clock ns, monotonic s) of the last clock step
        self._threads = [threading.Thread(target=self._run_publisher, name='rig-publish',
                                          daemon=True),
                         threading.Thread(target=self._run_precompute, name='rig-precompute',
                                          daemon=True)]
        for t in self._threads:
            t.start()

    # -------------------------------------------------------------- control (any thread)

    def clock(self, model, speed_rad_s, period_ns, angle0_rad=0.0):
        """Publish ticks of ``model`` at ``speed_rad_s`` every ``period_ns``, continuing on."""
        with self._cond:
            now = self._now_ns()
            if self._mode == 'clock' and self._schedule is not None:
                schedule = self._schedule.rebased(now, float(speed_rad_s), int(period_ns))
            else:
                schedule = ClockSchedule(int(now), int(period_ns), float(angle0_rad),
                                         float(speed_rad_s))
            self._restart('clock', model, schedule)

    def follow(self, model):
        """Publish one sample of ``model`` per encoder sample pushed."""
        with self._cond:
            self._restart('follow', model, None)

    def set_model(self, model):
        """Publish another design (or re-prepare) from the next sample on, same schedule."""
        with self._cond:
            self._restart(self._mode, model, self._schedule, keep_pending=True)

    @property
    def clock_schedule(self):
        """Return the clock-mode :class:`ClockSchedule` in force, or None (follow mode)."""
        with self._cond:
            return self._schedule if self._mode == 'clock' else None

    def push(self, sample):
        """Queue a follow-mode :class:`CrankSample`; return False if the oldest was dropped."""
        with self._cond:
            dropped = len(self._pending) >= MAX_PENDING
            if dropped:
                self._pending.popleft()
                self.unanswered['queue full (the core fell behind)'] += 1
            self._pending.append(sample)
            self._cond.notify_all()
        return not dropped

    def stop(self, timeout=2.0):
        """Stop both threads (idempotent)."""
        with self._cond:
            self._stopped = True
            self._cond.notify_all()
        self._refill.set()
        for t in self._threads:
            if t is not threading.current_thread():
                t.join(timeout)

    def _restart(self, mode, model, schedule, keep_pending=False):
        self._last_step = None
        if not keep_pending:  # a new mode, rate or speed: statistics start again
            self.stats = TickStats()
        same_ticks = keep_pending and schedule is not None and schedule is self._schedule
        self._generation += 1
        self._mode, self._model, self._schedule = mode, model, schedule
        self._batches.clear()
        if not same_ticks:   # a design switch goes on from the next tick: none left out
            self._next_k = None
        if not keep_pending and self._pending:
            self.unanswered['discarded by a mode, rate or scene change'] += len(self._pending)
            self._pending.clear()
        self._cond.notify_all()

    # -------------------------------------------------------------- evaluation

    def _evaluate_ticks(self, model, schedule, k0, count):
        """Return the payloads of ticks ``k0 ..``: the core on their exact angles, prepared."""
        t0 = time.perf_counter()
        turned = schedule.turned(k0, count)
        samples = model.evaluate(np.mod(turned, TWO_PI), schedule.speed_rad_s, 0.0)
        stamps = schedule.epoch_ns + np.arange(k0, k0 + count, dtype=np.int64) * \
            schedule.period_ns
        payloads = self._prepared(samples, stamps)
        self.stats.batch_seconds.append(time.perf_counter() - t0)
        self.stats.batch_sizes.append(count)
        if self._record is not None:
            self._record(samples, turned, stamps)
        return payloads

    def _evaluate_follow(self, model, batch):
        """
        Evaluate queued encoder samples; on a core error, one by one (skipping bad ones).

        The model's cycle table once built (``follow_evaluate``), unless
        :attr:`follow_exact`; the exact ``evaluate`` otherwise.
        """
        t0 = time.perf_counter()
        evaluate = model.evaluate if self.follow_exact else \
            getattr(model, 'follow_evaluate', model.evaluate)
        try:
            _, angle, _, speed, accel = zip(*batch)   # the CrankSample fields, as columns
            groups = [(evaluate(angle, speed, accel), batch)]
        except ValueError:
            groups = []
            for s in batch:
                try:
                    groups.append((evaluate([s.angle_rad], [s.speed_rad_s],
                                            [s.accel_rad_s2]), [s]))
                except ValueError as exc:
                    with self._cond:
                        self.unanswered['refused by the core'] += 1
                    self._warn(f'crank_joint_state: skipped the sample at '
                               f'{s.stamp_ns * 1e-9:.9f} s: {exc}')
        out = []
        for samples, group in groups:
            stamp, _, turned, _, _ = zip(*group)
            stamps = np.array(stamp, dtype=np.int64)
            out.append(self._prepared(samples, stamps))
            if self._record is not None:
                self._record(samples, np.array(turned), stamps)
        self.stats.batch_seconds.append(time.perf_counter() - t0)
        self.stats.batch_sizes.append(len(batch))
        return [p for payloads in out for p in payloads]

    def _prepared(self, samples, stamps):
        """Prepare a batch; a sample with a non-finite value gets the payload None."""
        samples, ok = withhold_nonfinite(samples)
        payloads = list(self._prepare(samples, stamps))
        if not ok.all():
            for i in np.flatnonzero(~ok):
                payloads[i] = None
        return payloads

    def _send(self, payload):
        """Publish one payload, the last check first: None (non-finite) is withheld."""
        if payload is None:
            self.stats.withheld += 1
            self._warn(f'publishing: withheld a sample with a non-finite value '
                       f'({self.stats.withheld} so far); nothing non-finite is published')
            return
        t0 = time.perf_counter()
        self._publish(payload)
        self.stats.add(time.perf_counter() - t0)
        self.published_total += 1

    # -------------------------------------------------------------- threads

    def _run_publisher(self):
        while True:
            with self._cond:
                if self._stopped:
                    return
                mode = self._mode
                if mode is None:
                    self._cond.wait(MAX_WAIT_S * 20)
                    continue
            try:
                if mode == 'clock':
                    self._clock_step()
                else:
                    self._follow_step()
            except Exception as exc:  # noqa: BLE001 - the node never dies on a sample
                self._guard.caught('publishing failed', exc)
                time.sleep(MAX_WAIT_S)

    def _clock_step(self):
        with self._cond:
            gen, model, schedule = self._generation, self._model, self._schedule
            now = self._now_ns()
            if now == 0:  # simulated time that has not started (no /clock yet)
                self._report_zero_clock()
                self._cond.wait(MAX_WAIT_S)
                return
            self._zero_clock_since = self._zero_clock_warned = None
            if schedule.epoch_ns == 0:  # the schedule was made before the clock started
                schedule = self._schedule = ClockSchedule(
                    now, schedule.period_ns, schedule.angle0_rad, schedule.speed_rad_s)
            k = self._next_k
            if k is None:
                k = schedule.first_index_at_or_after(now)
            due = schedule.time_ns(k)
            if due > now + schedule.period_ns + int(MAX_LAG_S * 1e9):
                # the clock went back (e.g. a simulation restarted): start again from now
                self._schedule = schedule.rebased(now)
                self.stats.rebased += 1
                self._next_k = None
                self._batches.clear()
                self._generation += 1
                return
            if due > now:
                self._next_k = k
                self._cond.wait(min((due - now) * 1e-9, MAX_WAIT_S))
                return
            late = (now - due) * 1e-9
            last, mono = self._last_step, time.monotonic()
            self._last_step = (now, mono)
            held = last is not None and mono - last[1] >= STALL_SHARE * (now - last[0]) * 1e-9
            if late > CLOCK_JUMP_S and held:  # this thread was held, the clock ran on
                k_now = schedule.first_index_at_or_after(now)
                self.stats.skipped += k_now - k
                self._next_k = k_now
                self._batches.clear()
                self._warn(f'clock mode: publishing was held up for {mono - last[1]:.3g} s '
                           f'(not a clock jump: the clock advanced as much): skipped '
                           f'{k_now - k} ticks')
                return
            if late > CLOCK_JUMP_S:  # use_sim_time switched, a simulation resumed
                self._schedule = schedule.rebased(now)
                self.stats.rebased += 1
                self._next_k = None
                self._batches.clear()
                self._generation += 1
                self._warn(f'clock mode: the clock jumped forward by {late:.3g} s (use_sim_time '
                           'switched or a simulation resumed): publishing from now on, no '
                           'ticks counted as skipped')
                return
            if late > MAX_LAG_S:
                k_now = schedule.first_index_at_or_after(now)
                self.stats.skipped += k_now - k
                self._next_k = k_now
                self._batches.clear()
                self._warn(f'clock mode: skipped {k_now - k} ticks ({late:.3f} s late: the '
                           'clock jumped or the machine is overloaded)')
                return
            found = self._lookup(k)
        if found is None:  # not prepared yet (start, design change): evaluate it now
            payloads = self._evaluate_ticks(model, schedule, k, batch_size(schedule.period_ns))
            with self._cond:
                if gen != self._generation:
                    return
                self._batches.clear()
                self._batches.append((k, payloads))
                found = payloads[0]
        self._send(found)
        if self.stats.first_tick is None:
            self.stats.first_tick = k - self.stats.skipped   # skips before the first send
        self.stats.last_tick = k
        self.stats.late_max_s = max(self.stats.late_max_s, late)
        with self._cond:
            if gen == self._generation:
                self._next_k = k + 1
                if self._needs_refill():
                    self._refill.set()

    def _report_zero_clock(self):
        """Say so when the clock has read 0 for NO_CLOCK_WARN_S (lock held)."""
        now = time.monotonic()
        if self._zero_clock_since is None:
            self._zero_clock_since = now
        waited = now - self._zero_clock_since
        last = self._zero_clock_warned
        if waited >= NO_CLOCK_WARN_S and (last is None or now - last >= NO_CLOCK_REPEAT_S):
            self._zero_clock_warned = now
            self._warn(f'clock mode: not publishing: the node clock has read 0 for {waited:.0f} '
                       's (use_sim_time is true and no /clock message has arrived; start the '
                       'simulation or set use_sim_time false)')

    def _needs_refill(self):
        """Return whether less than one batch lies ahead of the next tick (lock held)."""
        if not self._batches or self._next_k is None:
            return False
        k0, last = self._batches[-1]
        return k0 + len(last) - self._next_k < batch_size(self._schedule.period_ns)

    def _lookup(self, k):
        while self._batches:
            k0, payloads = self._batches[0]
            if k < k0:
                return None
            if k < k0 + len(payloads):
                return payloads[k - k0]
            self._batches.popleft()
        return None

    def _run_precompute(self):
        """Evaluate the next clock-mode batch whenever less than one batch lies ahead."""
        while not self._stopped:
            try:
                self._precompute_step()
            except Exception as exc:  # noqa: BLE001 - reported, the publisher retries
                self._guard.caught('clock mode: evaluating ticks', exc)
                time.sleep(MAX_WAIT_S * 20)

    def _precompute_step(self):
        """Evaluate one clock-mode batch if less than one batch lies ahead."""
        self._refill.wait(MAX_WAIT_S * 20)
        self._refill.clear()
        with self._cond:
            if self._stopped:
                return
            if self._mode != 'clock' or not self._needs_refill():
                return
            k0, last = self._batches[-1]
            gen, model, schedule = self._generation, self._model, self._schedule
            k0, count = k0 + len(last), batch_size(schedule.period_ns)
        payloads = self._evaluate_ticks(model, schedule, k0, count)
        with self._cond:
            if gen == self._generation and self._batches:
                k_last, last = self._batches[-1]
                if k_last + len(last) == k0:
                    self._batches.append((k0, payloads))

    def _follow_step(self):
        with self._cond:
            if not self._pending:
                self._cond.wait(MAX_WAIT_S * 20)
                return
            gen, model = self._generation, self._model
            batch = [self._pending.popleft()
                     for _ in range(min(len(self._pending), MAX_FOLLOW_BATCH))]
        payloads = self._evaluate_follow(model, batch)
        for i, payload in enumerate(payloads):
            with self._cond:
                if gen != self._generation or self._stopped:
                    self.unanswered['evaluated for a design switched away from'] += \
                        len(payloads) - i
                    return
            self._send(payload)
