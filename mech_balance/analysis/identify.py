"""
Identification of a planar rig's inertial parameters from its encoder and force sensor.

Pure functions on numpy arrays (numpy and scipy only): the ``identify`` command feeds them
the arrays of a recording (:mod:`mech_balance.bags`), the rig node its buffered samples.

Measurement model
    The sensor reports the wrench the moving links exert on the frame, in the frame's axes
    and about the crank pivot O (the sign and frame of :mod:`mech_balance.conventions`),
    planar components (f_x, f_y, n_z).  By Newton and Euler for the moving links as a whole
    that wrench is the shaking wrench (seed 001 eq. 39: -dp/dt, -dH_O/dt) plus the static
    weight of the links, which the conventions leave out of the shaking wrench but a sensor
    under a rig whose plane is not horizontal measures:

        w_k = f_sh(psi_k, psid_k, psidd_k; theta) + sum_i [m_i g,  (c_i - O) x m_i g] + b + e_k

    with g the scene's gravity (in the plane of motion), b a constant sensor bias and e_k
    the sensor noise.  For a given motion both terms are linear in the links' inertial
    parameters theta = (m, m c_x, m c_y, I_O) per link (seed 001 eqs. 25-26, 39): the
    shaking part is evaluated by the core (:func:`mech_balance.dynamics.inverse_dynamics`)
    at the 4 n unit parameter vectors on one kinematic solution at the measured crank
    states (the idea of :func:`mech_balance.analysis.linear_maps.linear_maps`, here with per-sample
    speed and acceleration), the weight part from the link poses:
    ``(c_i - O) x m_i g = (m_i (o_i - O) + R_i h_i) x g``.  When the encoder reports effort
    (the motor torque) the driving torque tau_k = Y_tau theta + b_tau + e_k is stacked
    below (the core's power balance, gravity included; b_tau absorbs a constant friction).

Crank motion (:func:`crank_motion`)
    The encoder gives quantized positions only.  The angle is unwrapped and smoothed by a
    Savitzky-Golay filter (a least-squares polynomial of order :data:`SG_ORDER` over a
    sliding window, evaluated with its first and second derivatives at the window's
    centre).  The window is the shortest one whose predicted acceleration noise from the
    quantization (step q, uniform error of standard deviation q / sqrt(12), white) is below
    :data:`ACCEL_NOISE_REL` times the mean crank speed squared, but at most
    :data:`MAX_WINDOW_TURNS` of a mean revolution (the crank's speed varies at multiples
    of the rotation frequency; over half a turn an order-6 fit passes them with a gain
    error of 1.5e-4 at once and 8e-3 at twice the rotation frequency).  The predicted
    standard deviations of angle, speed and acceleration and the gain errors at one and two
    times the rotation frequency are returned with the estimate (:class:`CrankMotion`);
    samples within half a window of either end are dropped.  Non-uniform stamps are
    resampled (linearly) to the median period first.

Least squares, base parameters (:func:`identify`)
    Columns are scaled per link by the scene's own size (m, m l, m l, m l^2, l the radius
    of gyration about the link origin: :func:`parameter_scales`) and rows weighted by one
    noise level per channel (f_x, f_y, n_z, tau), re-estimated from the residuals
    (:data:`WEIGHT_PASSES` passes).  The bias is a free nuisance parameter: it is
    projected out (per-channel mean removed), and the SVD of what remains gives the
    numerical rank (singular values above :data:`RANK_RTOL` times the largest), the
    condition number of the identifiable part and the row space.  The estimate keeps the
    non-identifiable directions at the scene's values, the minimum-norm deviation from the
    prior: theta = theta_scene + V1 V1^T (theta_ls - theta_scene) (scaled coordinates).
    The identifiable combinations are reported as base parameters: a QR factorization with
    column pivoting of V1^T picks r parameters, and the basis of the row space is
    normalized to have coefficient 1 on its own base parameter and 0 on the others.
    Standard errors follow from the residual variance: Cov = s^2 V1 S1^-2 V1^T (scaled).
    The solve runs on the per-channel QR factors of [Y_c | r_c] (exact, small).  Errors
    in the estimated crank acceleration enter as errors in the variables: on the
    slider-crank at 5 rev/s they bias the crank-inertia combinations by about 1-2 standard
    errors (measured on the synthetic rig).
    The bias estimate is b = mean(w - Y theta); when the static weight of links that only
    rotate about a frame pivot (a crank, a rocker) is constant it is
    confounded with the bias, and then the bias reported is b + G (theta - theta_scene),
    whose coefficients G are returned (:attr:`Identification.bias_confounding`).
"""

from dataclasses import dataclass, field, replace
import math

from mech_balance import schema
from mech_balance.analysis import cycle as analysis
from mech_balance.analysis import recording_checks as checks
from mech_balance.analysis.linear_maps import linear_maps
from mech_balance.conic import solver_settings
from mech_balance.core.planar import dynamics
from mech_balance.core.planar.rig import objective_units
from mech_balance.schema.scene import INERTIA_ROUNDOFF
import numpy as np
import scipy.linalg

SG_ORDER = 6
"""Order of the Savitzky-Golay polynomial fitted to the unwrapped encoder angle."""
ACCEL_NOISE_REL = 1e-3
"""Window choice: predicted crank acceleration noise (from the quantization) at most this
fraction of the mean crank speed squared."""
MAX_WINDOW_TURNS = 0.5
"""Window choice: at most this fraction of a mean crank revolution (bounds the smoothing
bias of speed variations at the rotation frequency and its harmonics).  Measured on the
synthetic rigs: Hoeken at 1 rev/s takes 379 samples (the noise target, 0.38 turn), the
slider-crank at 5 rev/s 99 (this cap), acceleration noise 0.034 and 0.96 rad/s^2."""
QUANT_TOL = 0.1
"""An increment agrees with a step q when it is within this many q of a multiple of q."""
QUANT_FRACTION_MIN = 0.99
"""An encoder step is accepted when at least this fraction of the nonzero increments agree
with it (QUANT_TOL); the largest such step is the encoder's.  The confidence printed is the
fraction that agrees (white angle noise of s = 0.03 q leaves 0.999 in, an unquantized
encoder 2 QUANT_TOL = 0.2)."""
QUANT_CLUSTER_MIN = 0.005
"""A level of the increments holding at least this fraction of them is a major level."""
QUANT_CLUSTER_COVER = 0.9
"""The major levels must hold this fraction of the increments (else: not quantized)."""
QUANT_MAX_INCREMENTS = 20000
"""Increments the step search tests at most (evenly spaced over the recording)."""
QUANT_SPLIT_RATIO = 30.0
"""Sorted gaps between distinct positions jump by at least this ratio from the noise floor
(float round-off, float32 positions: below 1e-6 rad) to the encoder step (above 6e-4 rad for
10 000 counts per turn)."""
QUANT_GAP_QUANTILE = 0.02
"""Candidate step: this quantile of the gaps above the noise floor (robust to a few stray
positions between two counts)."""
QUANT_MAX_DIVISOR = 8
"""The candidate step may be this many encoder steps (counts missing from a short
recording); divisors up to this are tried."""
QUANT_REFINE_PASSES = 2
"""Least-squares passes refining the step on the increments."""
COUNT_SNAP = 0.05
"""A step within this many counts of an integer number of counts per modulus is snapped."""
MODULUS_SNAP_REL = 1e-3
"""A wrap modulus within this fraction of 2 pi is 2 pi."""
FIT_NOISE_WINDOW = 31
"""Samples of the smooth fit whose residual measures the angle noise (order SG_ORDER)."""
MIN_MASS_REL = 1e-3
"""Consistency: every calibrated link's mass at least this fraction of its scene mass."""
INERTIA_MARGIN_REL = 1e-7
"""Consistency: the centroidal inertia at least this fraction of the link's m l^2 (above the
cone solver's feasibility tolerance, so the written inertia is >= 0 after round-off)."""
CONFIDENCE_SE = 3.0
"""The data's confidence region: every combination within this many standard errors."""
LS_TIE_REL = 1e-9
"""Constrained least squares: weight of the pull towards the scene (times the largest
squared singular value), choosing among equally good fits in the unseen directions."""
ACTIVE_REL = 1e-5
"""A consistency constraint whose slack is below this (relative) is reported active."""
MIN_WINDOW = 2 * SG_ORDER + 3
"""Fewest samples in the smoothing window."""
UNIFORM_JITTER_REL = 1e-3
"""Encoder stamps whose periods deviate from their median by more than this fraction are
resampled to a uniform grid before smoothing."""
MAX_STEP_RAD = 0.9 * math.pi
"""Largest crank step between encoder samples that unwraps unambiguously."""
MIN_TURNS = 1.0
"""A recording must turn the crank at least this many revolutions in its usable span."""
GAP_PERIODS = 10.0
"""The encoder data is split into stretches where two stamps are further apart than this
many median encoder periods (dropped messages, a stopped encoder): each stretch gets its own
crank-motion fit, and the wrench samples inside a gap, whose motion is unknown, are not
used (:func:`encoder_segments`)."""

