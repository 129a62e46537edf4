"""
The twin against the real rig: a force sensor's wrench compared with the model (numpy only).

Every array is SI, sample-first, wrenches as six columns :data:`COMPONENTS` in the rig
frame about the moment point.  The sensor's pose, the model of a measurement, the crank state
at a stamp, the RMS and the tare: `docs/identification.md#the-twin-against-the-real-rig`.
"""

from collections import Counter
from dataclasses import dataclass
import math

from mech_balance.rotations import rpy_matrix, TWO_PI
import numpy as np

CONVENTIONS = ('load_on_sensor', 'reaction')
"""``sensor.convention``: what the sensor reports (s = +1, -1: :data:`SIGN`)."""
SIGN = {'load_on_sensor': 1.0, 'reaction': -1.0}
COMPONENTS = ('force_x', 'force_y', 'force_z', 'torque_x', 'torque_y', 'torque_z')
"""The six columns of every wrench array here, rig frame about the moment point."""
UNITS = ('N', 'N', 'N', 'N*m', 'N*m', 'N*m')
PLANAR = (0, 1, 5)
"""Columns of the planar wrench [f_x, f_y, n_z] (:mod:`mech_balance.analysis.identify`)."""
MIN_FIT_SAMPLES = 5
"""Fewest encoder samples in a crank-state fit."""
MIN_SIDE_SAMPLES = 2
"""Fewest encoder samples on each side of a measurement's stamp in its fit."""
PAIR_TIMEOUT_S = 2.0
"""A measurement without encoder data this long (plus half the crank window) is rejected."""
PENDING_CAPACITY = 20_000
"""Most measurements waiting for encoder data (the oldest are rejected beyond)."""
PAIRED_CAPACITY = 120_000
"""Most paired measurements kept for the RMS and the tare (2 min at 1 kHz)."""
IDENTIFY_CAPACITY = 120_000
"""Most encoder and measurement samples kept for ``~/identify`` (each; 2 min at 1 kHz)."""
IDENTIFY_SPAN_S = 120.0
"""``~/identify`` uses at most the newest this many seconds of data (by stamp)."""
REST_SPEED_RAD_S = 1e-3
"""A tare whose crank speeds stay below this is taken at rest."""
RESYNC_AFTER = 10
"""Refusals in a row after which a track re-synchronizes (default of ``follow.resync_after``)."""
MAX_MEASUREMENT = 1e9
"""Largest |component| of a measured wrench accepted, N and N*m (beyond: corrupt)."""
MODEL_FLOOR = 1e-12
"""A component whose model RMS is at or below this (SI) is not modelled, nor judged."""


def _wrench_pair(force, moment, what):
    f = np.atleast_2d(np.asarray(force, dtype=float))
    m = np.atleast_2d(np.asarray(moment, dtype=float))
    if f.shape != m.shape or f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f'{what}: got force {f.shape} and torque {m.shape}, expected two '
                         '(n, 3) arrays')
    return f, m


def _point(point_m, what='point_m'):
    p = np.asarray(point_m, dtype=float).ravel()
    if p.shape == (2,):
        p = np.append(p, 0.0)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise ValueError(f'{what}: got {point_m!r}, expected a finite point (x, y, z) m')
    return p


def reduce_moment(force, moment, from_point_m, to_point_m):
    """Return the moment about ``to_point_m`` of a wrench given about ``from_point_m``."""
    f, m = _wrench_pair(force, moment, 'wrench')
    return m + np.cross(_point(from_point_m) - _point(to_point_m), f)


