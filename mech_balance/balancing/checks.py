"""The balancing's option checks: each names the option, its value and what was expected."""

import math

from mech_balance import schema
from mech_balance.balancing.defaults import BOUND_RATIO_RANGE, DISTANCE_RATIO_RANGE
from mech_balance.conventions import MAX_WEIGHT
import numpy as np


class BalanceError(ValueError):
    """A balancing problem is ill-posed, infeasible or cannot be solved."""


def check_planar(scene):
    """Raise a :class:`BalanceError` unless the scene's rig has the planar redistribution."""
    kind = schema.kind_of(scene)
    if 'mass_redistribution' not in kind.rig_factory().capabilities:
        raise BalanceError(f'scene {scene.name!r}: kind {kind.name!r}, expected a planar '
                           'scene (the rig cannot be balanced by mass redistribution; '
                           'mech_balance.balancing.balance picks its method)')


def check_weights(weights):
    """Return (w1, w2) of ``weights``: two finite numbers in [0, MAX_WEIGHT]."""
    try:
        w1, w2 = (float(v) for v in weights)
    except (TypeError, ValueError):
        raise BalanceError(f'weights: got {show(weights)}, expected two numbers (w1, w2)') \
            from None
    for name, v in (('w1', w1), ('w2', w2)):
        if not (math.isfinite(v) and v >= 0.0):
            raise BalanceError(f'weights: {name} = {v:g}, expected a finite number >= 0')
        if v > MAX_WEIGHT:
            raise BalanceError(f'weights: {name} = {v:g}, expected at most {MAX_WEIGHT:g} '
                               '(the fixed range of the weights)')
    return w1, w2


def check_nonneg(value, name, highest=None):
    """Return ``value`` as a finite float >= 0 (at most ``highest``), else name ``name``."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise BalanceError(f'{name}: got {value!r}, expected a number >= 0') from None
    if not (math.isfinite(v) and v >= 0.0):
        raise BalanceError(f'{name}: got {v:g}, expected a finite number >= 0')
    if highest is not None and v > highest:
        raise BalanceError(f'{name}: got {v:g}, expected at most {highest:g} '
                           '(the fixed range of the weights)')
    return v


def check_link_names(values, names, field_name):
    """Return the set of link names in ``values`` (each one of ``names``, once)."""
    if isinstance(values, str):
        values = [values]
    out = set()
    for v in values or ():
        if v not in names:
            raise BalanceError(f'{field_name}: got {v!r}, expected link names from '
                               f'{", ".join(names)}')
        if v in out:
            raise BalanceError(f'{field_name}: got {v!r} twice, expected each link once')
        out.add(v)
    return out


def link_bounds(given, names, original, factors, field_name, factors_name):
    """Return SI (lo, hi) arrays: factors x original, overridden per link (0 < lo <= hi <= inf)."""
    try:
        f_lo, f_hi = (float(v) for v in factors)
    except (TypeError, ValueError):
        raise BalanceError(f'{factors_name}: got {show(factors)}, expected (low, high)') \
            from None
    if not (0.0 < f_lo <= f_hi) or math.isinf(f_lo):
        raise BalanceError(f'{factors_name}: got {show(factors)}, expected factors of the '
                           'original with 0 < low <= high')
    lo = np.array(original, dtype=float) * f_lo
    hi = np.array(original, dtype=float) * f_hi
    from_factors = set(names)
    if given is not None:
        if not isinstance(given, dict):
            raise BalanceError(f'{field_name}: got {show(given)}, expected a mapping link -> '
                               '(min, max)')
        for key, pair in given.items():
            if key not in names:
                raise BalanceError(f'{field_name}.{key}: no such link, expected one of '
                                   f'{", ".join(names)}')
            i = names.index(key)
            try:
                a, b = pair
                a = float(a)
                b = math.inf if b is None else float(b)
            except (TypeError, ValueError):
                raise BalanceError(f'{field_name}.{key}: got {show(pair)}, expected '
                                   '(min, max), max may be None') from None
            if not (0.0 < a <= b) or math.isinf(a):
                raise BalanceError(f'{field_name}.{key}: got {show(pair)}, expected '
                                   '0 < min <= max')
            lo[i], hi[i] = a, b
            from_factors.discard(key)
    low_ratio, high_ratio = DISTANCE_RATIO_RANGE if field_name == 'distance_bounds' else \
        BOUND_RATIO_RANGE
    for i, name in enumerate(names):
        if not lo[i] > 0.0:   # a factor times an original of 0
            raise BalanceError(f'{field_name}.{name}: lower bound {lo[i]:g}, expected > 0 '
                               f'(the original is 0; give {field_name} for this link)')
        ref = float(original[i])
        if ref > 0.0 and not (low_ratio * ref <= lo[i] and
                              (math.isinf(hi[i]) or hi[i] <= high_ratio * ref)):
            where = f'{factors_name} {show(factors)} for link {name}' \
                if name in from_factors else f'{field_name}.{name}'
            raise BalanceError(
                f'{where}: got ({lo[i]:g}, {hi[i]:g}), expected bounds within '
                f'[{low_ratio:g}, {high_ratio:g}] x the original {ref:g} (defaults.'
                'BOUND_RATIO_RANGE, DISTANCE_RATIO_RANGE: tighter or wider bounds no '
                'solver resolves)')
    return lo, hi


def show(value):
    """Return a value for an error message: numbers as :g, never a numpy repr."""
    if isinstance(value, (list, tuple, np.ndarray)):
        return '(' + ', '.join(show(v) for v in value) + ')'
    if isinstance(value, (float, np.floating, np.integer)) and not isinstance(value, bool):
        return f'{value:g}'
    return repr(value)


def finite_or_none(x):
    """Return ``x`` as a float, or None when it is not finite (an open bound)."""
    return None if not math.isfinite(x) else float(x)


__all__ = ['BalanceError', 'check_link_names', 'check_nonneg', 'check_planar',
           'check_weights', 'finite_or_none', 'link_bounds', 'show']