RANK_RTOL = 1e-7
"""Singular values of the scaled, weighted, bias-free regressor at or below this fraction of
the largest span its null space: structurally non-identifiable combinations sit at
round-off (at most 3e-13 relative on the synthetic Hoeken and slider-crank rigs), every
excited one above 2e-4 there."""
CONFOUND_RTOL = 1e-9
"""A bias channel whose sensitivity to the non-identifiable directions is below this
fraction of the channel's regressor size is identifiable on its own."""
COEFF_PRINT_RTOL = 1e-6
"""Coefficients of a base-parameter combination smaller than this (in the rig's units) are
left out of its printed form (kept in the numbers)."""
WEIGHT_PASSES = 3
"""Least-squares passes: the first weights each channel by its measured RMS, the next by
the residual noise level of the previous pass."""
CHANNELS = ('force_x', 'force_y', 'moment_z')
"""Wrench channels of a planar rig (rig frame, about the crank pivot)."""
TORQUE_CHANNEL = 'torque'
"""Channel of the driving torque (from the encoder's effort), stacked when present."""
CHANNEL_UNITS = {'force_x': 'N', 'force_y': 'N', 'moment_z': 'N*m', 'torque': 'N*m'}
PARAMETERS = ('m', 'hx', 'hy', 'I_O')
"""Per link: mass (kg), first moment m c_x and m c_y in the link frame (kg*m), inertia about
the link origin (kg*m^2), the order of :func:`mech_balance.dynamics.parameter_vector`."""
PARAMETER_UNITS = ('kg', 'kg*m', 'kg*m', 'kg*m^2')


SPATIAL_NOT_YET = (
    'identification of a spatial rig (kind spatial) is not implemented yet: the '
    'encoder model, the base-parameter fit and the physically consistent calibration are '
    'written for planar links (4 parameters each: m, m c_x, m c_y, I_O); a spatial body has 10 '
    '(m, m c, the inertia tensor), and the pieces a spatial identification would stand on '
    "exist (the rigs' body kinematics and core/regressor.py, the six-component wrench as a "
    'linear map of them) but are not wired into identify yet')
"""Why ``identify`` refuses a spatial scene (printed in its error)."""


class IdentifyError(ValueError):
    """Identification input is missing, inconsistent or cannot determine the parameters."""


# ============================================================================ crank motion


def oaconvolve(*args, **kwargs):
    """
    Return :func:`scipy.signal.oaconvolve` (imported on first use).

    Importing ``scipy.signal`` costs about 0.6 s, and this module is imported by every
    ``balance`` call (a calibrated scene's +-1 SE); only the crank-motion fit convolves.
    """
    from scipy.signal import oaconvolve as convolve
    return convolve(*args, **kwargs)


@dataclass
class Quantization:
    """
    The encoder's quantization step and the angle noise the window choice rests on.

    ``step_rad`` is 0 when the positions are not quantized (``source`` says which:
    ``estimated``, ``stated`` by ``--counts-per-turn``, or ``not quantized``);
    ``confidence`` the fraction of the nonzero increments within :data:`QUANT_TOL` steps of
    a multiple of the step (:func:`_fraction_on_grid`);
    ``noise_rad`` the standard deviation of the angle noise used for the window: the larger
    of q / sqrt(12) and the residual of a smooth fit (:func:`fit_noise`).
    """

    step_rad: float
    confidence: float
    source: str
    modulus_rad: float
    noise_rad: float
    fit_noise_rad: float

    @property
    def counts_per_turn(self):
        """Return 2 pi / step, or None when not quantized."""
        return 2.0 * math.pi / self.step_rad if self.step_rad > 0.0 else None

    def describe(self):
        """Return the step, its confidence and its source in words."""
        if self.step_rad <= 0.0:
            return (f'not quantized (no step has {QUANT_FRACTION_MIN:g} of the increments '
                    f'within {QUANT_TOL:g} step of its multiples); angle noise '
                    f'{self.fit_noise_rad:.3g} rad '
                    'from the residual of a smooth fit')
        return (f'encoder step {self.step_rad:.6g} rad ({self.counts_per_turn:.6g} counts per '
                f'turn, {self.source}; {self.confidence:.4f} of the increments on its grid), '
                f'wrapping at {self.modulus_rad:.6g} rad')

    def to_dict(self):
        """Return the estimate as a plain dict."""
        return {'step_rad': self.step_rad, 'counts_per_turn': self.counts_per_turn,
                'confidence': self.confidence, 'source': self.source,
                'modulus_rad': self.modulus_rad, 'noise_rad': self.noise_rad,
                'fit_noise_rad': self.fit_noise_rad}


@dataclass
class CrankMotion:
    """
    Crank angle, speed and acceleration estimated from encoder positions (uniform grid).

    ``predicted_std`` is the standard deviation from the quantization alone (angle rad,
    speed rad/s, acceleration rad/s^2); ``gain_error`` the relative error of speed and
    acceleration for a sinusoidal speed variation at 1x and 2x the mean rotation frequency.
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
        """
        Return (psi, speed, accel) interpolated to stamps ``t_s`` (s) in the valid span.

        Linear interpolation on the grid (its error in the angle is below
        period^2 |psidd| / 8, far below the quantization).
        """
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


def unwrap_encoder(position_rad):
    """
    Return ``(unwrapped angle, modulus)`` of encoder positions that may wrap at any modulus.

    A wrap is an increment larger than half the positions' range; the modulus M follows
    from the wraps: a wrap of d while the crank turns by the median increment delta is
    d = delta - M sign(rotation), so M = median(|d - delta|).  A modulus within
    :data:`MODULUS_SNAP_REL` of 2 pi is taken as 2 pi.  Positions without a wrap keep 2 pi.
    """
    pos = np.asarray(position_rad, dtype=float)
    d = np.diff(pos)
    span = float(np.max(pos) - np.min(pos)) if pos.size else 0.0
    jumps = np.abs(d) > 0.5 * span
    modulus = 2.0 * math.pi
    if jumps.any() and (~jumps).any():
        delta = float(np.median(d[~jumps]))
        est = float(np.median(np.abs(d[jumps] - delta)))
        if est > 0.0 and abs(est - modulus) > MODULUS_SNAP_REL * modulus:
            modulus = est
    return np.unwrap(pos, period=modulus), modulus


def _fraction_on_grid(increments, step):
    """Return the fraction of increments within QUANT_TOL steps of a multiple of ``step``."""
    r = increments / step
    return float(np.mean(np.abs(r - np.round(r)) <= QUANT_TOL))


def _value_clusters(values, floor):
    """
    Return the centres of the major clusters of ``values`` (split where sorted gaps > floor).

    A cluster is major when it holds at least :data:`QUANT_CLUSTER_MIN` of the values, and
    the major ones must hold :data:`QUANT_CLUSTER_COVER` of them (else none is returned: the
    values do not fall on a few levels, an unquantized encoder).  Two major clusters are two
    different multiples of the step: a candidate step that puts them on one multiple (the
    mean increment of a crank at a nearly constant 47.7 counts a sample) is refused.
    """
    v = np.sort(values)
    if v.size == 0:
        return v
    cuts = np.flatnonzero(np.diff(v) > floor) + 1
    sizes = np.diff(np.concatenate([[0], cuts, [v.size]]))
    sums = np.add.reduceat(v, np.concatenate([[0], cuts]))
    major = sizes >= QUANT_CLUSTER_MIN * v.size
    if sizes[major].sum() < QUANT_CLUSTER_COVER * v.size:
        return np.zeros(0)
    return sums[major] / sizes[major]


def fit_noise(t_s, psi_rad, order=SG_ORDER):
    """
    Return the standard deviation of the angle noise about a smooth fit (rad).

    A Savitzky-Golay fit of ``order`` over :data:`FIT_NOISE_WINDOW` samples; the residual's
    RMS divided by sqrt(1 - h), h the fit's weight on the centre sample (the residual of a
    least-squares smoother of white noise of standard deviation s has variance s^2 (1 - h)).
    """
    psi = np.asarray(psi_rad, dtype=float)
    window = min(FIT_NOISE_WINDOW, (psi.size - 1) | 1) | 1
    if window < order + 2:
        return 0.0
    period = float(np.median(np.diff(t_s)))
    w0 = savgol_weights(window, order, period)[0]
    smooth = oaconvolve(psi - psi[0], w0[::-1], mode='valid') + psi[0]
    half = (window - 1) // 2
    res = psi[half:psi.size - half] - smooth
    h = float(w0[half])
    return float(np.sqrt(np.mean(res ** 2) / max(1.0 - h, 1e-12)))


def estimate_quantization(position_rad, counts_per_turn=None, t_s=None):
    """
    Return the :class:`Quantization` of encoder positions (rad; wrapped or not).

    The robust greatest common divisor of the increments (float noise, float32 positions,
    missing counts, either direction, any wrap): the positions are unwrapped
    (:func:`unwrap_encoder`); the candidate step q_c is the :data:`QUANT_GAP_QUANTILE`
    quantile of the gaps between distinct positions (wrapped onto one turn, where every
    count of a long recording occurs), between distinct increments and of the increments
    themselves, "distinct" meaning above the noise floor: a jump (a ratio of at
    least :data:`QUANT_SPLIT_RATIO`, the highest one) in the sorted gaps separates noise from
    steps.  The step
    is the largest q_c j / k (j, k = 1 .. :data:`QUANT_MAX_DIVISOR`) with at least
    :data:`QUANT_FRACTION_MIN` of the nonzero increments on its grid and every major level of
    the increments on its own multiple (:func:`_value_clusters`), refined by least squares
    (q = sum n d / sum n^2, n = round(d / q)) and snapped to an integer number of counts per
    modulus when within :data:`COUNT_SNAP` of one.  When no candidate agrees the positions
    are "not quantized" and only the smooth fit's noise is used.
    """
    pos = np.asarray(position_rad, dtype=float).ravel()
    psi, modulus = unwrap_encoder(pos)
    t = np.arange(pos.size, dtype=float) if t_s is None else np.asarray(t_s, dtype=float)
    sigma_fit = fit_noise(t, psi)
    if counts_per_turn is not None:
        q = 2.0 * math.pi / float(counts_per_turn)
        inc = np.diff(psi)
        moving = np.abs(inc)[np.abs(inc) > 0.5 * q]
        conf = _fraction_on_grid(moving, q) if moving.size else 1.0
        return Quantization(q, conf, 'stated', modulus,
                            max(q / math.sqrt(12.0), sigma_fit), sigma_fit)
    inc = np.diff(psi)
    moving = np.abs(inc)
    if moving.size > QUANT_MAX_INCREMENTS:
        moving = moving[np.linspace(0, moving.size - 1, QUANT_MAX_INCREMENTS).astype(int)]
    wrapped = np.sort(np.mod(psi - psi[0], modulus))
    inc_gaps = np.diff(np.sort(moving))
    gaps = np.sort(np.concatenate([np.diff(wrapped), inc_gaps]))
    gaps = gaps[gaps > 0.0]
    step, conf = 0.0, 0.0
    if gaps.size >= 2:
        ratios = gaps[1:] / gaps[:-1]
        jumps = np.flatnonzero(ratios >= QUANT_SPLIT_RATIO)
        # the highest jump: below it float round-off (float32 positions leave increments on
        # a grid of their own ulps, 2e-10 rad and more), above it the encoder's steps
        floor = gaps[jumps[-1]] if jumps.size else 0.0
        moving = moving[moving > floor]
        candidates = [float(np.quantile(v[v > floor], QUANT_GAP_QUANTILE))
                      for v in (inc_gaps, np.diff(wrapped), moving) if (v > floor).any()]
        centres = _value_clusters(moving, floor)
        if moving.size and centres.size:
            for q_c in candidates:
                for j in range(1, QUANT_MAX_DIVISOR + 1):
                    for k in range(1, QUANT_MAX_DIVISOR + 1):
                        q = q_c * j / k
                        if q <= step * (1.0 + QUANT_TOL) or q <= floor * QUANT_SPLIT_RATIO:
                            continue
                        frac = _fraction_on_grid(moving, q)
                        n = np.round(centres / q)
                        if frac >= QUANT_FRACTION_MIN and n.min() >= 1 and \
                                np.unique(n).size == n.size:
                            step, conf = q, frac
    if step > 0.0:
        for _ in range(QUANT_REFINE_PASSES):
            n = np.round(moving / step)
            step = float(np.sum(n * moving) / np.sum(n * n))
        counts = modulus / step
        if abs(counts - round(counts)) <= COUNT_SNAP:
            step = modulus / round(counts)
        conf = _fraction_on_grid(moving, step)
    if step <= 0.0 or conf < QUANT_FRACTION_MIN:
        return Quantization(0.0, conf, 'not quantized', modulus, sigma_fit, sigma_fit)
    return Quantization(step, conf, 'estimated', modulus,
                        max(step / math.sqrt(12.0), sigma_fit), sigma_fit)


def quantization_step(position_rad):
    """Return the encoder's step, rad (0: not quantized): :func:`estimate_quantization`."""
    return estimate_quantization(position_rad).step_rad