@dataclass(frozen=True)
class SensorPose:
    """The sensor's pose in the rig frame and its sign convention (module docstring)."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    roll: float = 0.0
    pitch: float = 0.0
    yaw: float = 0.0
    convention: str = CONVENTIONS[0]

    def __post_init__(self):
        """Check the numbers and the convention."""
        for name in ('x', 'y', 'z', 'roll', 'pitch', 'yaw'):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value)):
                raise ValueError(f'sensor.{name}: got {value!r}, expected a finite number')
        if self.convention not in CONVENTIONS:
            raise ValueError(f'sensor.convention: got {self.convention!r}, expected one of '
                             f'{", ".join(CONVENTIONS)}')

    @property
    def position_m(self):
        """Return the sensor's origin in the rig frame, ``(3,)`` m."""
        return np.array([self.x, self.y, self.z], dtype=float)

    @property
    def rotation(self):
        """Return the ``(3, 3)`` rotation from the sensor's axes to the rig's."""
        return rpy_matrix((self.roll, self.pitch, self.yaw))

    @property
    def sign(self):
        """Return +1 (load_on_sensor) or -1 (reaction)."""
        return SIGN[self.convention]

    def to_rig(self, force_sensor, torque_sensor, point_m):
        """
        Return ``(n, 6)``: measurements in the rig's axes about ``point_m``, as loads on it.

        ``force_sensor`` and ``torque_sensor`` are ``(n, 3)`` (or ``(3,)``) in the sensor's
        axes, the torque about the sensor's origin.
        """
        f_s, n_s = _wrench_pair(force_sensor, torque_sensor, 'measured_wrench')
        r = self.rotation * self.sign
        f = f_s @ r.T
        n = reduce_moment(f, n_s @ r.T, self.position_m, point_m)
        return np.hstack([f, n])

    def to_sensor(self, wrench_rig, point_m):
        """Return ``(force (n, 3), torque (n, 3))`` the sensor reports (inverse of to_rig)."""
        w = np.atleast_2d(np.asarray(wrench_rig, dtype=float))
        if w.ndim != 2 or w.shape[1] != 6:
            raise ValueError(f'wrench_rig: got shape {w.shape}, expected (n, 6)')
        n_p = reduce_moment(w[:, :3], w[:, 3:], point_m, self.position_m)
        r = self.rotation * self.sign
        return w[:, :3] @ r, n_p @ r


@dataclass(frozen=True)
class WeightModel:
    """The moving links' static weight: ``mass_kg (nb,)``, ``centre_m (nb, 3)`` (link frames)."""

    bodies: tuple
    mass_kg: np.ndarray
    centre_m: np.ndarray
    gravity_m_s2: np.ndarray

    @classmethod
    def of(cls, rig):
        """Return the weight model of a rig, or None when its model has no gravity."""
        if 'gravity' not in rig.capabilities:
            return None
        g = np.zeros(3)
        g[:len(rig.scene.gravity_m_s2)] = rig.scene.gravity_m_s2
        if not np.any(g):
            return None
        mass = {lk.name: float(lk.mass_kg) for lk in rig.scene.links}
        bodies = rig.drawing.bodies
        return cls(tuple(b.name for b in bodies), np.array([mass[b.name] for b in bodies]),
                   np.array([b.mass_centre_m for b in bodies], dtype=float), g)

    def wrench(self, poses, point_m):
        """Return ``(n, 6)``: the links' weight at ``poses`` (BodyPoses), about ``point_m``."""
        point = _point(point_m)
        n = poses.origin_m.shape[0]
        out = np.zeros((n, 6))
        for name, m, c_local in zip(self.bodies, self.mass_kg, self.centre_m):
            k = poses.names.index(name)
            c = poses.origin_m[:, k] + poses.rotation[:, k] @ c_local
            weight = m * self.gravity_m_s2
            out[:, :3] += weight
            out[:, 3:] += np.cross(c - point, weight)
        return out


def model_wrench(data, weight, point_m):
    """Return the ``(n, 6)`` model of a measurement: shaking wrench plus weight (RigData)."""
    w = np.hstack([data.force_N, data.moment_Nm])
    if weight is not None:
        w = w + weight.wrench(data.bodies, point_m)
    return w


