"""Checks of a recording and of its fit, as :class:`Finding` objects (docs/identification.md)."""

from dataclasses import dataclass, field
import math

from mech_balance.analysis.identify.model import CHANNELS, IdentifyError
from mech_balance.analysis.identify.quantization import unwrap_encoder
import numpy as np

DIFF_ORDER = 4
"""Order k of the differences whose variance / C(2k, k) estimates the white noise."""
DEGREES_MODULUS = 360.0
UNIT_SNAP_REL = 1e-3
"""Positions wrapping within this fraction of 360 are degrees."""
INTERLEAVE_RATIO = 4.0
"""Two interleaved sources: the difference noise this many times that of even/odd apart."""
STUCK_JUMP = 8.0
"""A repeated position is stuck when the increment after it is this many 99th percentiles."""
STUCK_MIN_SAMPLES = 3
FIT_RATIO_MAX = 2.0
"""Refuse a fit whose residual RMS is above this many noise floors in any channel."""
FIT_RATIO_WARN = 1.25
"""Warn above this many noise floors."""
ACCEL_GAIN_WARN = 0.02
"""Warn when the smoothing window loses this fraction of the acceleration at 1x or 2x."""
ACCEL_GAIN_REFUSE = 0.1
"""Refuse when the window loses this fraction of it at the rotation frequency."""
ENCODER_NOISE_STEPS = 3.0
"""Angle noise above this many steps / sqrt(12) names the encoder as a bad fit's cause."""


@dataclass
class Finding:
    """One thing a check found; ``action``: ``corrected``, ``warned`` or ``refused``."""

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


def noise_floor(values):
    """Return the white noise's standard deviation per column of ``values`` (samples first)."""
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

    About 1 for one source; two sources taking turns give their difference over the noise.
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


def encoder_unit(position, modulus, unit='auto'):
    """Return ``(positions in rad, Finding or None)``; ``unit`` ``rad``, ``deg`` or ``auto``."""
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
    """Return ``(keep mask, Finding or None)``: runs of a repeated position that jump after."""
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
    """Return a Finding when the encoder's noise needs a window that smooths ``motion`` away."""
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


def judge_fit(channels, rms_after, floor, motion, units, ratio_max=FIT_RATIO_MAX):
    """Return the Findings on the fit's residual against ``floor`` (refused over ``ratio_max``)."""
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


def checkable(t, values):
    """Return True when stamps and values are arrays the checks can read."""
    t = np.asarray(t, dtype=float)
    v = np.asarray(values, dtype=float)
    return (t.ndim == 1 and v.shape[:1] == t.shape and t.size >= 4 * (DIFF_ORDER + 2)
            and np.isfinite(t).all() and np.isfinite(v).all() and (np.diff(t) > 0.0).all())


def check_data(t_encoder, position_rad, t_wrench, wrench, effort, unit):
    """Return ``(t_encoder, position_rad, effort, findings)``; IdentifyError if interleaved."""
    findings = []
    if checkable(t_encoder, position_rad):
        t_encoder = np.asarray(t_encoder, dtype=float)
        pos = np.asarray(position_rad, dtype=float)
        _, modulus = unwrap_encoder(pos)
        pos, found = encoder_unit(pos, modulus, unit)
        findings += [found] if found else []
        psi, modulus = unwrap_encoder(pos)
        found = check_interleaved_encoder(psi)
        if found:
            raise IdentifyError(f'encoder: {found.evidence}; {found.way_out}')
        keep, found = stuck_runs(t_encoder, psi, modulus)
        if found:
            findings.append(found)
            t_encoder, pos = t_encoder[keep], pos[keep]
            effort = None if effort is None else np.asarray(effort, dtype=float)[keep]
        position_rad = pos
    if checkable(t_wrench, wrench) and np.ndim(wrench) == 2:
        found = check_interleaved_wrench(wrench, CHANNELS)
        if found:
            raise IdentifyError(f'wrench: {found.evidence}; {found.way_out}')
    return t_encoder, position_rad, effort, findings