def savgol_weights(window, order, period_s):
    """
    Return the ``(3, window)`` Savitzky-Golay weights of value, slope and curvature.

    Row d applied (as a dot product) to ``window`` samples spaced ``period_s`` gives the d-th
    derivative at the centre of the least-squares polynomial of degree ``order``.  The fit is
    done on the abscissa scaled to [-1, 1] by an orthogonal factorization (scipy's
    ``savgol_coeffs`` fits on raw sample indices and loses all accuracy for windows of
    hundreds of samples at order 6).
    """
    half = (window - 1) // 2
    x = np.arange(-half, half + 1) / half
    vander = np.vander(x, order + 1, increasing=True)
    pinv = np.linalg.pinv(vander)                  # (order + 1, window)
    scale = half * period_s
    return np.stack([pinv[0], pinv[1] / scale, 2.0 * pinv[2] / scale ** 2])


def _window_accuracy(window, order, period_s, sigma_q, turn_hz):
    """Return (predicted std dict, gain error dict) of a Savitzky-Golay window."""
    half = (window - 1) // 2
    k = np.arange(-half, half + 1)
    c = savgol_weights(window, order, period_s)
    std = {'angle_rad': sigma_q * float(np.linalg.norm(c[0])),
           'speed_rad_s': sigma_q * float(np.linalg.norm(c[1])),
           'accel_rad_s2': sigma_q * float(np.linalg.norm(c[2]))}
    gain = {}
    for mult in (1, 2):
        w = 2.0 * math.pi * turn_hz * mult
        phase = np.exp(1j * w * k * period_s)
        for d, name in ((1, 'speed'), (2, 'accel')):
            g = abs(np.sum(c[d] * phase)) / w ** d if w > 0.0 else 1.0
            gain[f'{name}_{mult}x'] = float(g - 1.0)
    return std, gain


def crank_motion(t_s, position_rad, window=None, order=SG_ORDER, quantization_rad=None,
                 counts_per_turn=None):
    """
    Return the :class:`CrankMotion` of encoder samples (stamps s, positions rad).

    ``window`` (odd number of samples) overrides the choice of this module's docstring;
    ``counts_per_turn`` (or ``quantization_rad``, the step) states the encoder's step instead
    of :func:`estimate_quantization`.
    """
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
    dts = np.diff(t)
    if not (dts > 0.0).all():
        i = int(np.flatnonzero(~(dts > 0.0))[0])
        raise IdentifyError(f'encoder: sample {i + 1} stamp {t[i + 1]:.9f} s is not after '
                            f'sample {i} stamp {t[i]:.9f} s, expected increasing stamps')
    period = float(np.median(dts))
    if quantization_rad is not None and counts_per_turn is None and quantization_rad > 0.0:
        counts_per_turn = 2.0 * math.pi / float(quantization_rad)
    quant = estimate_quantization(pos, counts_per_turn, t)
    psi, _ = unwrap_encoder(pos)
    if np.max(np.abs(np.diff(psi))) > MAX_STEP_RAD:
        raise IdentifyError('encoder: the crank turns by nearly half a revolution or more '
                            'between samples (or the angle jumps), expected a faster encoder '
                            'rate')
    resampled = bool(np.max(np.abs(dts - period)) > UNIFORM_JITTER_REL * period)
    if resampled:
        grid = t[0] + period * np.arange(int(math.floor((t[-1] - t[0]) / period)) + 1)
        psi = np.interp(grid, t, psi)
        t = grid
    q = quant.step_rad
    sigma = quant.noise_rad
    span = t[-1] - t[0]
    speed_mean = abs(psi[-1] - psi[0]) / span
    turn_hz = speed_mean / (2.0 * math.pi)
    cap = MAX_WINDOW_TURNS / turn_hz / period if turn_hz > 0.0 else t.size
    cap = max(MIN_WINDOW, min(int(cap), t.size - 2)) | 1
    target = ACCEL_NOISE_REL * speed_mean ** 2
    floor = MIN_WINDOW
    limit = (t.size - 2) | 1
    while floor < limit:
        c2 = savgol_weights(floor | 1, order, period)[2]
        if sigma * np.linalg.norm(c2) <= target:
            break
        floor = int(floor * 1.1) + 2
    floor = min(floor | 1, limit if limit <= t.size else limit - 2)
    if window is None:
        window = max(floor, MIN_WINDOW)
        if floor > cap:
            rests = (f'the acceleration noise budget ({ACCEL_NOISE_REL:g} x mean speed^2 = '
                     f'{target:.3g} rad/s^2 from angle noise {sigma:.3g} rad) needs {floor} '
                     f'samples, above the {MAX_WINDOW_TURNS:g}-turn smoothing-bias cap of '
                     f'{cap}: the noise floor wins')
        else:
            rests = (f'the shortest window whose acceleration noise (angle noise '
                     f'{sigma:.3g} rad) is within the budget {ACCEL_NOISE_REL:g} x mean '
                     f'speed^2 = {target:.3g} rad/s^2 (cap {MAX_WINDOW_TURNS:g} turn = {cap} '
                     'samples)')
    else:
        rests = f'--window {int(window) | 1} stated'
        if (int(window) | 1) < floor:
            rests += (f', below the noise floor of {floor} samples: the acceleration noise '
                      'exceeds the budget')
    window = int(window) | 1
    if not (order + 2 <= window <= t.size):
        raise IdentifyError(f'window: got {window} samples, expected an odd number from '
                            f'{order + 2} to the {t.size} encoder samples')
    weights = savgol_weights(window, order, period)
    # samples within half a window of either end have no centred fit: dropped
    psi_s, speed, accel = (oaconvolve(psi - psi[0], wd[::-1], mode='valid') for wd in weights)
    half = (window - 1) // 2
    std, gain = _window_accuracy(window, order, period, sigma, turn_hz)
    return CrankMotion(t[half:t.size - half], psi_s + psi[0], speed, accel, period, window,
                       order, q, speed_mean, resampled, std, gain, quant, rests, int(floor))


# ============================================================================ regressor


@dataclass
class Regressor:
    """
    The measured quantities as a linear function of the inertial parameters theta (SI).

    ``wrench`` is ``(p, 3, 4 n)``: [f_x, f_y, n_z] per sample (rig frame, about the crank
    pivot, what the links exert on the frame, weight included); ``torque`` ``(p, 4 n)`` the
    driving torque, or None.  ``w = wrench @ theta (+ bias)``.
    """

    wrench: np.ndarray
    torque: np.ndarray = None
    names: tuple = ()
    residual: float = 0.0   # worst loop-closure residual of the kinematic solution
    cond: float = 0.0       # worst Jacobian condition number

    def predict(self, theta):
        """Return the modelled (wrench (p, 3), torque (p,) or None) of a parameter vector."""
        w = self.wrench @ theta
        return w, None if self.torque is None else self.torque @ theta


