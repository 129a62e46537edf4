"""The crank's angle, speed and acceleration from encoder positions (docs/identification.md)."""

from dataclasses import dataclass, field
import math

from mech_balance.analysis.identify.model import IdentifyError
from mech_balance.analysis.identify.quantization import (
    estimate_quantization, Quantization, unwrap_encoder)
from mech_balance.analysis.identify.smoothing import (
    oaconvolve, savgol_weights, SG_ORDER, window_accuracy)
import numpy as np

ACCEL_NOISE_REL = 1e-3
"""Window choice: predicted acceleration noise at most this fraction of mean speed^2."""
MAX_WINDOW_TURNS = 0.5
"""Window choice: at most this fraction of a mean crank revolution (the smoothing bias)."""
MIN_WINDOW = 2 * SG_ORDER + 3
"""Fewest samples in the smoothing window."""
UNIFORM_JITTER_REL = 1e-3
"""Stamps whose periods deviate from their median by this fraction are resampled first."""
MAX_STEP_RAD = 0.9 * math.pi
"""Largest crank step between encoder samples that unwraps unambiguously."""
GAP_PERIODS = 10.0
"""The encoder data is split where two stamps are this many median periods apart; each
stretch gets its own fit, the wrench samples inside a gap are not used."""


@dataclass
class CrankMotion:
    """
    Crank angle, speed and acceleration from encoder positions (uniform grid).

    ``predicted_std``: noise std; ``gain_error``: relative, at 1x and 2x the rotation frequency.
    """

    t_s: np.ndarray             # (p,) grid stamps, s
    psi_rad: np.ndarray         # (p,) unwrapped crank angle
    speed_rad_s: np.ndarray     # (p,)
    accel_rad_s2: np.ndarray    # (p,)
    period_s: float
    window: int                 # samples
    order: int
    quantization_rad: float
    mean_speed_rad_s: float
    resampled: bool
    predicted_std: dict = field(default_factory=dict)
    gain_error: dict = field(default_factory=dict)
    quantization: Quantization = None
    window_reason: str = ''
    window_floor: int = 0

    @property
    def window_s(self):
        """Return the smoothing window in seconds."""
        return self.window * self.period_s

    def at(self, t_s):
        """Return (psi, speed, accel) interpolated to stamps ``t_s`` (s) in the valid span."""
        t_s = np.asarray(t_s, dtype=float)
        return tuple(np.interp(t_s, self.t_s, v)
                     for v in (self.psi_rad, self.speed_rad_s, self.accel_rad_s2))

    def to_dict(self):
        """Return the settings and accuracy of the estimate as a plain dict."""
        return {'period_s': self.period_s, 'window_samples': int(self.window),
                'window_s': self.window_s, 'order': int(self.order),
                'quantization_rad': self.quantization_rad,
                'counts_per_turn': 2.0 * math.pi / self.quantization_rad
                if self.quantization_rad > 0.0 else None,
                'mean_speed_rad_s': self.mean_speed_rad_s, 'resampled': bool(self.resampled),
                'predicted_std': dict(self.predicted_std),
                'gain_error': dict(self.gain_error),
                'quantization': None if self.quantization is None else
                self.quantization.to_dict(),
                'window_reason': self.window_reason, 'window_floor': self.window_floor}


def _checked_samples(t_s, position_rad):
    """Return the encoder's (stamps, positions) as float arrays, or raise naming the fault."""
    t = np.asarray(t_s, dtype=float).ravel()
    pos = np.asarray(position_rad, dtype=float).ravel()
    if t.shape != pos.shape:
        raise IdentifyError(f'encoder: {t.size} stamps and {pos.size} positions, expected '
                            'one stamp per position')
    if not (np.isfinite(t).all() and np.isfinite(pos).all()):
        bad = int(np.flatnonzero(~(np.isfinite(t) & np.isfinite(pos)))[0])
        raise IdentifyError(f'encoder: sample {bad} has stamp {t[bad]!r} and position '
                            f'{pos[bad]!r}, expected finite values')
    if t.size < MIN_WINDOW + 2:
        raise IdentifyError(f'encoder: {t.size} samples, expected at least {MIN_WINDOW + 2}')
    steps = np.diff(t)
    if not (steps > 0.0).all():
        i = int(np.flatnonzero(~(steps > 0.0))[0])
        raise IdentifyError(f'encoder: sample {i + 1} stamp {t[i + 1]:.9f} s is not after '
                            f'sample {i} stamp {t[i]:.9f} s, expected increasing stamps')
    return t, pos