class Series:
    """
    Samples in stamp order, at most ``capacity`` (the oldest dropped).

    One array of twice the capacity, compacted when full; allocated whole, every page written,
    at the first sample, so the node's memory stays flat while it fills.
    """

    def __init__(self, columns, capacity):
        self.capacity = int(capacity)
        self.columns = int(columns)
        self._t = np.zeros(0, dtype=np.int64)
        self._v = np.zeros((0, self.columns))
        self._lo = self._hi = 0

    @property
    def nbytes(self):
        """Return the bytes the series holds once fed (twice the capacity, stamps and values)."""
        return 2 * self.capacity * (8 + 8 * self.columns)

    def _allocate(self):
        """Allocate both arrays whole and write every page (``np.full``, not lazy zeros)."""
        self._t = np.full(2 * self.capacity, 0, dtype=np.int64)
        self._v = np.full((2 * self.capacity, self.columns), 0.0)

    def __len__(self):
        """Return the number of samples kept."""
        return self._hi - self._lo

    def clear(self):
        """Forget every sample."""
        self._lo = self._hi = 0

    def append(self, stamps_ns, values):
        """Append samples (stamps increasing, after the newest kept)."""
        t = np.atleast_1d(np.asarray(stamps_ns, dtype=np.int64))
        if t.size == 0:
            return
        v = np.asarray(values, dtype=float).reshape(t.size, -1)
        if t.size > self.capacity:
            t, v = t[-self.capacity:], v[-self.capacity:]
        self._make_room(t.size)
        self._t[self._hi:self._hi + t.size] = t
        self._v[self._hi:self._hi + t.size] = v
        self._hi += t.size
        self._lo = max(self._lo, self._hi - self.capacity)

    def _make_room(self, count):
        """Allocate at the first sample; move the newest to the front when full."""
        if not self._t.size:
            self._allocate()
        if self._hi + count > self._t.size:
            keep = min(len(self), self.capacity - count)
            self._t[:keep] = self._t[self._hi - keep:self._hi]
            self._v[:keep] = self._v[self._hi - keep:self._hi]
            self._lo, self._hi = 0, keep

    def append_one(self, stamp_ns, row):
        """Append one sample (after the newest kept): :meth:`append` without the batch."""
        self._make_room(1)
        self._t[self._hi] = stamp_ns
        self._v[self._hi] = row
        self._hi += 1
        if self._hi - self._lo > self.capacity:
            self._lo = self._hi - self.capacity

    @property
    def stamps_ns(self):
        """Return the stamps, ns, oldest first."""
        return self._t[self._lo:self._hi]

    @property
    def values(self):
        """Return the ``(n, columns)`` values, oldest first."""
        return self._v[self._lo:self._hi]

    @property
    def newest_ns(self):
        """Return the newest stamp, or None."""
        return int(self._t[self._hi - 1]) if self._hi > self._lo else None

    def truncate_from(self, stamp_ns):
        """Forget the samples stamped at or after ``stamp_ns`` (a re-synchronization)."""
        t = self.stamps_ns
        self._hi = self._lo + int(np.searchsorted(t, int(stamp_ns), side='left'))

    def since(self, stamp_ns):
        """Return ``(stamps, values)`` of the samples stamped at or after ``stamp_ns``."""
        t = self.stamps_ns
        i = int(np.searchsorted(t, stamp_ns, side='left'))
        return t[i:], self.values[i:]


