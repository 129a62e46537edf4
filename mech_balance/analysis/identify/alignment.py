"""The sensor's frame and clock judged against the scene's model (:func:`check_pose_and_time`)."""

import math

from mech_balance.analysis import cycle as analysis
from mech_balance.analysis.identify.checks import Finding
from mech_balance.analysis.identify.model import CHANNELS, regressor
import numpy as np

FRAME_ANGLE_MAX_DEG = 45.0
"""The measured force may differ from the scene's model by a rotation up to this angle."""
FRAME_GAIN_MIN = 0.3
"""The frame is judged only where the model's gains (singular values) are at least this."""
FRAME_SNR_MIN = 3.0
"""The frame is judged only when the model's force (moment) RMS is this many floors."""
OFFSET_MAX_S = 0.25
"""A time offset is searched within +- this many seconds (and +- OFFSET_MAX_TURNS)."""
OFFSET_MAX_TURNS = 0.4
"""... and within +- this fraction of a mean turn."""
OFFSET_SPAN_S = 4.0
"""The search fits at most this many seconds of the recording (the middle of it)."""
OFFSET_SAMPLES = 1500
"""Wrench samples of the search (evenly spaced)."""
OFFSET_GRID = 41
"""Shifts of the search's coarse grid."""
OFFSET_F = 25.0
"""A shift is significant when the residual drops by this many residual variances."""
MIN_ALIGNMENT_SAMPLES = 50
"""Fewest wrench samples inside the encoder's span for the frame and the clock to be judged."""


def frame_check(meas, model, floor, channels):
    """
    Return a refusing Finding when the measured wrench's sign or axes disagree with the model.

    ``meas``, ``model`` ``(p, >= 3)``: [f_x, f_y, n_z]; ``floor`` their noise floors.
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


def _evenly_spaced(indices, count):
    """Return at most ``count`` of ``indices``, evenly spaced, the first and last included."""
    return indices[np.linspace(0, indices.size - 1, min(count, indices.size)).astype(int)]


def _interp_rows(t_grid, rows, t):
    """Return ``rows`` (grid first) linearly interpolated at ``t`` (inside the grid)."""
    k = np.clip(np.searchsorted(t_grid, t) - 1, 0, t_grid.size - 2)
    f = ((t - t_grid[k]) / (t_grid[k + 1] - t_grid[k]))[:, None, None]
    return rows[k] * (1.0 - f) + rows[k + 1] * f


def _bias_free_residual(y_cols, meas, weights):
    """Return (weighted residual sum of squares, dof) of the bias-free least squares."""
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

    ``regress(psi, speed, accel)`` returns the ``(p, c, n)`` regressor; ``motion`` the
    longest stretch's; ``t_w``, ``meas`` the wrench stamps and values; ``floor`` noise floors.
    """
    t_m = motion.t_s
    turn_s = 2.0 * math.pi / motion.mean_speed_rad_s if motion.mean_speed_rad_s > 0 else 1.0
    limit = min(OFFSET_MAX_S, OFFSET_MAX_TURNS * turn_s, 0.25 * (t_m[-1] - t_m[0]))
    mid = 0.5 * (t_m[0] + t_m[-1])
    half = min(0.5 * OFFSET_SPAN_S, 0.5 * (t_m[-1] - t_m[0]))
    lo, hi = max(t_m[0], mid - half), min(t_m[-1], mid + half)
    inside = np.flatnonzero((t_w >= lo + limit) & (t_w <= hi - limit))
    if limit <= 0.0 or inside.size < MIN_ALIGNMENT_SAMPLES:
        return 0.0, None
    pick = _evenly_spaced(inside, OFFSET_SAMPLES)
    ts, ms = t_w[pick], meas[pick]
    step = max(1, int((hi - lo) / motion.period_s / 2000))
    grid = t_m[(t_m >= lo) & (t_m <= hi)][::step]
    if grid.size < 4:
        return 0.0, None
    rows = regress(*motion.at(grid))
    weights = np.where(floor > 0.0, floor, 1.0)

    def residual_at(tau):
        return _bias_free_residual(_interp_rows(grid, rows, ts - tau), ms, weights)[0]

    taus = np.linspace(-limit, limit, OFFSET_GRID)
    values = np.array([residual_at(tau) for tau in taus])
    best = int(np.argmin(values))
    h = taus[1] - taus[0]
    fine = np.linspace(taus[best] - h, taus[best] + h, 11)
    fine = fine[np.abs(fine) <= limit]
    fine_values = np.array([residual_at(tau) for tau in fine])
    k = int(np.argmin(fine_values))
    tau = float(fine[k])
    if 0 < k < fine.size - 1:
        y0, y1, y2 = fine_values[k - 1:k + 2]
        den = y0 - 2.0 * y1 + y2
        if den > 0.0:
            tau += 0.5 * (y0 - y2) / den * (fine[1] - fine[0])
    r_best, dof = _bias_free_residual(_interp_rows(grid, rows, ts - tau), ms, weights)
    r_zero = residual_at(0.0)
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


def check_pose_and_time(scene, motion, t_wrench, wrench, floor, theta0, scale):
    """Return ``(wrench stamps, findings)``: the sensor frame judged, a time offset corrected."""
    t_w = np.asarray(t_wrench, dtype=float)
    w = np.asarray(wrench, dtype=float)
    inside = np.flatnonzero((t_w >= motion.t_s[0]) & (t_w <= motion.t_s[-1]))
    if inside.size < MIN_ALIGNMENT_SAMPLES:
        return t_wrench, []
    pick = _evenly_spaced(inside, OFFSET_SAMPLES)
    rig = analysis.Rig(scene)
    model = regressor(scene, *motion.at(t_w[pick]), rig=rig).wrench @ theta0
    found = frame_check(w[pick], model, floor, CHANNELS)
    if found:
        return t_wrench, [found]
    tau, found = time_offset(
        lambda *state: regressor(scene, *state, rig=rig).wrench * scale, motion, t_w, w,
        floor[:3])
    return (t_w - tau if tau else t_wrench), ([found] if found else [])