def crank_motion(t_s, position_rad, window=None, order=SG_ORDER, quantization_rad=None,
                 counts_per_turn=None):
    """
    Return the :class:`CrankMotion` of encoder samples (stamps s, positions rad).

    ``window`` (odd) overrides the choice; ``counts_per_turn`` or ``quantization_rad`` the step.
    """
    t, pos = _checked_samples(t_s, position_rad)
    steps = np.diff(t)
    period = float(np.median(steps))
    if quantization_rad is not None and counts_per_turn is None and quantization_rad > 0.0:
        counts_per_turn = 2.0 * math.pi / float(quantization_rad)
    quant = estimate_quantization(pos, counts_per_turn, t)
    psi, _ = unwrap_encoder(pos)
    if np.max(np.abs(np.diff(psi))) > MAX_STEP_RAD:
        raise IdentifyError('encoder: the crank turns by nearly half a revolution or more '
                            'between samples (or the angle jumps), expected a faster encoder '
                            'rate')
    resampled = bool(np.max(np.abs(steps - period)) > UNIFORM_JITTER_REL * period)
    if resampled:
        grid = t[0] + period * np.arange(int(math.floor((t[-1] - t[0]) / period)) + 1)
        psi = np.interp(grid, t, psi)
        t = grid
    sigma = quant.noise_rad
    speed_mean = abs(psi[-1] - psi[0]) / (t[-1] - t[0])
    turn_hz = speed_mean / (2.0 * math.pi)
    cap = MAX_WINDOW_TURNS / turn_hz / period if turn_hz > 0.0 else t.size
    cap = max(MIN_WINDOW, min(int(cap), t.size - 2)) | 1
    target = ACCEL_NOISE_REL * speed_mean ** 2
    # the noise floor: the shortest window whose acceleration noise is within the budget
    floor = MIN_WINDOW
    limit = (t.size - 2) | 1
    while floor < limit:
        accel_weights = savgol_weights(floor | 1, order, period)[2]
        if sigma * np.linalg.norm(accel_weights) <= target:
            break
        floor = int(floor * 1.1) + 2
    floor = min(floor | 1, limit if limit <= t.size else limit - 2)
    if window is None:
        window = max(floor, MIN_WINDOW)
        if floor > cap:
            reason = (f'the acceleration noise budget ({ACCEL_NOISE_REL:g} x mean speed^2 = '
                      f'{target:.3g} rad/s^2 from angle noise {sigma:.3g} rad) needs {floor} '
                      f'samples, above the {MAX_WINDOW_TURNS:g}-turn smoothing-bias cap of '
                      f'{cap}: the noise floor wins')
        else:
            reason = (f'the shortest window whose acceleration noise (angle noise '
                      f'{sigma:.3g} rad) is within the budget {ACCEL_NOISE_REL:g} x mean '
                      f'speed^2 = {target:.3g} rad/s^2 (cap {MAX_WINDOW_TURNS:g} turn = {cap} '
                      'samples)')
    else:
        reason = f'--window {int(window) | 1} stated'
        if (int(window) | 1) < floor:
            reason += (f', below the noise floor of {floor} samples: the acceleration noise '
                       'exceeds the budget')
    window = int(window) | 1
    if not (order + 2 <= window <= t.size):
        raise IdentifyError(f'window: got {window} samples, expected an odd number from '
                            f'{order + 2} to the {t.size} encoder samples')
    weights = savgol_weights(window, order, period)
    # samples within half a window of either end have no centred fit: dropped
    psi_s, speed, accel = (oaconvolve(psi - psi[0], wd[::-1], mode='valid') for wd in weights)
    half = (window - 1) // 2
    std, gain = window_accuracy(window, order, period, sigma, turn_hz)
    return CrankMotion(t[half:t.size - half], psi_s + psi[0], speed, accel, period, window,
                       order, quant.step_rad, speed_mean, resampled, std, gain, quant, reason,
                       int(floor))


@dataclass
class EncoderSegment:
    """A stretch of encoder data between gaps (:data:`GAP_PERIODS`); ``reason``: why unused."""

    start_s: float
    end_s: float
    encoder_samples: int
    wrench_samples: int = 0
    used: bool = True
    reason: str = ''

    def to_dict(self):
        """Return the stretch as a plain dict."""
        return {'start_s': float(self.start_s), 'end_s': float(self.end_s),
                'encoder_samples': int(self.encoder_samples),
                'wrench_samples': int(self.wrench_samples), 'used': bool(self.used),
                'reason': self.reason}


def encoder_segments(t_s, position_rad, gap_periods=GAP_PERIODS):
    """
    Return the encoder data split at its gaps: a list of ``(t, position)`` arrays.

    Data that cannot be split is returned whole, for :func:`crank_motion` to refuse.
    """
    t = np.asarray(t_s, dtype=float).ravel()
    pos = np.asarray(position_rad, dtype=float).ravel()
    if t.shape != pos.shape or t.size < 3 or not np.isfinite(t).all():
        return [(t, pos)]
    steps = np.diff(t)
    if not (steps > 0.0).all():
        return [(t, pos)]
    cut = np.flatnonzero(steps > gap_periods * np.median(steps)) + 1
    bounds = np.concatenate([[0], cut, [t.size]])
    return [(t[a:b], pos[a:b]) for a, b in zip(bounds[:-1], bounds[1:])]


def segment_motions(t_encoder, position_rad, window, quantization_rad, counts_per_turn):
    """
    Return ``(main motion, [(motion or None, EncoderSegment)])`` over the encoder's stretches.

    The longest stretch sets the window and quantization for the others.
    """
    pieces = encoder_segments(t_encoder, position_rad)
    main = max(range(len(pieces)), key=lambda k: pieces[k][0].size)
    motion = crank_motion(*pieces[main], window, quantization_rad=quantization_rad,
                          counts_per_turn=counts_per_turn)
    out = []
    for k, (t, pos) in enumerate(pieces):
        segment = EncoderSegment(float(t[0]), float(t[-1]), int(t.size))
        fitted = motion if k == main else None
        if k != main:
            if t.size < motion.window + 2:
                segment.used, segment.reason = False, (
                    f'{t.size} samples, shorter than the {motion.window}-sample window + 2')
            else:
                try:
                    fitted = crank_motion(t, pos, motion.window,
                                          counts_per_turn=motion.quantization.counts_per_turn)
                except IdentifyError as exc:
                    segment.used, segment.reason = False, str(exc)
        out.append((fitted, segment))
    return motion, out
