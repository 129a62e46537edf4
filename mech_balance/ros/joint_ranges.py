"""Each joint's range over one crank cycle, and the URDF limits that hold it."""

import math

from mech_balance.rotations import TWO_PI, wrap_angle
import numpy as np

RANGE_SAMPLES = 720
"""Crank angles per turn at which each joint's range over a cycle is first located."""
GOLDEN_ITERATIONS = 36
"""Golden-section steps refining each extreme (the bracket to ~3e-8 of its width: beyond,
only rounding noise is compared, at a kinematics evaluation each)."""
LIMIT_MARGIN = 1e-9
"""Joint limits lie this far outside the cycle's extremes (rad; prismatic: x length scale)."""
FULL_TURN_FRACTION = 1.0 - 1e-9
"""A swing wider than this fraction of 2 pi is treated as a full turn (``continuous``)."""
_GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0
"""The golden section's inner fraction."""


def _golden_extremes(f, centres, rows, half_width, sign):
    """
    Return refined extreme values of ``f`` near ``centres`` (one ``f`` call per step).

    Candidate i: row ``rows[i]`` within ``centres[i] +- half_width``, a minimum for
    ``sign[i]`` +1, a maximum for -1.
    """
    cols = np.arange(len(centres))
    sign = np.broadcast_to(np.asarray(sign, dtype=float), cols.shape)
    a, b = centres - half_width, centres + half_width
    c, d = b - _GOLDEN * (b - a), a + _GOLDEN * (b - a)

    def value(psi):
        return sign * f(psi)[rows, cols]

    fc, fd = value(c), value(d)
    for _ in range(GOLDEN_ITERATIONS):
        left = fc < fd
        b = np.where(left, d, b)
        a = np.where(left, a, c)
        c_new = b - _GOLDEN * (b - a)
        d_new = a + _GOLDEN * (b - a)
        c, d = np.where(left, c_new, d), np.where(left, c, d_new)
        fresh = np.where(left, c, d)
        fv = value(fresh)
        fc, fd = np.where(left, fv, fd), np.where(left, fc, fv)
    return sign * np.minimum(fc, fd)


def cycle_ranges(f, start_rad, angular):
    """
    Return ``(lower, upper, turns)`` of each row of ``f(psi)`` over one crank turn.

    ``angular`` ``(n_rows,)``: which rows are angles.  ``turns``: full turns per crank turn
    (0: a limited swing; otherwise lower and upper are nan).
    """
    angular = np.asarray(angular, dtype=bool)
    psi = start_rad + TWO_PI * np.arange(RANGE_SAMPLES + 1) / RANGE_SAMPLES
    values = np.asarray(f(psi), dtype=float)
    values = np.where(angular[:, None], np.unwrap(values, axis=1), values)
    turns = np.where(angular, np.round((values[:, -1] - values[:, 0]) / TWO_PI), 0.0)
    span = values.max(axis=1) - values.min(axis=1)
    turns = np.where(angular & (span >= FULL_TURN_FRACTION * TWO_PI) & (turns == 0),
                     np.nan, turns)  # swings a full turn and back: continuous as well
    mid = 0.5 * (values.max(axis=1) + values.min(axis=1))

    def centred(p):
        v = np.asarray(f(p), dtype=float) - mid[:, None]
        return np.where(angular[:, None], wrap_angle(v), v)

    rows = np.arange(values.shape[0])
    sampled = centred(psi[:-1])
    h = TWO_PI / RANGE_SAMPLES
    n = len(rows)   # the minima and maxima of every row refined together
    both = _golden_extremes(centred, np.concatenate([psi[np.argmin(sampled, axis=1)],
                                                     psi[np.argmax(sampled, axis=1)]]),
                            np.concatenate([rows, rows]), h,
                            np.concatenate([np.ones(n), -np.ones(n)]))
    low, high = both[:n], both[n:]
    low = np.minimum(low, sampled.min(axis=1)) + mid
    high = np.maximum(high, sampled.max(axis=1)) + mid
    limited = turns == 0
    return np.where(limited, low, np.nan), np.where(limited, high, np.nan), turns


def angle_limits(lower, upper):
    """
    Return ``(offset, lower, upper)`` of a limited revolute joint.

    Offset 0 when the swing fits in (-pi, pi], else its middle; widened by LIMIT_MARGIN.
    """
    k = math.ceil((upper + LIMIT_MARGIN - math.pi) / TWO_PI)
    if lower - LIMIT_MARGIN - k * TWO_PI > -math.pi:
        offset = k * TWO_PI
        lo, hi = lower - offset, upper - offset
        return 0.0, lo - LIMIT_MARGIN, hi + LIMIT_MARGIN
    mid = 0.5 * (lower + upper)
    half = 0.5 * (upper - lower) + LIMIT_MARGIN
    return float(wrap_angle(mid)), -half, half
