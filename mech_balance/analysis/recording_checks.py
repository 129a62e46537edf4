"""
Checks of a recording and of its fit: the identification knows when it is wrong.

Pure functions on numpy arrays (numpy only; the wiring at the end calls back into
:mod:`mech_balance.analysis.identify` for the encoder's unwrapping and the regressor),
called by :func:`mech_balance.analysis.identify.identify`.  Each returns :class:`Finding` objects:
what was found, the evidence (measured numbers), the way out, and what was done about it
(``corrected``: the data were repaired and the fit used the repair; ``warned``; ``refused``:
no calibrated scene is written).  The checks, in the order they run:

* the encoder's unit (:func:`encoder_unit`): positions that wrap at 360 are degrees;
  converted to rad (corrected);
* two encoders interleaved on one topic (:func:`interleaved`): the even and the odd
  samples each form a smooth track, the sequence does not (refused);
* an encoder so noisy that the window holding its acceleration noise to the budget
  smooths the crank's motion away (:func:`encoder_smoothing`, refused);
* a stuck encoder (:func:`stuck_runs`): a run of one repeated position followed by a jump
  no sample-to-sample motion explains; the repeated samples are dropped, so the stretch is
  a gap (corrected);
* two sensors interleaved (:func:`interleaved` on the wrench, refused; mixed ``frame_id``
  s are refused when the bag is read, :mod:`mech_balance.ros.bags`);
* the sensor's frame (:func:`frame_check`): the measured force regressed on the scene's
  model, ``f_meas = A f_model``; a gain matrix nearer a reflection, a negation or a
  rotation by more than :data:`FRAME_ANGLE_MAX_DEG` than the identity, or a negative gain
  of the moment, is a sign or axes the model does not have (refused);
* a time offset between encoder and wrench (:func:`time_offset`): the least-squares fit
  at shifted wrench stamps, its residual minimized over the shift; a significant minimum
  away from 0 is corrected (the wrench stamps moved), one at the search's edge refused;
* the fit against the noise (:func:`judge_fit`): the recording's noise floor per channel
  (:func:`noise_floor`, from high-order differences of the samples: the sensor's
  sample-to-sample noise, whatever the signal) against the calibrated fit's residual; a
  residual above :data:`FIT_RATIO_MAX` times the floor is not explained by the noise
  (refused), with the encoder's angle noise named when it is the likely cause.
"""

from dataclasses import dataclass, field
import math

import numpy as np

ACTIONS = ('corrected', 'warned', 'refused')
DIFF_ORDER = 4
"""Order k of the differences whose variance / C(2k, k) estimates the white noise: the
k-th difference passes a sinusoid of f samples per period with gain (2 sin(pi / f))^k (a
harmonic at 50 samples a period: 2.5e-4), so the signal does not leak in."""
DEGREES_MODULUS = 360.0
UNIT_SNAP_REL = 1e-3
"""Positions wrapping within this fraction of 360 are degrees."""
INTERLEAVE_RATIO = 4.0
"""Two interleaved sources: the sequence's difference noise this many times that of its
even and odd samples taken apart (one source: about 1)."""
STUCK_JUMP = 8.0
"""A run of one repeated position is a stuck encoder when the increment after it is this
many times the 99th percentile of the nonzero increments (a crank starting from rest, or
a slow one, moves a count)."""
STUCK_MIN_SAMPLES = 3
FRAME_ANGLE_MAX_DEG = 45.0
"""The measured force may differ from the scene's model by a rotation up to this angle (a
scene off by tens of percent in its inertias shifts the phase of the force)."""
FRAME_GAIN_MIN = 0.3
"""The frame is judged only where the model explains the measurement: the force's gain
matrix with both singular values, the moment's gain in magnitude, at least this (a sign or
an axis off gives about 1; a model that does not explain the data, about 0, is left to the
fit's judgement)."""
FRAME_SNR_MIN = 3.0
"""The frame is judged only when the model's force (moment) RMS is this many noise
floors."""
OFFSET_MAX_S = 0.25
"""A time offset is searched within +- this many seconds (and +- 0.4 of a mean turn)."""
OFFSET_MAX_TURNS = 0.4
OFFSET_SPAN_S = 4.0
"""The search fits at most this many seconds of the recording (the middle of it)."""
OFFSET_SAMPLES = 1500
"""Wrench samples of the search (evenly spaced)."""
OFFSET_GRID = 41
OFFSET_F = 25.0
"""A shift is significant when the residual drops by this many residual variances (a 5
standard-error change of a one-parameter fit)."""
FIT_RATIO_MAX = 2.0
"""Refuse a fit whose residual RMS is above this many noise floors in any channel.  Good
recordings: 0.99-1.06 at 1% noise and 4096 counts; up to 1.37 in 96 of test_identify_real's
384-recording grid (0.3% noise with a 1024-count encoder: its errors enter the model), all
of them within 1%; the misconfigured recordings of test_identify_faults: 2.4 and more."""
FIT_RATIO_WARN = 1.25
"""Warn above this many noise floors."""
ACCEL_GAIN_WARN = 0.02
"""Warn of an encoder whose smoothing window loses more than this fraction of the crank
acceleration at once or twice the rotation frequency (the half-turn cap loses 8e-3 at
twice)."""
ACCEL_GAIN_REFUSE = 0.1
"""Refuse it when the window loses more than this fraction at the rotation frequency (the
rig node's tests at 250 Hz: 0.023; 0.05 rad of encoder noise: 0.38-0.45)."""
ENCODER_NOISE_STEPS = 3.0
"""An encoder whose angle noise (smooth-fit residual) is above this many quantization
steps / sqrt(12) (or, unquantized, whose acceleration noise is over budget) is named as the
likely cause of a fit the noise does not explain."""