def parameter_names(scene):
    """Return the names ``m[link]``, ``hx[link]``, ``hy[link]``, ``I_O[link]`` in order."""
    return tuple(f'{p}[{lk.name}]' for lk in scene.links for p in PARAMETERS)


def cross2(a, b):
    """Return the z component of a x b for complex-coded planar vectors."""
    return (np.conjugate(a) * b).imag


def regressor(scene, psi_rad, speed_rad_s, accel_rad_s2, torque=False, rig=None):
    """
    Return the :class:`Regressor` of a planar scene at per-sample crank states.

    One kinematic solution at the given angles, speeds and accelerations; the core's
    shaking wrench (and driving torque) at the 4 n unit parameter vectors (seed 001 eqs.
    25-26, 39; linear in theta); the links' weight from their poses.
    """
    check_identifiable(scene)
    rig = analysis.Rig(scene) if rig is None else rig
    # the kinematics is periodic in the crank angle: solve at the wrapped angle (the solver
    # loses the branch at large unwrapped angles on some scenes)
    psi = np.mod(np.asarray(psi_rad, dtype=float), 2.0 * math.pi)
    state = rig.linkage.solve(psi, np.asarray(speed_rad_s, dtype=float),
                              np.asarray(accel_rad_s2, dtype=float))
    n = len(scene.links)
    p = psi.size
    gravity = complex(*scene.gravity_m_s2)
    need = ('shaking_wrench', 'driving_torque') if torque else ('shaking_wrench',)
    wrench = np.empty((p, 3, 4 * n))
    tau = np.empty((p, 4 * n)) if torque else None
    for k in range(4 * n):
        e = np.zeros(4 * n)
        e[k] = 1.0
        w = dynamics.inverse_dynamics(rig.linkage, state, dynamics.inertia_from_vector(e),
                                      gravity, need)
        wrench[:, 0, k] = w.shaking_force.real
        wrench[:, 1, k] = w.shaking_force.imag
        wrench[:, 2, k] = w.shaking_moment
        if torque:
            tau[:, k] = w.driving_torque
    if gravity:
        # the links' weight on the frame: m_i g at c_i; about the pivot
        # (c_i - O) x m_i g = (m_i (o_i - O) + R_i h_i) x g
        pose = state.pose
        arm = pose.origin[1:] - rig.linkage.pivot          # (n, p)
        rot = pose.rot[1:]
        for i in range(n):
            k = 4 * i
            wrench[:, 0, k] += gravity.real
            wrench[:, 1, k] += gravity.imag
            wrench[:, 2, k] += cross2(arm[i], gravity)
            wrench[:, 2, k + 1] += cross2(rot[i], gravity)
            wrench[:, 2, k + 2] += cross2(1j * rot[i], gravity)
    return Regressor(wrench, tau, parameter_names(scene), float(np.max(state.residual)),
                     float(np.max(state.cond)))


# ============================================================================ consistency


@dataclass
class Consistency:
    """
    How the calibrated parameters were made physically consistent (:func:`consistent`).

    ``stage``: ``exact`` (the identified combinations reproduced, the consistent set closest
    to the scene) or ``least squares`` (no consistent set reproduces them: the least
    residual subject to consistency); ``residual_growth`` the relative growth of the
    weighted residual norm over the unconstrained least squares (0 for ``exact``);
    ``max_shift_se`` the largest change of a combination in its standard errors;
    ``within_confidence`` whether that is within :data:`CONFIDENCE_SE`; ``active`` the
    constraints at their bound (``links.NAME.inertia_com_kg_m2 >= 0``, ``... mass_kg``).
    """

    stage: str
    residual_growth: float
    max_shift_se: float
    within_confidence: bool
    active: list
    solver_status: str
    iterations: int

    def describe(self):
        """Return the result in words."""
        if self.stage == 'exact':
            text = ('physically consistent: the identified combinations reproduced exactly, '
                    "the non-identifiable directions closest to the scene in each link's scale")
        else:
            text = ('no physically consistent set reproduces the identified combinations: '
                    'constrained least squares, residual grows by '
                    f'{100.0 * self.residual_growth:.3g}%, combinations moved by up to '
                    f'{self.max_shift_se:.3g} standard errors ('
                    + ('within' if self.within_confidence else 'OUTSIDE')
                    + f' the {CONFIDENCE_SE:g}-SE confidence region)')
        if self.active:
            text += '; active: ' + ', '.join(self.active)
        return text

    def to_dict(self):
        """Return the result as a plain dict."""
        return {'stage': self.stage, 'residual_growth': self.residual_growth,
                'max_shift_se': self.max_shift_se,
                'within_confidence': bool(self.within_confidence),
                'active_constraints': list(self.active), 'solver_status': self.solver_status,
                'iterations': int(self.iterations)}


def _cone_rows(scene, theta0, scale):
    """
    Return ``(A, b, cones)`` of the consistency cones on the scaled deviation u.

    Per link, in its own scale (y = theta / scale: the cone is invariant under it since
    scale_h^2 = scale_m scale_I): y_m >= MIN_MASS_REL and the rotated cone
    y_m (y_I - INERTIA_MARGIN_REL) >= y_hx^2 + y_hy^2, written as the second-order cone
    ||(2 y_hx, 2 y_hy, y_m - y_I')|| <= y_m + y_I' (Wensing, Kim & Slotine 2017, the planar
    case of their LMI; Sousa & Cortesao 2014).  Clarabel's form: s = b - A u in the cone.
    """
    import clarabel
    n = theta0.size
    a0 = theta0 / scale
    rows_a, rows_b, cones = [], [], []
    for i in range(len(scene.links)):
        km, kx, ky, ki = 4 * i, 4 * i + 1, 4 * i + 2, 4 * i + 3
        row = np.zeros((1, n))
        row[0, km] = -1.0
        rows_a.append(row)
        rows_b.append([a0[km] - MIN_MASS_REL])
        cones.append(clarabel.NonnegativeConeT(1))
        soc = np.zeros((4, n))
        soc[0, km], soc[0, ki] = -1.0, -1.0
        soc[1, kx] = -2.0
        soc[2, ky] = -2.0
        soc[3, km], soc[3, ki] = -1.0, 1.0
        ai = a0[ki] - INERTIA_MARGIN_REL
        rows_a.append(soc)
        rows_b.append([a0[km] + ai, 2.0 * a0[kx], 2.0 * a0[ky], a0[km] - ai])
        cones.append(clarabel.SecondOrderConeT(4))
    return np.vstack(rows_a), np.concatenate(rows_b), cones


def _solve_qp(p_mat, q_vec, a_mat, b_vec, cones):
    import clarabel
    import scipy.sparse as sp
    settings = solver_settings()
    sol = clarabel.DefaultSolver(sp.csc_matrix(np.triu(p_mat)), np.asarray(q_vec, float),
                                 sp.csc_matrix(a_mat), np.asarray(b_vec, float), cones,
                                 settings).solve()
    return sol


def _ok(status):
    return str(status) in ('Solved', 'AlmostSolved')


def consistent(scene, theta0, scale, v1, sv, du, chi2_ls, se_u):
    """
    Return ``(u, Consistency)``: the physically consistent scaled deviation from the scene.

    ``v1`` ``(n, r)`` and ``sv`` ``(r,)``: the row space of the scaled, weighted regressor
    and its singular values; ``du`` the least-squares deviation (minimum norm); ``chi2_ls``
    its weighted residual sum of squares; ``se_u`` ``(r,)`` the standard errors of the
    combinations v1^T u.  Stage 1: minimize ||u||^2 subject to v1^T u = v1^T du and the cones
    of :func:`_cone_rows` (the consistent set with the identified combinations closest to
    the scene).  If that is infeasible, stage 2: minimize
    ||S1 v1^T (u - du)||^2 + LS_TIE_REL s_1^2 ||(I - v1 v1^T) u||^2 (the residual growth over
    the unconstrained fit, a tie-break towards the scene in the directions the data cannot
    see)
    subject to the cones.  Raises :class:`IdentifyError` when no consistent set exists.
    """
    import clarabel
    n = theta0.size
    a_c, b_c, cones = _cone_rows(scene, theta0, scale)
    target = v1.T @ du
    stage = 'exact'
    sol = _solve_qp(2.0 * np.eye(n), np.zeros(n), np.vstack([v1.T, a_c]),
                    np.concatenate([target, b_c]),
                    [clarabel.ZeroConeT(v1.shape[1]), *cones])
    if not _ok(sol.status):
        stage = 'least squares'
        g = v1 * sv ** 2 @ v1.T
        tie = LS_TIE_REL * float(sv[0]) ** 2
        null = np.eye(n) - v1 @ v1.T               # the directions the data cannot see
        sol = _solve_qp(2.0 * (g + tie * null), -2.0 * g @ du, a_c, b_c, cones)
        if not _ok(sol.status):
            raise IdentifyError(f'no physically consistent parameter set found (Clarabel '
                                f'{sol.status}): expected a positive mass and centroidal '
                                'inertia per link to be reachable')
    u = np.array(sol.x)
    shift = sv * (v1.T @ (u - du))
    growth = math.sqrt(1.0 + float(shift @ shift) / max(chi2_ls, 1e-300)) - 1.0
    moved = np.abs(v1.T @ (u - du)) / np.where(se_u > 0.0, se_u, np.inf)
    max_se = float(np.max(moved)) if moved.size else 0.0
    active = []
    y = (theta0 + scale * u) / scale
    for i, lk in enumerate(scene.links):
        m, hx, hy, i_o = y[4 * i:4 * i + 4]
        if m <= MIN_MASS_REL * (1.0 + ACTIVE_REL):
            active.append(f'links.{lk.name}.mass_kg > 0')
        if m * (i_o - INERTIA_MARGIN_REL) - hx * hx - hy * hy <= ACTIVE_REL * m * i_o:
            active.append(f'links.{lk.name}.inertia_com_kg_m2 >= 0')
    if stage == 'exact':
        growth, max_se = 0.0, 0.0
    return u, Consistency(stage, growth, max_se, max_se <= CONFIDENCE_SE, active,
                          str(sol.status), int(sol.iterations))