class EncoderTrack:
    """
    The encoder's turned angle over time, and the crank state at any stamp inside it.

    Column 0 the turned angle (unwrapped to the branch nearest the last), column 1 the
    position as sent (what the identification smooths).
    """

    def __init__(self, window_s, capacity=IDENTIFY_CAPACITY, resync_after=RESYNC_AFTER):
        self.set_window(window_s)
        self.series = Series(2, capacity)
        self.resync_after = resync_after
        self.refused_in_a_row = 0
        self.resyncs = 0

    def set_window(self, window_s):
        """Set the fit's span, s."""
        if not (window_s > 0.0 and math.isfinite(window_s)):
            raise ValueError(f'sensor.crank_window: got {window_s!r}, expected a span > 0 s')
        self.half_ns = int(round(0.5 * window_s * 1e9))

    def add(self, stamp_ns, position_rad, turned_rad=None, resync=False):
        """
        Add an accepted encoder sample; return False if its stamp was refused.

        ``turned_rad``: the estimator's unwrapped angle, or None.  A stamp not after the
        newest is refused unless ``resync`` or it is the ``resync_after``-th in a row: then
        the samples stamped at or after it are forgotten (counted in :attr:`resyncs`).
        """
        newest = self.series.newest_ns
        raw = float(position_rad)
        turned = raw if turned_rad is None else float(turned_rad)
        if newest is not None and int(stamp_ns) <= newest:
            self.refused_in_a_row += 1
            if not resync and self.refused_in_a_row < self.resync_after:
                return False
            self.series.truncate_from(int(stamp_ns))
            self.resyncs += 1
            newest = self.series.newest_ns
        self.refused_in_a_row = 0
        if newest is not None:
            last = float(self.series.values[-1, 0])
            turned -= TWO_PI * round((turned - last) / TWO_PI)
        self.series.append_one(int(stamp_ns), (turned, raw))
        return True

    def state_at(self, stamps_ns):
        """
        Return ``(psi, speed, accel, status)`` at ``stamps_ns`` ``(n,)`` (NaN unless ok).

        ``status`` per stamp: ``'ok'``, ``'wait'`` (not passed by half a window yet), or
        why it can never be paired (``'before the encoder data'``, ``'encoder gap ...'``).
        """
        stamps = np.atleast_1d(np.asarray(stamps_ns, dtype=np.int64))
        n = stamps.size
        psi, speed, accel = np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan)
        status = ['wait'] * n
        t = self.series.stamps_ns
        if t.size == 0:
            return psi, speed, accel, status
        ang = self.series.values[:, 0]
        half = self.half_ns
        lo = np.searchsorted(t, stamps - half, side='left')
        hi = np.searchsorted(t, stamps + half, side='right')
        mid = np.searchsorted(t, stamps, side='left')
        passed = stamps + half <= t[-1]
        early = passed & (stamps - half < t[0])
        gap = passed & ~early & ((hi - lo < MIN_FIT_SAMPLES) | (mid - lo < MIN_SIDE_SAMPLES) |
                                 (hi - mid < MIN_SIDE_SAMPLES))
        ok = passed & ~early & ~gap
        status = np.where(ok, 'ok', np.where(early, 'before the encoder data', np.where(
            gap, 'encoder gap at the stamp', 'wait'))).tolist()
        idx = np.flatnonzero(ok)
        if idx.size:
            # every window padded to the longest, the padding weighted 0: one batched solve
            # of the 3x3 normal equations of the quadratic in x = (t_k - t) / (window / 2)
            width = int(np.max(hi[idx] - lo[idx]))
            k = lo[idx, None] + np.arange(width)
            weight = (k < hi[idx, None]).astype(float)
            k = np.minimum(k, t.size - 1)
            scale = half * 1e-9
            x = (t[k] - stamps[idx, None]) * (1e-9 / scale)
            ref = ang[mid[idx]]
            y = ang[k] - ref[:, None]
            powers = x[:, :, None] ** np.arange(5)                      # (m, width, 5)
            moments = np.einsum('mw,mwp->mp', weight, powers)
            normal = np.stack([moments[:, i:i + 3] for i in range(3)], axis=1)
            rhs = np.einsum('mw,mwp->mp', weight * y, powers[:, :, :3])
            c = np.linalg.solve(normal, rhs[:, :, None])[:, :, 0]
            psi[idx] = ref + c[:, 0]
            speed[idx] = c[:, 1] / scale
            accel[idx] = 2.0 * c[:, 2] / scale ** 2
        return psi, speed, accel, status


def clock_crank(schedule, stamps_ns):
    """Return ``(psi, speed, accel)`` of a :class:`~.streaming.ClockSchedule` at stamps."""
    t = np.atleast_1d(np.asarray(stamps_ns, dtype=np.int64))
    psi = schedule.angle0_rad + schedule.speed_rad_s * ((t - schedule.epoch_ns) * 1e-9)
    return psi, np.full(t.size, schedule.speed_rad_s), np.zeros(t.size)