@dataclass
class Finding:
    """One thing a check found: its evidence, the way out, and what was done."""

    code: str
    action: str
    evidence: str
    way_out: str
    values: dict = field(default_factory=dict)

    def describe(self):
        """Return the finding as one line."""
        return f'{self.action.upper()} [{self.code}] {self.evidence}; {self.way_out}'

    def to_dict(self):
        """Return the finding as a plain dict."""
        return {'code': self.code, 'action': self.action, 'evidence': self.evidence,
                'way_out': self.way_out,
                'values': {k: (float(v) if isinstance(v, (float, np.floating)) else v)
                           for k, v in self.values.items()}}


def refusals(findings):
    """Return the findings that refuse the calibration."""
    return [f for f in findings if f.action == 'refused']


# ============================================================================ noise


def noise_floor(values):
    """
    Return the white noise's standard deviation per column of ``values`` (samples first).

    The variance of the :data:`DIFF_ORDER`-th difference divided by C(2k, k): exact for
    white noise, blind to a signal that is smooth over a few samples.  A sensor whose noise
    is correlated over many samples (a low-pass filter below the sampling rate) has a
    smaller floor than its noise.
    """
    v = np.asarray(values, dtype=float)
    if v.ndim == 1:
        v = v[:, None]
    if v.shape[0] <= DIFF_ORDER + 1:
        return np.zeros(v.shape[1])
    d = np.diff(v, n=DIFF_ORDER, axis=0)
    return np.sqrt(np.mean(d ** 2, axis=0) / math.comb(2 * DIFF_ORDER, DIFF_ORDER))


def interleaved(values):
    """
    Return per column the ratio of the sequence's noise floor to its even/odd samples'.

    One source gives about 1 (white noise is white at half the rate); two sources taking
    turns (two encoders, two sensors on one topic) give the size of their difference over
    the noise, as the differences alternate.
    """
    v = np.asarray(values, dtype=float)
    if v.ndim == 1:
        v = v[:, None]
    if v.shape[0] < 4 * (DIFF_ORDER + 2):
        return np.ones(v.shape[1])
    full = noise_floor(v)
    half = np.sqrt(0.5 * (noise_floor(v[0::2]) ** 2 + noise_floor(v[1::2]) ** 2))
    return np.where(half > 0.0, full / np.where(half > 0.0, half, 1.0),
                    np.where(full > 0.0, np.inf, 1.0))


# ============================================================================ encoder