# ============================================================================ identification


@dataclass
class Combination:
    """One identifiable combination of parameters: ``sum coefficients[j] theta_j``."""

    base: str                 # the base parameter (coefficient 1)
    unit: str
    coefficients: np.ndarray  # (4 n,) on theta (SI)
    estimate: float
    std_error: float
    scene_value: float
    text: str
    calibrated_value: float = math.nan   # of the (physically consistent) calibrated scene

    def value(self, theta):
        """Return the combination of a parameter vector (e.g. the truth)."""
        return float(self.coefficients @ np.asarray(theta, dtype=float))

    def to_dict(self):
        """Return the combination as a plain dict."""
        return {'base': self.base, 'unit': self.unit, 'combination': self.text,
                'coefficients': [float(c) for c in self.coefficients],
                'estimate': self.estimate, 'std_error': self.std_error,
                'scene_value': self.scene_value, 'calibrated_value': self.calibrated_value}


@dataclass
class Identification:
    """Result of :func:`identify` (SI throughout)."""

    scene: object
    names: tuple
    theta_scene: np.ndarray
    theta: np.ndarray               # calibrated parameters
    covariance: np.ndarray          # (4 n, 4 n) of theta
    rank: int
    singular_values: np.ndarray     # scaled, weighted, bias-free regressor
    condition_number: float         # of the identifiable part
    combinations: list
    channels: tuple
    bias: np.ndarray                # per channel
    bias_std_error: np.ndarray
    bias_confounding: np.ndarray    # (channels, 4 n): b estimates b + G (theta - theta_scene)
    bias_identifiable: np.ndarray   # (channels,) bool
    noise_std: np.ndarray           # per channel, residual standard deviation after
    rms_before: np.ndarray          # per channel: measured - scene model (bias fitted)
    rms_after: np.ndarray           # per channel: measured - calibrated model
    samples: int
    motion: CrankMotion
    kinematic_residual: float
    kinematic_cond: float
    calibrated_links: list          # dicts per link
    problems: list                  # why the calibrated scene is not physical, if it is not
    consistency: Consistency = None
    theta_ls: np.ndarray = None     # the unconstrained least squares (minimum norm)
    prediction: object = None       # PredictedRms of the calibrated scene
    source: str = ''
    segments: list = None           # per encoder stretch: EncoderSegment (see identify)
    findings: list = field(default_factory=list)   # recording_checks.Finding
    noise_floor: np.ndarray = None  # per channel: the recording's sample-to-sample noise

    @property
    def refusals(self):
        """Return the findings that refuse the calibration (recording_checks)."""
        return checks.refusals(self.findings)

    def summary(self):
        """Return the one-line summary: rank, residual, consistency and the prediction."""
        rms = ', '.join(f'{c} {b:.4g} -> {a:.4g} {CHANNEL_UNITS[c]}'
                        for c, b, a in zip(self.channels, self.rms_before, self.rms_after))
        out = (f'identified scene {self.scene.name!r} from {self.samples} measurements: rank '
               f'{self.rank} of {len(self.names)}; residual RMS before -> after: {rms}')
        if self.prediction is not None:
            out += '; ' + self.prediction.describe()
        return out

    def identification_block(self, source=None):
        """Return the calibrated scene's ``identification`` section (the schema's mapping)."""
        pred = self.prediction.to_dict() if self.prediction is not None else {}
        return {'source': self.source if source is None else source,
                'parameters': list(self.names), 'theta': [float(v) for v in self.theta],
                'std_directions': std_directions(self.covariance, self.rank).tolist(),
                'predicted_rms': pred}

    @property
    def realizable(self):
        """Return True if every calibrated link has a positive mass and inertia."""
        return not self.problems

    def bias_target(self, bias_true, theta_true):
        """Return what :attr:`bias` estimates for a true bias and parameter vector."""
        return np.asarray(bias_true, dtype=float) + self.bias_confounding @ (
            np.asarray(theta_true, dtype=float) - self.theta)

    def calibrated_scene(self, source=None):
        """
        Return the scene with the calibrated link inertias and its ``identification``.

        Raises :class:`IdentifyError` naming the links whose calibrated parameters no body
        can have (a mass <= 0 or a centroidal inertia < 0).
        """
        if self.refusals:
            raise IdentifyError('refused, no calibrated scene: '
                                + ' | '.join(f.describe() for f in self.refusals))
        if self.problems:
            raise IdentifyError('calibrated parameters are physically unrealizable: '
                                + '; '.join(self.problems)
                                + '; expected a positive mass and centroidal inertia per link '
                                  '(record a longer or richer motion, or check the sensor)')
        links = []
        for lk, c in zip(self.scene.links, self.calibrated_links):
            links.append(replace(lk, mass_kg=c['mass_kg'], com_m=tuple(c['com_m']),
                                 inertia_com_kg_m2=c['inertia_com_kg_m2']))
        out = self.scene.with_links(links, name=f'{self.scene.name}_calibrated')
        return replace(out, identification=schema.identification_from_dict(
            schema.plain(self.identification_block(source)), [lk.name for lk in links]))

    def to_dict(self):
        """Return the report as a plain, JSON- and YAML-able dict."""
        unit = [CHANNEL_UNITS[c] for c in self.channels]
        return {
            'scene': self.scene.name, 'samples': int(self.samples),
            'parameters': list(self.names), 'rank': int(self.rank),
            'parameter_count': len(self.names),
            'condition_number': self.condition_number,
            'singular_values': [float(s) for s in self.singular_values],
            'rank_rtol': RANK_RTOL,
            'combinations': [c.to_dict() for c in self.combinations],
            'bias': {c: {'estimate': float(b), 'std_error': float(s), 'unit': u,
                         'identifiable': bool(ok)}
                     for c, b, s, u, ok in zip(self.channels, self.bias, self.bias_std_error,
                                               unit, self.bias_identifiable)},
            'residual_rms': {c: {'before': float(b), 'after': float(a), 'unit': u}
                             for c, b, a, u in zip(self.channels, self.rms_before,
                                                   self.rms_after, unit)},
            'theta_scene': [float(v) for v in self.theta_scene],
            'theta': [float(v) for v in self.theta],
            'theta_std_error': [float(v) for v in np.sqrt(np.maximum(
                np.diag(self.covariance), 0.0))],
            'calibrated_links': self.calibrated_links, 'realizable': self.realizable,
            'problems': list(self.problems), 'crank_motion': self.motion.to_dict(),
            'encoder_segments': [g.to_dict() for g in self.segments or ()],
            'consistency': None if self.consistency is None else self.consistency.to_dict(),
            'summary': self.summary(),
            'predicted_rms': None if self.prediction is None else self.prediction.to_dict(),
            'kinematic_residual': self.kinematic_residual,
            'kinematic_condition': self.kinematic_cond,
            'findings': [f.to_dict() for f in self.findings],
            'refused': bool(self.refusals),
            'noise_floor': None if self.noise_floor is None else
            {c: float(v) for c, v in zip(self.channels, self.noise_floor)}}


def check_data(t_encoder, position_rad, t_wrench, wrench, effort, unit):
    """
    Return the encoder data after the data checks, and their findings.

    The encoder's unit (``unit``: auto, rad, deg; converted), two interleaved encoders or
    sensors (raises :class:`IdentifyError` naming the
    finding), a stuck encoder (its repeated samples dropped).
    """
    findings = []
    if checks.checkable(t_encoder, position_rad):
        t_encoder = np.asarray(t_encoder, dtype=float)
        pos = np.asarray(position_rad, dtype=float)
        _, modulus = unwrap_encoder(pos)
        pos, found = checks.encoder_unit(pos, modulus, unit)
        findings += [found] if found else []
        psi, modulus = unwrap_encoder(pos)
        found = checks.check_interleaved_encoder(psi)
        if found:
            raise IdentifyError(f'encoder: {found.evidence}; {found.way_out}')
        keep, found = checks.stuck_runs(t_encoder, psi, modulus)
        if found:
            findings.append(found)
            t_encoder, pos = t_encoder[keep], pos[keep]
            effort = None if effort is None else np.asarray(effort, dtype=float)[keep]
        position_rad = pos
    if checks.checkable(t_wrench, wrench) and np.ndim(wrench) == 2:
        found = checks.check_interleaved_wrench(wrench, CHANNELS)
        if found:
            raise IdentifyError(f'wrench: {found.evidence}; {found.way_out}')
    return t_encoder, position_rad, effort, findings


def check_pose_and_time(scene, motion, t_wrench, wrench, floor, theta0, scale):
    """
    Return ``(wrench stamps, findings)``: the sensor frame judged, a time offset corrected.

    Both on the longest stretch (``motion``), against the scene's model
    (:func:`~.recording_checks.frame_check`, :func:`~.recording_checks.time_offset`).
    """
    t_w = np.asarray(t_wrench, dtype=float)
    w = np.asarray(wrench, dtype=float)
    inside = np.flatnonzero((t_w >= motion.t_s[0]) & (t_w <= motion.t_s[-1]))
    if inside.size < 50:
        return t_wrench, []
    pick = inside[np.linspace(0, inside.size - 1, min(checks.OFFSET_SAMPLES, inside.size))
                  .astype(int)]
    rig = analysis.Rig(scene)
    model = regressor(scene, *motion.at(t_w[pick]), rig=rig).wrench @ theta0
    found = checks.frame_check(w[pick], model, floor, CHANNELS)
    if found:
        return t_wrench, [found]
    tau, found = checks.time_offset(
        lambda *state: regressor(scene, *state, rig=rig).wrench * scale, motion, t_w, w,
        floor[:3])
    return (t_w - tau if tau else t_wrench), ([found] if found else [])


