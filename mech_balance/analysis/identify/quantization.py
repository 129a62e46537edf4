"""The encoder's quantization step, estimated from its positions, and its unwrapping."""

from dataclasses import dataclass
import math

from mech_balance.analysis.identify.smoothing import fit_noise
import numpy as np

QUANT_TOL = 0.1
"""An increment agrees with a step q when it is within this many q of a multiple of q."""
QUANT_FRACTION_MIN = 0.99
"""An encoder step needs this fraction of the nonzero increments on its grid (QUANT_TOL)."""
QUANT_CLUSTER_MIN = 0.005
"""A level of the increments holding at least this fraction of them is a major level."""
QUANT_CLUSTER_COVER = 0.9
"""The major levels must hold this fraction of the increments (else: not quantized)."""
QUANT_MAX_INCREMENTS = 20000
"""Increments the step search tests at most (evenly spaced over the recording)."""
QUANT_SPLIT_RATIO = 30.0
"""Sorted gaps jump by at least this ratio from float round-off to the encoder step."""
QUANT_GAP_QUANTILE = 0.02
"""Candidate step: this quantile of the gaps above the noise floor."""
QUANT_MAX_DIVISOR = 8
"""Divisors of the candidate step tried (counts missing from a short recording)."""
QUANT_REFINE_PASSES = 2
"""Least-squares passes refining the step on the increments."""
COUNT_SNAP = 0.05
"""A step within this many counts of an integer number of counts per modulus is snapped."""
MODULUS_SNAP_REL = 1e-3
"""A wrap modulus within this fraction of 2 pi is 2 pi."""


@dataclass
class Quantization:
    """
    The encoder's quantization step and the angle noise the window choice rests on.

    ``step_rad`` 0: not quantized; ``source``: ``estimated``, ``stated``, ``not quantized``;
    ``confidence``: the fraction of increments on the grid; ``noise_rad`` (rad).
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


def unwrap_encoder(position_rad):
    """Return ``(unwrapped angle, modulus)`` of encoder positions that may wrap at any modulus."""
    pos = np.asarray(position_rad, dtype=float)
    steps = np.diff(pos)
    span = float(np.max(pos) - np.min(pos)) if pos.size else 0.0
    wraps = np.abs(steps) > 0.5 * span
    modulus = 2.0 * math.pi
    if wraps.any() and (~wraps).any():
        delta = float(np.median(steps[~wraps]))
        estimate = float(np.median(np.abs(steps[wraps] - delta)))
        if estimate > 0.0 and abs(estimate - modulus) > MODULUS_SNAP_REL * modulus:
            modulus = estimate
    return np.unwrap(pos, period=modulus), modulus


def fraction_on_grid(increments, step):
    """Return the fraction of increments within QUANT_TOL steps of a multiple of ``step``."""
    r = increments / step
    return float(np.mean(np.abs(r - np.round(r)) <= QUANT_TOL))


def value_clusters(values, floor):
    """Return the centres of the major clusters of ``values`` (none if they cover too little)."""
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


def estimate_quantization(position_rad, counts_per_turn=None, t_s=None):
    """Return the :class:`Quantization` of encoder positions (rad), or of ``counts_per_turn``."""
    pos = np.asarray(position_rad, dtype=float).ravel()
    psi, modulus = unwrap_encoder(pos)
    t = np.arange(pos.size, dtype=float) if t_s is None else np.asarray(t_s, dtype=float)
    sigma_fit = fit_noise(t, psi)
    if counts_per_turn is not None:
        q = 2.0 * math.pi / float(counts_per_turn)
        inc = np.diff(psi)
        moving = np.abs(inc)[np.abs(inc) > 0.5 * q]
        conf = fraction_on_grid(moving, q) if moving.size else 1.0
        return Quantization(q, conf, 'stated', modulus,
                            max(q / math.sqrt(12.0), sigma_fit), sigma_fit)
    moving = np.abs(np.diff(psi))
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
        centres = value_clusters(moving, floor)
        if moving.size and centres.size:
            for q_c in candidates:
                for j in range(1, QUANT_MAX_DIVISOR + 1):
                    for k in range(1, QUANT_MAX_DIVISOR + 1):
                        q = q_c * j / k
                        if q <= step * (1.0 + QUANT_TOL) or q <= floor * QUANT_SPLIT_RATIO:
                            continue
                        frac = fraction_on_grid(moving, q)
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
        conf = fraction_on_grid(moving, step)
    if step <= 0.0 or conf < QUANT_FRACTION_MIN:
        return Quantization(0.0, conf, 'not quantized', modulus, sigma_fit, sigma_fit)
    return Quantization(step, conf, 'estimated', modulus,
                        max(step / math.sqrt(12.0), sigma_fit), sigma_fit)