def encoder_unit(position, modulus, unit='auto'):
    """
    Return ``(positions in rad, Finding or None)`` from the wrap modulus of the positions.

    ``unit`` ``rad`` takes them as given, ``deg`` converts, ``auto`` converts when they wrap
    at 360 (within :data:`UNIT_SNAP_REL`).
    """
    pos = np.asarray(position, dtype=float)
    if unit == 'rad':
        return pos, None
    if unit == 'deg':
        return np.radians(pos), Finding(
            'encoder_unit', 'corrected', 'the encoder positions are degrees (--encoder-unit '
            'deg stated)', 'converted to rad', {'modulus': modulus})
    if abs(modulus - DEGREES_MODULUS) <= UNIT_SNAP_REL * DEGREES_MODULUS:
        return np.radians(pos), Finding(
            'encoder_unit', 'corrected',
            f'the encoder positions wrap at {modulus:.6g}: degrees, not rad (their range '
            f'{float(np.min(pos)):.4g}..{float(np.max(pos)):.4g})',
            'converted to rad; --encoder-unit rad takes them as rad', {'modulus': modulus})
    return pos, None


def check_interleaved_encoder(psi_unwrapped):
    """Return a refusing Finding when the encoder samples come from two encoders, or None."""
    ratio = float(interleaved(psi_unwrapped)[0])
    if ratio <= INTERLEAVE_RATIO:
        return None
    psi = np.asarray(psi_unwrapped, dtype=float)
    m = min(psi[0::2].size, psi[1::2].size) - 1
    gap = float(np.median(psi[1::2][:m] - 0.5 * (psi[0::2][:m] + psi[0::2][1:m + 1])))
    return Finding(
        'encoder_interleaved', 'refused',
        f'the encoder samples alternate between two tracks {abs(gap):.4g} rad apart: the '
        f"sequence's sample-to-sample noise is {ratio:.3g} times that of its even and odd "
        'samples taken apart (two encoders publishing on one topic?)',
        'record one encoder on --encoder-topic (each publisher its own topic), then '
        'identify', {'ratio': ratio, 'track_gap_rad': gap})