def check_identifiable(scene):
    """Raise IdentifyError (one line: capability, kind, why) unless ``scene`` can be identified."""
    from mech_balance.core.rig import CapabilityError, require
    try:
        require(scene, 'identification', 'identify')
    except CapabilityError as exc:
        raise IdentifyError(f'{exc} ({SPATIAL_NOT_YET})') from None


def parameter_scales(scene):
    """
    Return the ``(4 n,)`` scale of each parameter: per link m, m l, m l, m l^2 (scene).

    l = sqrt(I_O / m) is the link's radius of gyration about its origin (the point-mass
    distance of seed 001 eq. 27), so a unit step in the scaled coordinates is a change of
    the link's own size: the minimum-norm deviation from the scene spreads what the data
    cannot separate over the links in proportion to their size (the scaling the balancing's
    cone program uses).  A link without mass or inertia falls back to the rig's units.
    """
    u = objective_units(scene)
    out = []
    for lk in scene.links:
        m = lk.mass_kg if lk.mass_kg > 0.0 else u.mass_kg
        i_o = lk.inertia_origin_kg_m2
        ln = math.sqrt(i_o / m) if i_o > 0.0 else u.length_m
        out += [m, m * ln, m * ln, m * ln * ln]
    return np.array(out)


@dataclass
class EncoderSegment:
    """
    One stretch of encoder data between gaps (:data:`GAP_PERIODS`) and what it gave.

    ``used`` is False with ``reason`` when the stretch is too short for the crank-motion
    window (or its fit failed); ``wrench_samples`` counts the measurements inside its fitted
    span (0 when not used).
    """

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

    A gap is a step between stamps above ``gap_periods`` median steps.  Data that cannot
    be split (mismatched shapes, non-finite or non-increasing stamps, too few samples) is
    returned whole, for :func:`crank_motion` to refuse with its own message.
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


def _segment_motions(t_encoder, position_rad, window, quantization_rad, counts_per_turn):
    """
    Return ``(main motion, [(motion or None, EncoderSegment)])`` over the encoder's stretches.

    The longest stretch chooses the window and the quantization (:func:`crank_motion`); the
    others are fitted with the same ones, or skipped (with the reason) when shorter than
    the window or when their fit fails.
    """
    pieces = encoder_segments(t_encoder, position_rad)
    main = max(range(len(pieces)), key=lambda k: pieces[k][0].size)
    motion = crank_motion(*pieces[main], window, quantization_rad=quantization_rad,
                          counts_per_turn=counts_per_turn)
    out = []
    for k, (t, pos) in enumerate(pieces):
        seg = EncoderSegment(float(t[0]), float(t[-1]), int(t.size))
        fitted = motion if k == main else None
        if k != main:
            if t.size < motion.window + 2:
                seg.used, seg.reason = False, (f'{t.size} samples, shorter than the '
                                               f'{motion.window}-sample window + 2')
            else:
                try:
                    fitted = crank_motion(t, pos, motion.window,
                                          counts_per_turn=motion.quantization.counts_per_turn)
                except IdentifyError as exc:
                    seg.used, seg.reason = False, str(exc)
        out.append((fitted, seg))
    return motion, out


def _measurements(wrench, effort, t_wrench, t_effort, motion):
    """Return the (p, c) measurement matrix at the wrench stamps inside the valid span."""
    wrench = np.asarray(wrench, dtype=float)
    if wrench.ndim != 2 or wrench.shape[1] != 3:
        raise IdentifyError(f'wrench: got shape {wrench.shape}, expected (samples, 3): '
                            'force x, force y, moment z')
    t_w = np.asarray(t_wrench, dtype=float).ravel()
    if t_w.size != wrench.shape[0]:
        raise IdentifyError(f'wrench: {t_w.size} stamps and {wrench.shape[0]} samples, '
                            'expected one stamp per sample')
    if not (np.isfinite(wrench).all() and np.isfinite(t_w).all()):
        raise IdentifyError('wrench: non-finite value, expected finite forces and moments')
    inside = (t_w >= motion.t_s[0]) & (t_w <= motion.t_s[-1])
    meas = wrench[inside]
    if effort is not None:
        eff = np.asarray(effort, dtype=float).ravel()
        t_e = np.asarray(t_effort, dtype=float).ravel()
        if not np.isfinite(eff).all():
            raise IdentifyError('effort: non-finite value, expected finite torques')
        meas = np.column_stack([meas, np.interp(t_w[inside], t_e, eff)])
    return t_w[inside], meas


REDUCE_CHUNK = 4096
"""Samples per regressor evaluation in :func:`_reduce`: the working memory of an
identification is that of this many samples, whatever the recording's length."""


@dataclass
class _Reduction:
    """What the weighted least squares needs of all samples (:func:`_reduce`)."""

    samples: int
    names: tuple
    factors: list           # per channel: R factor (n+1, n+1) of the centred [Y_c | r_c]
    ys_mean: np.ndarray     # (c, n) per channel mean of the scaled columns
    r0_mean: np.ndarray     # (c,) mean of measured minus the scene's model
    rms_before: np.ndarray  # (c,) RMS of the centred r0
    sigma: np.ndarray       # (c,) standard deviation of the measurements
    size: np.ndarray        # (c,) RMS over samples of the scaled regressor row norm
    residual: float
    cond: float


def _reduce(scene, psi, speed, accel, meas, torque, theta0, scale, chunk=REDUCE_CHUNK):
    """
    Return the :class:`_Reduction` of the samples, ``chunk`` samples at a time.

    Per channel c one orthogonal (QR) reduction of ``[1 | Y_c | r_c | w_c]`` (scaled
    regressor, measured minus the scene's model, measured), updated chunk by chunk: the
    trailing block of its R factor is the R factor of the centred columns (the bias-free
    problem), its first row divided by sqrt(p) their means.  So the regressor of the whole
    recording is never held at once.
    """
    nc = meas.shape[1]
    stacks = [None] * nc
    names, residual, cond, sq = (), 0.0, 0.0, np.zeros(nc)
    rig = analysis.Rig(scene)                       # built (its branch traced) once
    for a in range(0, psi.size, chunk):
        k = slice(a, a + chunk)
        reg = regressor(scene, psi[k], speed[k], accel[k], torque=torque, rig=rig)
        y = reg.wrench if reg.torque is None else np.concatenate(
            [reg.wrench, reg.torque[:, None, :]], axis=1)
        names, residual, cond = reg.names, max(residual, reg.residual), max(cond, reg.cond)
        ys = y * scale                              # scaled columns: theta = scale * u
        r0 = meas[k] - y @ theta0                   # measured minus the scene's model
        sq += np.sum(ys ** 2, axis=(0, 2))
        for c in range(nc):
            block = np.column_stack([np.ones(ys.shape[0]), ys[:, c, :], r0[:, c],
                                     meas[k, c]])
            if stacks[c] is not None:
                block = np.vstack([stacks[c], block])
            stacks[c] = np.linalg.qr(block, mode='r')
    p, n = psi.size, theta0.size
    first = np.array([st[0, 1:] / st[0, 0] for st in stacks])     # (c, n + 2) means
    tail = [st[1:, 1:] for st in stacks]
    return _Reduction(
        samples=p, names=names, factors=[t[:n + 1, :n + 1] for t in tail],
        ys_mean=first[:, :n], r0_mean=first[:, n],
        rms_before=np.array([np.linalg.norm(t[:, n]) for t in tail]) / math.sqrt(p),
        sigma=np.array([np.linalg.norm(t[:, n + 1]) for t in tail]) / math.sqrt(p),
        size=np.sqrt(sq / p),
        residual=residual, cond=cond)


def identify(scene, t_encoder, position_rad, t_wrench, wrench, effort=None, window=None,
             quantization_rad=None, counts_per_turn=None, check=True, encoder_unit='auto',
             max_residual_ratio=checks.FIT_RATIO_MAX):
    """
    Return the :class:`Identification` of a planar rig from encoder and wrench samples.

    ``t_encoder`` and ``position_rad`` (s, rad): the encoder's stamps and crank positions;
    ``t_wrench`` and ``wrench`` ``(samples, 3)``: the sensor's stamps and [f_x, f_y, n_z]
    (rig frame, about the crank pivot, what the rig exerts on its frame, N and N*m);
    ``effort``: the encoder's motor torque at its stamps (N*m) or None.  The model is
    evaluated at each wrench stamp with the crank state interpolated from the encoder.

    ``check``: run the checks of :mod:`mech_balance.analysis.recording_checks` (the
    encoder's unit, ``encoder_unit`` ``auto``, ``rad`` or ``deg``; interleaved sources; a
    stuck encoder; the sensor's frame; a time offset; the fit against the noise floor,
    refused above ``max_residual_ratio`` floors): their findings are
    :attr:`Identification.findings`, and a refused one keeps :meth:`calibrated_scene` from
    being made.
    """
    check_identifiable(scene)
    findings = []
    if check:
        t_encoder, position_rad, effort, findings = check_data(
            t_encoder, position_rad, t_wrench, wrench, effort, encoder_unit)
    motion, stretches = _segment_motions(t_encoder, position_rad, window, quantization_rad,
                                         counts_per_turn)
    theta0 = dynamics.parameter_vector(dynamics.Inertia.from_links(scene.links))
    scale = parameter_scales(scene)
    floor = None
    if check and checks.checkable(t_wrench, wrench) and np.ndim(wrench) == 2 and \
            np.shape(wrench)[1] == 3:
        floor = checks.noise_floor(wrench)
        if effort is not None:
            floor = np.append(floor, checks.noise_floor(effort))
        t_wrench, found = check_pose_and_time(scene, motion, t_wrench, wrench, floor,
                                              theta0, scale)
        findings += found
    if check:
        found = checks.encoder_smoothing(motion, MAX_WINDOW_TURNS)
        findings += [found] if found else []
    try:
        return _fit(scene, motion, stretches, t_encoder, t_wrench, wrench, effort, theta0,
                    scale, floor, findings, max_residual_ratio)
    except IdentifyError as exc:
        refused = checks.refusals(findings)
        if not refused:
            raise
        raise IdentifyError(' | '.join(f.describe() for f in refused)
                            + f' (and then: {exc})') from None