@dataclass(frozen=True)
class BiasEstimate:
    """A tare: bias ``(6,)`` and its standard error, samples used, at rest or turning."""

    bias: np.ndarray
    std_error: np.ndarray
    samples: int
    span_s: float
    at_rest: bool

    def summary(self):
        """Return a one-line description."""
        how = 'at rest' if self.at_rest else \
            'while turning (jointly with the model: as good as the model)'
        parts = ', '.join(f'{c} {b:+.6g} +- {s:.2g} {u}' for c, b, s, u in
                          zip(COMPONENTS, self.bias, self.std_error, UNITS))
        return f'tare from {self.samples} measurements over {self.span_s:.3g} s {how}: {parts}'

    def to_dict(self):
        """Return the estimate as a plain dict."""
        return {'samples': self.samples, 'span_s': self.span_s, 'at_rest': self.at_rest,
                'bias': {c: {'estimate': float(b), 'std_error': float(s), 'unit': u}
                         for c, b, s, u in zip(COMPONENTS, self.bias, self.std_error,
                                               UNITS)}}


def estimate_bias(measured, model, speed_rad_s=None, span_s=0.0):
    """Return the :class:`BiasEstimate` of ``measured - model = bias + noise``, ``(n, 6)`` each."""
    r = np.asarray(measured, dtype=float) - np.asarray(model, dtype=float)
    n = r.shape[0]
    if n < 2:
        raise ValueError(f'tare: got {n} paired measurements, expected at least 2 (is '
                         'measured_wrench publishing, and the crank state known?)')
    std = np.std(r, axis=0, ddof=1)
    rest = speed_rad_s is not None and bool(np.all(np.abs(speed_rad_s) < REST_SPEED_RAD_S))
    return BiasEstimate(r.mean(axis=0), std / math.sqrt(n), n, float(span_s), rest)


@dataclass
class Paired:
    """Measurements paired with the model: stamps, residual (n, 6) after the bias."""

    stamps_ns: np.ndarray
    residual: np.ndarray