def stuck_runs(t_s, psi_unwrapped, modulus=2.0 * math.pi):
    """
    Return ``(keep mask, Finding or None)``: runs of a repeated position that jump after.

    A run of at least :data:`STUCK_MIN_SAMPLES` equal positions followed by an increment
    above :data:`STUCK_JUMP` times the 99th percentile of the nonzero increments (wrapped
    to half a turn): the encoder repeated its last value while the crank turned.  The mask
    drops the run but its first sample, so that the time the encoder was stuck is a gap
    (:data:`mech_balance.analysis.identify.GAP_PERIODS`).
    """
    t = np.asarray(t_s, dtype=float)
    psi = np.asarray(psi_unwrapped, dtype=float)
    keep = np.ones(psi.size, dtype=bool)
    if psi.size < 8:
        return keep, None
    d = np.diff(psi)
    d = (d + 0.5 * modulus) % modulus - 0.5 * modulus
    moving = np.abs(d[d != 0.0])
    if moving.size == 0:
        return keep, None
    typical = float(np.quantile(moving, 0.99))   # of the moving ones: a slow crank's count
    same = d == 0.0
    edges = np.diff(np.concatenate([[0], same.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    # d[a:b] == 0: samples a .. b equal; the increment after the run is d[b]
    long_enough = (ends - starts + 1 >= STUCK_MIN_SAMPLES) & (ends < d.size)
    starts, ends = starts[long_enough], ends[long_enough]
    jumps = np.abs(d[ends])
    hit = (jumps > STUCK_JUMP * typical) & (jumps > 0.0)
    runs = [(int(a), int(b), float(j)) for a, b, j in zip(starts[hit], ends[hit], jumps[hit])]
    for a, b, _ in runs:
        keep[a + 1:b + 1] = False
    if not runs:
        return keep, None
    a, b, jump = max(runs, key=lambda r: r[1] - r[0])
    return keep, Finding(
        'encoder_stuck', 'corrected',
        f'the encoder repeated one position in {len(runs)} run(s), the longest '
        f'{b - a + 1} samples ({t[a]:.3f}..{t[b]:.3f} s) at {psi[a]:.6g} rad, then jumped '
        f'{jump:.4g} rad (the 99th percentile of the moving increments is {typical:.3g} rad)',
        f'{int(np.sum(~keep))} repeated samples dropped: their span is a gap, the wrench '
        'samples in it unused (check the encoder driver if this recurs)',
        {'runs': len(runs), 'dropped_samples': int(np.sum(~keep)), 'longest_s':
         float(t[b] - t[a]), 'jump_rad': jump})


def encoder_smoothing(motion, cap_turns):
    """
    Return a Finding when the encoder's noise needs a window that smooths the motion away.

    ``motion`` the :class:`~mech_balance.analysis.identify.CrankMotion`; ``cap_turns`` the
    window's cap in turns.  Above the cap the window's gain error at once and twice the
    rotation frequency (:attr:`CrankMotion.gain_error`) is the fraction of the crank
    acceleration lost: above :data:`ACCEL_GAIN_WARN` at either warned, above
    :data:`ACCEL_GAIN_REFUSE` at once refused.
    """
    gain = motion.gain_error
    worst = max(abs(gain.get('accel_1x', 0.0)), abs(gain.get('accel_2x', 0.0)))
    if worst <= ACCEL_GAIN_WARN:
        return None
    action = 'refused' if abs(gain.get('accel_1x', 0.0)) > ACCEL_GAIN_REFUSE else 'warned'
    q = motion.quantization
    turns = motion.window_s * motion.mean_speed_rad_s / (2.0 * math.pi)
    noise = (f'{q.fit_noise_rad:.3g} rad ('
             + (f'{q.fit_noise_rad / q.step_rad:.3g} steps of {q.step_rad:.3g} rad'
                if q.step_rad > 0.0 else 'not quantized') + ')')
    return Finding(
        'encoder_noise', action,
        f"the encoder's angle noise {noise} needs a smoothing window of {motion.window} "
        f'samples ({turns:.3g} turns, the cap is {cap_turns:g}) to hold the crank '
        "acceleration's noise to its budget, and that window smooths the motion away: gain "
        f"error {gain['accel_1x']:+.2g} at the rotation frequency, {gain['accel_2x']:+.2g} "
        'at twice it',
        'a quantized encoder (its step with --counts-per-turn) or one with less angle noise, '
        'or a higher encoder rate',
        {'fit_noise_rad': q.fit_noise_rad, 'window': int(motion.window),
         'gain_error_accel_1x': gain['accel_1x'], 'gain_error_accel_2x': gain['accel_2x']})


# ============================================================================ wrench


def check_interleaved_wrench(wrench, channels):
    """Return a refusing Finding when the wrench samples come from two sensors, or None."""
    ratio = interleaved(wrench)
    worst = int(np.argmax(ratio))
    if not ratio[worst] > INTERLEAVE_RATIO:
        return None
    return Finding(
        'wrench_interleaved', 'refused',
        f'the wrench samples alternate between two tracks: the sample-to-sample noise of '
        f'{channels[worst]} is {ratio[worst]:.3g} times that of its even and odd samples '
        'taken apart (two sensors publishing on one topic?)',
        'record one sensor on --wrench-topic (a rosbag2 recording: --wrench-frame-id selects '
        "one sensor's messages)", {'ratio': [float(r) for r in ratio]})


def frame_check(meas, model, floor, channels):
    """
    Return a refusing Finding when the measured wrench's sign or axes disagree with the model.

    ``meas`` and ``model`` ``(p, >= 3)``: measured and the scene's modelled [f_x, f_y, n_z]
    at the same samples; ``floor`` their noise floors.  The means are removed (the bias);
    the force's gain matrix A (f_meas = A f_model, least squares) and its polar factor R
    (the orthogonal matrix nearest A): a reflection (det R < 0), or a rotation by more than
    :data:`FRAME_ANGLE_MAX_DEG` (a negation is one by 180 degrees); the moment's gain
    negative.  Judged only where the model's signal is above :data:`FRAME_SNR_MIN` noise
    floors.
    """
    y = np.asarray(meas, dtype=float)[:, :3] - np.mean(meas, axis=0)[:3]
    x = np.asarray(model, dtype=float)[:, :3] - np.mean(model, axis=0)[:3]
    rms = np.sqrt(np.mean(x ** 2, axis=0))
    parts, values = [], {}
    force_floor = max(float(np.hypot(*floor[:2])), 1e-300)
    force_ok = np.hypot(rms[0], rms[1]) > FRAME_SNR_MIN * force_floor
    if force_ok:
        a, *_ = np.linalg.lstsq(x[:, :2], y[:, :2], rcond=None)
        a = a.T                                  # f_meas = A f_model
        u, sv, vt = np.linalg.svd(a)
        r = u @ vt
        force_ok = sv[-1] >= FRAME_GAIN_MIN
    if force_ok:
        values['force_gain'] = a.tolist()
        gain = '[[%.3g, %.3g], [%.3g, %.3g]]' % tuple(a.ravel())
        if np.linalg.det(r) < 0.0:
            # a reflection about the axis at angle phi: [[cos 2phi, sin 2phi], [sin, -cos]]
            phi = 0.5 * math.degrees(math.atan2(r[0, 1], r[0, 0]))
            what = ('x and y swapped' if abs(phi - 45.0) < 22.5 else
                    'x and y swapped and negated' if abs(phi + 45.0) < 22.5 else 'mirrored')
            parts.append(f"the measured force is the model's mirrored about the axis at "
                         f'{phi:.1f} deg ({what}; gain matrix {gain})')
            values['reflection_axis_deg'] = phi
        else:
            angle = math.degrees(math.atan2(r[1, 0], r[0, 0]))
            values['force_rotation_deg'] = angle
            if abs(angle) > FRAME_ANGLE_MAX_DEG:
                what = 'negated' if abs(angle) > 180.0 - FRAME_ANGLE_MAX_DEG else \
                    f'rotated by {angle:.1f} deg'
                parts.append(f"the measured force is the model's {what} (gain matrix {gain})")
    if rms[2] > FRAME_SNR_MIN * max(float(floor[2]), 1e-300):
        g = float(x[:, 2] @ y[:, 2] / (x[:, 2] @ x[:, 2]))
        values['moment_gain'] = g
        if g < -FRAME_GAIN_MIN:
            parts.append(f"the measured {channels[2]} is the model's negated (gain {g:.3g})")
    if not parts:
        return None
    negated = values.get('moment_gain', 1.0) < 0.0 and \
        abs(values.get('force_rotation_deg', 0.0)) > 180.0 - FRAME_ANGLE_MAX_DEG
    if negated:
        way = ('a sensor upside down, or one that reports the support reaction: '
               '--sensor-convention reaction (or the mount in --sensor-rpy / /tf_static)')
    elif 'reflection_axis_deg' in values:
        way = ('no rotation of the sensor mirrors the plane with the moment kept: its x and '
               'y channels are exchanged (wiring, driver) or its z is upside down too; '
               'correct the channels of the recording, or give the mount (--sensor-rpy, '
               '/tf_static)')
    else:
        way = ("give the sensor's mount: --sensor-rpy (a yaw of minus the rotation) or "
               '/tf_static, and --sensor-convention')
    return Finding('sensor_frame', 'refused', '; '.join(parts), way, values)


# ============================================================================ time offset


def _interp_rows(t_grid, rows, t):
    """Return ``rows`` (grid first) linearly interpolated at ``t`` (inside the grid)."""
    k = np.clip(np.searchsorted(t_grid, t) - 1, 0, t_grid.size - 2)
    f = ((t - t_grid[k]) / (t_grid[k + 1] - t_grid[k]))[:, None, None]
    return rows[k] * (1.0 - f) + rows[k + 1] * f


def _rss(y_cols, meas, weights):
    """Return the weighted residual sum of squares of the bias-free least squares."""
    a = y_cols / weights[None, :, None]
    b = meas / weights[None, :]
    a = a - a.mean(axis=0)
    b = b - b.mean(axis=0)
    a = a.reshape(-1, a.shape[2])
    b = b.reshape(-1)
    coef, *_ = np.linalg.lstsq(a, b, rcond=None)
    r = b - a @ coef
    return float(r @ r), b.size - a.shape[1] - meas.shape[1]


def time_offset(regress, motion, t_w, meas, floor):
    """
    Return ``(offset s or 0, Finding or None)``: the sensor's lag behind the encoder.

    ``regress(psi, speed, accel)`` returns the ``(p, c, n)`` regressor (scaled); ``motion``
    the longest stretch's :class:`~mech_balance.analysis.identify.CrankMotion`; ``t_w`` and
    ``meas`` the wrench stamps and measurements; ``floor`` the channels' noise floors.  The
    weighted, bias-free least squares is fitted at the wrench stamps minus a shift tau (the
    sample stamped t taken at t - tau) over a grid of :data:`OFFSET_GRID` shifts within the
    limits of :data:`OFFSET_MAX_S`, refined around the best and by a parabola.  A drop of
    the residual by more than :data:`OFFSET_F` residual variances from tau = 0 is an offset
    (corrected: the wrench stamps moved by -tau); a best shift at the edge of the search is
    refused.
    """
    t_m = motion.t_s
    turn_s = 2.0 * math.pi / motion.mean_speed_rad_s if motion.mean_speed_rad_s > 0 else 1.0
    limit = min(OFFSET_MAX_S, OFFSET_MAX_TURNS * turn_s, 0.25 * (t_m[-1] - t_m[0]))
    mid = 0.5 * (t_m[0] + t_m[-1])
    half = min(0.5 * OFFSET_SPAN_S, 0.5 * (t_m[-1] - t_m[0]))
    lo, hi = max(t_m[0], mid - half), min(t_m[-1], mid + half)
    inside = np.flatnonzero((t_w >= lo + limit) & (t_w <= hi - limit))
    if limit <= 0.0 or inside.size < 50:
        return 0.0, None
    pick = inside[np.linspace(0, inside.size - 1, min(OFFSET_SAMPLES, inside.size))
                  .astype(int)]
    ts, ms = t_w[pick], meas[pick]
    step = max(1, int((hi - lo) / motion.period_s / 2000))
    grid = t_m[(t_m >= lo) & (t_m <= hi)][::step]
    if grid.size < 4:
        return 0.0, None
    rows = regress(*motion.at(grid))
    weights = np.where(floor > 0.0, floor, 1.0)

    def rss(tau):
        return _rss(_interp_rows(grid, rows, ts - tau), ms, weights)[0]

    taus = np.linspace(-limit, limit, OFFSET_GRID)
    values = np.array([rss(tau) for tau in taus])
    best = int(np.argmin(values))
    h = taus[1] - taus[0]
    fine = np.linspace(taus[best] - h, taus[best] + h, 11)
    fine = fine[np.abs(fine) <= limit]
    fvals = np.array([rss(tau) for tau in fine])
    k = int(np.argmin(fvals))
    tau = float(fine[k])
    if 0 < k < fine.size - 1:
        y0, y1, y2 = fvals[k - 1:k + 2]
        den = y0 - 2.0 * y1 + y2
        if den > 0.0:
            tau += 0.5 * (y0 - y2) / den * (fine[1] - fine[0])
    r_best, dof = _rss(_interp_rows(grid, rows, ts - tau), ms, weights)
    r_zero = rss(0.0)
    var = r_best / max(dof, 1)
    f_stat = (r_zero - r_best) / max(var, 1e-300)
    values = {'offset_s': tau, 'f_statistic': f_stat, 'search_s': limit,
              'residual_ratio': math.sqrt(r_zero / max(r_best, 1e-300))}
    if f_stat <= OFFSET_F:
        return 0.0, None
    zero = abs(tau) * motion.mean_speed_rad_s
    if tau > 0.0:
        lag = f'{tau * 1e3:.1f} ms late (the sensor stamps its samples after they were taken'
    else:
        lag = f'{-tau * 1e3:.1f} ms early (the sensor stamps its samples before they were taken'
    evidence = (f"the wrench fits the encoder best {lag}, or the encoder's zero is off by "
                f'{zero:.3g} rad): the residual RMS drops {values["residual_ratio"]:.3g}-fold '
                f'from no shift (F = {f_stat:.3g}; searched +-{limit * 1e3:.0f} ms)')
    if abs(abs(tau) - limit) < 0.5 * (fine[1] - fine[0]) + 1e-12:
        return 0.0, Finding('time_offset', 'refused', evidence + ', at the edge of the search',
                            'stamp both streams by one clock (or shift the wrench stamps) '
                            'and identify again', values)
    return tau, Finding('time_offset', 'corrected', evidence,
                        f'the wrench stamps moved by {-tau * 1e3:+.1f} ms; synchronize the '
                        'sensor and the encoder clocks to avoid it', values)


# ============================================================================ the fit


def judge_fit(channels, rms_after, floor, motion, units, ratio_max=FIT_RATIO_MAX):
    """
    Return the Findings on the calibrated fit's residual against the noise floor.

    ``rms_after`` and ``floor`` per channel; ``motion`` the encoder's
    :class:`~mech_balance.analysis.identify.CrankMotion` (its angle noise and window are
    named when they are the likely cause); ``units`` per channel; ``ratio_max`` the
    refusal's threshold (:data:`FIT_RATIO_MAX`).
    """
    ratio = np.asarray(rms_after, dtype=float) / np.where(floor > 0.0, floor, np.inf)
    worst = int(np.argmax(ratio))
    text = ', '.join(f'{c} {a:.4g} vs {f:.3g} {u} ({r:.3g}x)'
                     for c, a, f, u, r in zip(channels, rms_after, floor, units, ratio))
    values = {'ratio': [float(r) for r in ratio], 'noise_floor': [float(f) for f in floor]}
    if ratio[worst] <= FIT_RATIO_WARN:
        return []
    q = motion.quantization
    grid_noise = q.step_rad / math.sqrt(12.0) if q.step_rad > 0.0 else 0.0
    noisy = q.fit_noise_rad > ENCODER_NOISE_STEPS * grid_noise if grid_noise > 0.0 else \
        True
    short = motion.window < motion.window_floor
    cause = ''
    if noisy or short:
        cause = (f"; the encoder's angle noise is {q.fit_noise_rad:.3g} rad ("
                 + (f'{q.fit_noise_rad / q.step_rad:.3g} steps' if q.step_rad > 0.0 else
                    'not quantized') + f") and the crank acceleration's "
                 f'{motion.predicted_std["accel_rad_s2"]:.3g} rad/s^2'
                 + (f" (the window of {motion.window} samples is below the noise floor's "
                    f'{motion.window_floor})' if short else '') + ': its errors enter the model')
    evidence = (f"the calibrated fit's residual RMS is above the recording's noise floor "
                f'(sample-to-sample, per channel): {text}{cause}')
    if ratio[worst] <= ratio_max:
        return [Finding('fit_residual', 'warned', evidence,
                        'the model explains the data nearly to the noise: check the sensor '
                        "pose and the scene's geometry if the residual matters", values)]
    way = ('a better encoder (or its stated --counts-per-turn), no --window below the floor, '
           if noisy or short else '') + \
        ("the sensor pose and convention, the encoder's zero and unit, the scene's "
         'geometry; a sensor whose noise is filtered (correlated over many samples) has a '
         f'lower floor: --max-residual-ratio R accepts a residual up to R floors '
         f'(default {FIT_RATIO_MAX:g})')
    return [Finding('fit_residual', 'refused', evidence + f'; more than {ratio_max:g} '
                    'floors: the noise does not explain the fit', way, values)]


# ============================================================================ wiring


def checkable(t, values):
    """
    Return True when stamps and values are arrays the checks can read.

    Else :func:`~mech_balance.analysis.identify.crank_motion` refuses them with its own
    message.
    """
    t = np.asarray(t, dtype=float)
    v = np.asarray(values, dtype=float)
    return (t.ndim == 1 and v.shape[:1] == t.shape and t.size >= 4 * (DIFF_ORDER + 2)
            and np.isfinite(t).all() and np.isfinite(v).all() and (np.diff(t) > 0.0).all())