def _fit(scene, motion, stretches, t_encoder, t_wrench, wrench, effort, theta0, scale, floor,
         findings, max_residual_ratio):
    """Return the :class:`Identification` of :func:`identify` once the data is checked."""
    parts, turns, span = [], 0.0, 0.0
    for fitted, seg in stretches:
        if fitted is None:
            continue
        t_k, meas_k = _measurements(wrench, effort, t_wrench, t_encoder, fitted)
        seg.wrench_samples = int(t_k.size)
        if t_k.size:
            parts.append((t_k, meas_k) + tuple(fitted.at(t_k)))
            turns += abs(parts[-1][2][-1] - parts[-1][2][0]) / (2.0 * math.pi)
            span += t_k[-1] - t_k[0]
    channels = CHANNELS + ((TORQUE_CHANNEL,) if effort is not None else ())
    nc = len(channels)
    if sum(part[0].size for part in parts) < 2:
        raise IdentifyError(f'wrench: {sum(part[0].size for part in parts)} samples inside the '
                            f'encoder span {motion.t_s[0]:.3f}..{motion.t_s[-1]:.3f} s, '
                            'expected the sensor and the encoder to record the same time')
    t_w, meas, psi, speed, accel = (np.concatenate([part[i] for part in parts])
                                    for i in range(5))
    if turns < MIN_TURNS:
        raise IdentifyError(f'recording: the crank turns {turns:.3g} revolutions in the usable '
                            f'span of {span:.3g} s, expected at least {MIN_TURNS:g}'
                            ' (a longer recording)')
    red = _reduce(scene, psi, speed, accel, meas, effort is not None, theta0, scale)
    p, nparam = red.samples, theta0.size
    if p * nc <= nparam + nc:
        raise IdentifyError(f'recording: {p} samples, expected more than {nparam + nc} '
                            'measurements for the parameters and the bias')
    ys_mean, r0_mean, rms_before, factors = red.ys_mean, red.r0_mean, red.rms_before, \
        red.factors
    sigma = np.where(red.sigma > 0.0, red.sigma, 1.0)
    for _ in range(WEIGHT_PASSES):
        stacked = np.vstack([f / s for f, s in zip(factors, sigma)])
        u_mat, sv, vt = np.linalg.svd(stacked[:, :nparam], full_matrices=False)
        if not sv.size or sv[0] <= 0.0:
            raise IdentifyError('recording: the measured motion excites no inertial '
                                'parameter, expected a turning crank')
        rank = int(np.sum(sv > RANK_RTOL * sv[0]))
        v1 = vt[:rank].T
        du = v1 @ ((u_mat[:, :rank].T @ stacked[:, nparam]) / sv[:rank])
        step = np.append(-du, 1.0)
        res_sq = np.array([float(np.sum((f @ step) ** 2)) for f in factors])
        new_sigma = np.sqrt(res_sq / max(p - 1 - nparam / nc, 1.0))
        sigma = np.where(new_sigma > 0.0, new_sigma, sigma)
    dof = max(p * nc - rank - nc, 1)
    s2 = float(np.sum(res_sq / sigma ** 2)) / dof
    cov_u = s2 * (v1 / sv[:rank] ** 2) @ v1.T
    theta_ls = theta0 + scale * du
    cov = cov_u * np.outer(scale, scale)
    se_u = np.sqrt(s2) / sv[:rank]
    u_cal, consistency = consistent(scene, theta0, scale, v1, sv[:rank], du,
                                    float(np.sum(res_sq / sigma ** 2)), se_u)
    theta = theta0 + scale * u_cal
    res_sq = np.array([float(np.sum((f @ np.append(-u_cal, 1.0)) ** 2)) for f in factors])
    bias = r0_mean - ys_mean @ u_cal
    # Cov(b) = s^2 [(B^T B)^-1 + M P1-part]: sigma_c^2 / p from the mean, plus the slope's
    m_sens = ys_mean                                # (c, n) SI per unit u
    cov_b = s2 * np.diag(sigma ** 2 / p) + m_sens @ cov_u @ m_sens.T
    v0 = vt[rank:].T
    confound_u = m_sens @ v0 @ v0.T                 # (c, n) per unit of u
    size = red.size
    identifiable_b = np.linalg.norm(confound_u, axis=1) <= CONFOUND_RTOL * size
    confound = np.where(identifiable_b[:, None], 0.0, confound_u / scale)
    rms_after = np.sqrt(res_sq / p)
    combos = _combinations(vt[:rank], scale, red.names, theta_ls, theta0, cov, theta)
    links, problems = _calibrated_links(scene, theta)
    if floor is not None:
        findings += checks.judge_fit(channels, rms_after, floor, motion,
                                     [CHANNEL_UNITS[c] for c in channels], max_residual_ratio)
    return Identification(
        scene=scene, names=red.names, theta_scene=theta0, theta=theta, covariance=cov,
        rank=rank, singular_values=sv,
        condition_number=float(sv[0] / sv[rank - 1]), combinations=combos,
        channels=channels, bias=bias, bias_std_error=np.sqrt(np.diag(cov_b)),
        bias_confounding=confound, bias_identifiable=identifiable_b, noise_std=sigma,
        rms_before=rms_before, rms_after=rms_after, samples=p, motion=motion,
        kinematic_residual=red.residual, kinematic_cond=red.cond, calibrated_links=links,
        problems=problems, consistency=consistency, theta_ls=theta_ls,
        prediction=None if problems else predicted_rms(scene, theta, cov),
        segments=[seg for _, seg in stretches], findings=findings,
        noise_floor=floor)


def _combinations(v1t, scale, names, theta, theta0, cov, theta_cal):
    """Return the base-parameter form of the row space ``v1t`` (scaled coordinates)."""
    rank = v1t.shape[0]
    _, _, piv = scipy.linalg.qr(v1t, pivoting=True, mode='economic')
    base = np.sort(piv[:rank])
    e = np.linalg.solve(v1t[:, base], v1t)         # coefficient 1 on its own base parameter
    out = []
    for k, j in enumerate(base):
        coeff_u = e[k]
        coeff = coeff_u * scale[j] / scale         # on theta (SI), 1 on theta_j
        coeff[base] = np.where(base == j, 1.0, 0.0)
        terms = []
        for i in np.argsort(-np.abs(coeff_u)):
            cu = coeff_u[i]
            if abs(cu) <= COEFF_PRINT_RTOL:
                continue
            c = coeff[i]
            if i == j:
                terms.insert(0, names[i])
            else:
                terms.append(f'{"-" if c < 0 else "+"} {abs(c):.6g} {names[i]}')
        text = ' '.join(terms)
        unit = PARAMETER_UNITS[j % 4]
        out.append(Combination(
            base=names[j], unit=unit, coefficients=coeff, estimate=float(coeff @ theta),
            std_error=float(math.sqrt(max(coeff @ cov @ coeff, 0.0))),
            scene_value=float(coeff @ theta0), text=text,
            calibrated_value=float(coeff @ theta_cal)))
    return out


def _calibrated_links(scene, theta):
    """Return (per-link dicts of mass, centre, inertias, problems) of a parameter vector."""
    links, problems = [], []
    for lk, (m, hx, hy, i_o) in zip(scene.links, np.asarray(theta).reshape(-1, 4)):
        entry = {'name': lk.name, 'mass_kg': float(m), 'inertia_origin_kg_m2': float(i_o)}
        if not m > 0.0:
            problems.append(f'links.{lk.name}.mass_kg = {m:.6g}, expected > 0')
            entry.update(com_m=[math.nan, math.nan], inertia_com_kg_m2=math.nan)
        else:
            i_c = i_o - (hx * hx + hy * hy) / m
            tol = INERTIA_ROUNDOFF * abs(i_o)
            if i_c < -tol:
                problems.append(f'links.{lk.name}.inertia_com_kg_m2 = {i_c:.6g} (from I_O = '
                                f'{i_o:.6g} and m c = ({hx:.6g}, {hy:.6g})), expected >= 0')
            else:
                i_c = max(i_c, 0.0)   # parallel-axis round-off
            entry.update(com_m=[float(hx / m), float(hy / m)], inertia_com_kg_m2=float(i_c))
        links.append(entry)
    return links, problems


# ============================================================================ confidence