class Comparison:
    """
    The measured wrench against the model: pairing, residual, RMS, tare, identification data.

    Rejected input is counted by reason in :attr:`rejected`.  Not thread-safe: the node holds
    a lock around every call.
    """

    def __init__(self, pose, point_m, crank_window_s, weight=None, resync_after=RESYNC_AFTER):
        self.pose = pose
        self.point_m = _point(point_m)
        self.weight = weight
        self.bias = np.zeros(6)
        self.track = EncoderTrack(crank_window_s)
        self.pending = Series(6, PENDING_CAPACITY)     # rig frame, about the moment point
        self.measured = Series(6, IDENTIFY_CAPACITY)   # every accepted measurement
        # paired: measured (6), model without bias (6), crank speed (1)
        self.paired = Series(13, PAIRED_CAPACITY)
        self.used = 0
        self.received = 0
        self.rejected = Counter()
        self.resync_after = resync_after
        self.refused_in_a_row = 0      # measurements refused for their stamp, in a row
        self.measurement_resyncs = 0
        self.just_resynced = False
        self.last_resync = ''

    @property
    def resync_after(self):
        """Return the refusals in a row after which a track re-synchronizes."""
        return self._resync_after

    @resync_after.setter
    def resync_after(self, count):
        self._resync_after = max(1, int(count))
        self.track.resync_after = self._resync_after

    @property
    def resyncs(self):
        """Return the re-synchronizations of the encoder track and the measurements."""
        return self.track.resyncs + self.measurement_resyncs

    def measurement(self, stamp_ns, force_sensor, torque_sensor):
        """
        Take one sensor-frame reading; raise ValueError naming what is wrong.

        A stamp not after the newest is refused; the :attr:`resync_after`-th in a row
        re-synchronizes (the later measurements forgotten; :attr:`just_resynced`).
        """
        self.received += 1
        self.just_resynced = False
        f = np.asarray(force_sensor, dtype=float)
        m = np.asarray(torque_sensor, dtype=float)
        if not (np.all(np.isfinite(f)) and np.all(np.isfinite(m))):
            raise ValueError(f'wrench: got force {f.tolist()} and torque {m.tolist()}, '
                             'expected finite values')
        if max(np.max(np.abs(f)), np.max(np.abs(m))) > MAX_MEASUREMENT:
            raise ValueError(f'wrench: got force {f.tolist()} and torque {m.tolist()}, '
                             f'expected components of at most {MAX_MEASUREMENT:g} N, N*m in '
                             'magnitude')
        newest = self.measured.newest_ns
        if newest is not None and int(stamp_ns) <= newest:
            self.refused_in_a_row += 1
            if self.refused_in_a_row < self.resync_after:
                raise ValueError(f'stamp: {int(stamp_ns) * 1e-9:.9f} s is not after the '
                                 f'previous {newest * 1e-9:.9f} s, expected increasing stamps')
            self.last_resync = (f'{self.refused_in_a_row} consecutive measurements refused '
                                f'for their stamp (the newest kept: {newest * 1e-9:.9f} s)')
            for series in (self.measured, self.pending, self.paired):
                series.truncate_from(int(stamp_ns))
            self.measurement_resyncs += 1
            self.just_resynced = True
        self.refused_in_a_row = 0
        w = self.pose.to_rig(f, m, self.point_m)
        if len(self.pending) >= self.pending.capacity:
            self.rejected['no encoder data (too many waiting)'] += 1
        self.pending.append([int(stamp_ns)], w)
        self.measured.append([int(stamp_ns)], w)

    def encoder(self, stamp_ns, position_rad, turned_rad=None, resynced=False):
        """Add an accepted encoder sample (follow mode; :meth:`EncoderTrack.add`)."""
        if not self.track.add(stamp_ns, position_rad, turned_rad, resync=resynced):
            self.rejected['encoder stamp not after the newest'] += 1

    def configure(self, pose=None, crank_window_s=None):
        """Change the sensor's pose (forgets the bias and the measurements) or crank window."""
        if pose is not None and pose != self.pose:
            self.pose = pose
            self._forget_measurements()
        if crank_window_s is not None:
            self.track.set_window(crank_window_s)

    def new_model(self, weight, point_m):
        """Compare with another model: forget the paired data (another point: all the data)."""
        self.weight = weight
        self.paired.clear()
        point = _point(point_m)
        if not np.array_equal(point, self.point_m):
            self.point_m = point
            self._forget_measurements()

    def _forget_measurements(self):
        self.bias = np.zeros(6)
        self.pending.clear()
        self.measured.clear()
        self.paired.clear()

    def process(self, evaluate, schedule=None):
        """
        Pair the waiting measurements that can be paired; return their :class:`Paired`.

        ``evaluate(psi, speed, accel)`` returns the model's RigData; ``schedule``: clock
        mode's, None in follow mode.  What can never be paired is rejected (by reason).
        """
        t, w = self.pending.stamps_ns.copy(), self.pending.values.copy()
        if t.size == 0:
            return Paired(np.zeros(0, dtype=np.int64), np.zeros((0, 6)))
        if schedule is not None:
            psi, speed, accel = clock_crank(schedule, t)
            status = ['ok'] * t.size
        else:
            psi, speed, accel, status = self.track.state_at(t)
            timeout = int(PAIR_TIMEOUT_S * 1e9) + self.track.half_ns
            newest = t[-1]
            status = ['no encoder data after the stamp' if s == 'wait' and newest - ti >
                      timeout else s for s, ti in zip(status, t)]
        status = np.array(status, dtype=object)
        done = status != 'wait'
        for reason in status[done & (status != 'ok')]:
            self.rejected[reason] += 1
        ok = np.flatnonzero(status == 'ok')
        self.pending.clear()
        self.pending.append(t[~done], w[~done])
        if ok.size == 0:
            return Paired(np.zeros(0, dtype=np.int64), np.zeros((0, 6)))
        model, good = self._evaluate(evaluate, psi[ok], speed[ok], accel[ok])
        ok = ok[good]
        model = model[good]
        self.used += ok.size
        self.paired.append(t[ok], np.hstack([w[ok], model, speed[ok][:, None]]))
        return Paired(t[ok], w[ok] - model - self.bias)

    def _evaluate(self, evaluate, psi, speed, accel):
        """Return ``(model (n, 6), good (n,) bool)``: a batch, one by one if it fails."""
        wrapped = np.mod(psi, TWO_PI)
        try:
            data = evaluate(wrapped, speed, accel)
            return model_wrench(data, self.weight, self.point_m), np.ones(psi.size, bool)
        except ValueError:
            pass
        out, good = np.zeros((psi.size, 6)), np.zeros(psi.size, bool)
        for i in range(psi.size):
            try:
                data = evaluate(wrapped[i:i + 1], speed[i:i + 1], accel[i:i + 1])
                out[i] = model_wrench(data, self.weight, self.point_m)[0]
                good[i] = True
            except ValueError:
                self.rejected['model evaluation failed'] += 1
        return out, good

    def rms(self, window_s):
        """
        Return the RMS over the last ``window_s`` of paired measurements (by stamp).

        A dict: ``residual``, ``measured`` (less the bias), ``model`` ``(6,)`` each,
        ``samples``, ``oldest_ns``, ``newest_ns``; None when nothing is paired.
        """
        newest = self.paired.newest_ns
        if newest is None:
            return None
        t, v = self.paired.since(newest - int(window_s * 1e9))
        measured = v[:, :6] - self.bias
        model = v[:, 6:12]

        def rms(x):
            return np.sqrt(np.mean(x * x, axis=0))
        return {'residual': rms(measured - model), 'measured': rms(measured),
                'model': rms(model), 'samples': int(t.size), 'oldest_ns': int(t[0]),
                'newest_ns': int(t[-1])}

    def tare(self, seconds):
        """Estimate the bias from the last ``seconds`` of paired data, use it; return it."""
        newest = self.paired.newest_ns
        if newest is None:
            raise ValueError('tare: no paired measurements yet, expected measured_wrench '
                             'and the crank state (follow mode: crank_joint_state) to '
                             'stream')
        t, v = self.paired.since(newest - int(seconds * 1e9))
        est = estimate_bias(v[:, :6], v[:, 6:12], v[:, 12], (t[-1] - t[0]) * 1e-9)
        self.bias = est.bias
        return est

    def identification_data(self, schedule=None, t0_ns=None):
        """
        Return ``(t_encoder_s, angle_rad, t_wrench_s, planar_wrench (n, 3), t0_ns)``.

        The buffered encoder (with a clock-mode ``schedule``: the node's crank at the
        measurement stamps) and the measurements [f_x, f_y, n_z], bias not removed.
        """
        span_ns = int(IDENTIFY_SPAN_S * 1e9)
        tw, w = self.measured.stamps_ns, self.measured.values
        if tw.size == 0:
            raise ValueError('identify: no measured_wrench received, expected the sensor to '
                             'stream (and the encoder, in follow mode)')
        keep = tw >= tw[-1] - span_ns
        tw, w = tw[keep], w[keep]
        if schedule is not None:
            te = tw
            angle = clock_crank(schedule, te)[0]
        else:
            te = self.track.series.stamps_ns
            angle = self.track.series.values[:, 1]    # as sent: exact quantization steps
            if te.size < 2:
                raise ValueError('identify: no crank_joint_state received, expected the '
                                 'encoder to stream (follow mode)')
            recent = te >= te[-1] - span_ns
            te, angle = te[recent], angle[recent]
            inside = (tw >= te[0]) & (tw <= te[-1])
            tw, w = tw[inside], w[inside]
            if tw.size == 0:
                raise ValueError('identify: no measured_wrench stamped within the encoder '
                                 f'data ({te[0] * 1e-9:.9f} s to {te[-1] * 1e-9:.9f} s), '
                                 'expected both to stream on one clock')
        t0 = int(min(te[0], tw[0])) if t0_ns is None else int(t0_ns)
        return ((te - t0) * 1e-9, angle.copy(), (tw - t0) * 1e-9, w[:, PLANAR].copy(), t0)