@dataclass
class PredictedRms:
    """RMS shaking force (N) and moment (N*m) of a parameter vector, with standard errors."""

    force_N: float
    force_std_error_N: float
    moment_Nm: float
    moment_std_error_Nm: float
    speed_rad_s: float
    samples: int

    def describe(self):
        """Return the prediction in words."""
        return (f'predicted RMS shaking force {self.force_N:.6g} +- '
                f'{self.force_std_error_N:.2g} N, moment {self.moment_Nm:.6g} +- '
                f'{self.moment_std_error_Nm:.2g} N*m (calibrated scene at '
                f'{self.speed_rad_s:.6g} rad/s, {self.samples} crank angles; standard errors '
                "from the combinations' covariance)")

    def to_dict(self):
        """Return the prediction as the scene's ``identification.predicted_rms`` mapping."""
        return {'shaking_force_N': {'value': self.force_N,
                                    'std_error': self.force_std_error_N},
                'shaking_moment_Nm': {'value': self.moment_Nm,
                                      'std_error': self.moment_std_error_Nm}}


def _rms_maps(scene):
    """Return (force map, moment map) in SI: RMS = ||map @ theta|| (theta SI)."""
    units = objective_units(scene)
    maps = linear_maps(scene, units=units)
    m, ln, om = units.mass_kg, units.length_m, units.omega_rad_s
    scale = np.tile([m, m * ln, m * ln, m * ln * ln], len(scene.links))
    f_unit, n_unit = m * ln * om ** 2, m * ln * ln * om ** 2
    return maps.force * f_unit / scale, maps.moment * n_unit / scale


def predicted_rms(scene, theta, covariance):
    """
    Return the :class:`PredictedRms` of parameters ``theta`` (SI) on ``scene``'s geometry.

    The RMS over :attr:`Scene.samples` crank angles at the scene's crank speed
    (:func:`mech_balance.analysis.linear_maps.linear_maps`, the balancing's own definition,
    RMS = ||R theta||); the standard error by the delta method, g^T Cov g with
    g = R^T R theta / ||R theta||.
    """
    theta = np.asarray(theta, dtype=float)
    out = []
    for r in _rms_maps(scene):
        v = r @ theta
        value = float(np.linalg.norm(v))
        g = r.T @ v / value if value > 0.0 else np.zeros_like(theta)
        out += [value, float(math.sqrt(max(g @ covariance @ g, 0.0)))]
    return PredictedRms(*out, abs(scene.crank_speed_rad_s), int(scene.samples))


def std_directions(covariance, rank):
    """Return the ``(rank, n)`` factor D with D^T D = Cov (symmetric eigen-decomposition)."""
    w, v = np.linalg.eigh(0.5 * (covariance + covariance.T))
    keep = np.argsort(w)[::-1][:rank]
    return (v[:, keep] * np.sqrt(np.maximum(w[keep], 0.0))).T


def balance_confidence(scene, balanced_scene):
    """
    Return how a balanced design's RMS shaking force and moment vary within +-1 SE, or None.

    ``scene`` is a calibrated scene (with an ``identification`` section,
    :mod:`mech_balance.schema.identification`); ``balanced_scene`` the optimum of
    ``mech-balance balance`` on it.  The design changes the links by known amounts, so the
    true balanced parameters are theta_b + D^T a with the identification's factor D; for
    ||a|| <= 1 (+-1 standard error) the RMS ||R (theta_b + D^T a)|| lies within
    ||R theta_b|| -+ ||R D^T||_2 (the triangle inequality; a checked bound, not a linear
    estimate: at a balanced optimum ||R theta|| is not differentiable).
    """
    block = getattr(scene, 'identification', None)
    if block is None:
        return None
    theta_b = dynamics.parameter_vector(dynamics.Inertia.from_links(balanced_scene.links))
    d = np.array(block['std_directions'], dtype=float).reshape(-1, theta_b.size)
    out = {}
    for name, r in zip(('shaking_force_N', 'shaking_moment_Nm'), _rms_maps(balanced_scene)):
        value = float(np.linalg.norm(r @ theta_b))
        spread = float(np.linalg.norm(r @ d.T, 2)) if d.size else 0.0
        out[name] = {'value': value, 'low': max(value - spread, 0.0), 'high': value + spread}
    return out


def format_balance_confidence(conf):
    """Return the line ``mech-balance balance`` prints for :func:`balance_confidence`."""
    f, n = conf['shaking_force_N'], conf['shaking_moment_Nm']
    return (f"identification confidence (+-1 SE of the calibrated inertias): the optimum's RMS "
            f"shaking force {f['value']:.6g} N lies within [{f['low']:.6g}, {f['high']:.6g}] "
            f"N, moment {n['value']:.6g} N*m within [{n['low']:.6g}, {n['high']:.6g}] N*m")


# ============================================================================ output


def calibrated_yaml(result, source=''):
    """Return the calibrated scene as YAML text (:func:`mech_balance.schema.to_yaml`)."""
    sc = result.calibrated_scene(source)
    head = [f'# written by mech-balance identify from scene {result.scene.name}'
            + (f' and {source}' if source else ''),
            f'# rank {result.rank} of {len(result.names)} parameters, condition number '
            f'{result.condition_number:.4g}; residual RMS before -> after:']
    for c, b, a in zip(result.channels, result.rms_before, result.rms_after):
        head.append(f'#   {c}: {b:.6g} -> {a:.6g} {CHANNEL_UNITS[c]}')
    return '\n'.join(head) + '\n' + schema.to_yaml(sc)


def _segment_lines(segments):
    """Return the report's lines on the encoder's stretches (none for one stretch)."""
    if not segments or len(segments) == 1:
        return []
    used = [g for g in segments if g.used]
    lines = [f'  encoder gaps (> {GAP_PERIODS:g} periods): {len(segments)} stretches, '
             f'{len(used)} used ({sum(g.wrench_samples for g in used)} wrench samples); '
             'the wrench samples inside a gap are not used']
    lines += [f'    skipped {g.start_s:.3f}..{g.end_s:.3f} s: {g.reason}'
              for g in segments if not g.used]
    return lines


def format_report(result):
    """Return the identification report as text."""
    m = result.motion
    std = m.predicted_std
    lines = [
        f'scene: {result.scene.name} ({result.scene.source}); {result.samples} wrench samples, '
        f'channels {", ".join(result.channels)}',
        f'crank motion: Savitzky-Golay order {m.order} over {m.window} samples '
        f'({m.window_s * 1e3:.1f} ms) at {1.0 / m.period_s:.6g} Hz'
        + (' (resampled to a uniform grid)' if m.resampled else ''),
        f'  {m.quantization.describe()}; mean speed {m.mean_speed_rad_s:.6g} rad/s',
        f'  window: {m.window_reason}',
        *_segment_lines(result.segments),
        f"  predicted noise: angle {std['angle_rad']:.2e} rad, speed "
        f"{std['speed_rad_s']:.2e} rad/s, acceleration {std['accel_rad_s2']:.2e} rad/s^2; "
        f"gain error at 1x/2x rotation: accel {m.gain_error['accel_1x']:+.1e}/"
        f"{m.gain_error['accel_2x']:+.1e}",
        f'kinematics: worst loop-closure residual {result.kinematic_residual:.2e}, worst '
        f'Jacobian condition {result.kinematic_cond:.4g}',
        f'rank {result.rank} of {len(result.names)} inertial parameters (singular values > '
        f'{RANK_RTOL:g} x largest), condition number {result.condition_number:.4g}',
        '', 'identifiable combinations (base parameters; estimate +- standard error, scene):']
    for c in result.combinations:
        lines.append(f'  {c.text}')
        lines.append(f'      = {c.estimate:.6g} +- {c.std_error:.2g} {c.unit} '
                     f'(scene {c.scene_value:.6g})')
    lines += ['', 'sensor bias:']
    for i, ch in enumerate(result.channels):
        note = '' if result.bias_identifiable[i] else \
            '  (confounded with the static weight: given the non-identifiable parameters at ' \
            "the scene's values)"
        lines.append(f'  {ch:<10} {result.bias[i]:+.6g} +- {result.bias_std_error[i]:.2g} '
                     f'{CHANNEL_UNITS[ch]}{note}')
    lines += ['', f"{'residual RMS':<14}{'unit':>6}{'before':>14}{'after':>14}{'ratio':>9}",
              '-' * 57]
    for ch, b, a in zip(result.channels, result.rms_before, result.rms_after):
        ratio = a / b if b > 0 else math.nan
        lines.append(f'{ch:<14}{CHANNEL_UNITS[ch]:>6}{b:>14.6g}{a:>14.6g}{ratio:>9.3f}')
    lines.append('(before: the scene with a fitted bias; after: the calibrated scene)')
    lines += ['', 'calibrated links ('
              + (result.consistency.describe() if result.consistency else '') + '):']
    for c in result.calibrated_links:
        lines.append(f"  {c['name']:<10} mass {c['mass_kg']:.6g} kg, centre ({c['com_m'][0]:.6g},"
                     f" {c['com_m'][1]:.6g}) m, I_C {c['inertia_com_kg_m2']:.6g} kg*m^2, I_O "
                     f"{c['inertia_origin_kg_m2']:.6g} kg*m^2")
    if result.problems:
        lines.append('NOT physically realizable: ' + '; '.join(result.problems))
    if result.prediction is not None:
        lines += ['', result.prediction.describe()]
    if result.noise_floor is not None:
        lines += ['', 'noise floor (sample-to-sample) against the residual after: ' + ', '.join(
            f'{c} {f:.3g} / {a:.3g} {CHANNEL_UNITS[c]}'
            for c, f, a in zip(result.channels, result.noise_floor, result.rms_after))]
    if result.findings:
        lines += ['', 'findings (the recording and the fit checked):']
        lines += [f'  {f.describe()}' for f in result.findings]
    return '\n'.join(lines)
