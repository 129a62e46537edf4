"""
Which value of a scene makes a balancing cone program ill-posed: the text a failed solve adds.

A solver failure (Clarabel's NumericalError or InsufficientProgress after every retry of
:data:`mech_balance.conic.RETRY_SETTINGS`) is reported with the scene values that spread the
program's data over more decades than the solver resolves (:func:`blame`): the objective's
units (``normalization``) far from the scene's own masses, lengths and crank speed (the
program's data goes as their ratios), or link masses spanning many decades (its variables,
each in units of its own link, then meet in the objective with coefficients as far apart).
The limits are measured (docs/balancing.md, "Certificates (safe lower bounds)").
"""

import math

_LEAD = '; the scene makes it ill-scaled: '
"""How the text of a cause begins (a failed solve's reason continues with it)."""
SPEED_UNIT_RATIO_MAX = 10.0
"""A crank speed above this many times ``normalization.omega_rad_s`` is named when a cone
program fails (:func:`speed_blame`)."""


def speed_blame(speed, omega):
    """
    Return the text naming a crank speed far above the objective's unit ('' when it is not).

    The balancing's objective is in units of the scene's ``normalization`` (force
    m l omega^2, moment m l^2 omega^2); a crank speed far above ``normalization.omega_rad_s``
    makes the cone program's data (~ (speed / omega)^2) span more decades than the solver
    resolves.  Measured on rssr_skew (spatial): certified up to 16 x, not at 48 x,
    NumericalError from about 5e3 x; hoeken (planar): certified up to 1e6 x, not from
    1e7 x.  Slower than the unit certifies (1e-13 x, 1e-9 x).  The limit stated is the
    spatial one, where both certify.
    """
    ratio = speed / omega
    if not ratio > SPEED_UNIT_RATIO_MAX:
        return ''
    return (f'{_LEAD}crank.speed_rad_s = {speed:g} is {ratio:.3g} x '
            f'normalization.omega_rad_s = {omega:g}, the unit of the objective (its data goes '
            f'as the square, {ratio ** 2:.3g}), expected a crank speed at most '
            f'{SPEED_UNIT_RATIO_MAX:g} x normalization.omega_rad_s (set it near the crank '
            'speed, or drop the normalization block)')


MASS_UNIT_RATIO_MAX = 1e6
"""The heaviest moving link above this many times ``normalization.mass_kg`` is named.
Measured on rssr_skew: certified with normalization.mass_kg 1e-4 x its own, not certified at
1e-6 x, NumericalError at 1e-10 x."""
LENGTH_UNIT_RATIO_MAX = 1e3
"""The largest link reach above this many times ``normalization.length_m`` is named.
Measured on rssr_skew: certified with normalization.length_m 1e-2 x its own, not certified
at 1e-4 x, NumericalError at 1e-8 x."""
MASS_SPAN_MAX = 1e6
"""Moving link masses spanning more than this ratio (heaviest over lightest) are named.
Measured: rssr_skew certified with its crank 3e6 x heavier (a span of 4.8e6), not certified
at 1e7 x, NumericalError at 1e8 x; hoeken certified at 1e6 x, InsufficientProgress at
1e10 x."""


def blame(scene, units=None, speed_rad_s=None):
    """
    Return the text naming every scene value that makes the program ill-posed ('' if none).

    ``units``: the objective's units (``mass_kg``, ``length_m``, ``omega_rad_s``) when they
    are the scene's ``normalization`` (None otherwise: the units are the scene's own);
    ``speed_rad_s`` the crank speed.  Each cause names its field, its value and what was
    expected (:func:`speed_blame`, :data:`MASS_UNIT_RATIO_MAX`,
    :data:`LENGTH_UNIT_RATIO_MAX`, :data:`MASS_SPAN_MAX`).
    """
    causes = []
    masses = {lk.name: float(lk.mass_kg) for lk in scene.links
              if math.isfinite(float(lk.mass_kg)) and float(lk.mass_kg) > 0.0}
    reaches = {lk.name: max([math.hypot(*p) for p in lk.points.values()] + [0.0])
               for lk in scene.links}
    if units is not None:
        if speed_rad_s is not None:
            text = speed_blame(abs(float(speed_rad_s)), abs(float(units.omega_rad_s)))
            if text:
                causes.append(text[len(_LEAD):])
        if masses:
            heavy = max(masses, key=masses.get)
            ratio = masses[heavy] / float(units.mass_kg)
            if ratio > MASS_UNIT_RATIO_MAX:
                causes.append(
                    f'links.{heavy}.mass_kg = {masses[heavy]:g} is {ratio:.3g} x '
                    f'normalization.mass_kg = {float(units.mass_kg):g}, the unit of the '
                    f'objective, expected at most {MASS_UNIT_RATIO_MAX:g} x (set the unit '
                    'near the link masses, or drop the normalization block)')
        far = max(reaches, key=reaches.get) if reaches else None
        if far is not None and reaches[far] > 0.0:
            ratio = reaches[far] / float(units.length_m)
            if ratio > LENGTH_UNIT_RATIO_MAX:
                causes.append(
                    f'links.{far}.points reach {reaches[far]:g} m, {ratio:.3g} x '
                    f'normalization.length_m = {float(units.length_m):g}, the unit of the '
                    f'objective, expected at most {LENGTH_UNIT_RATIO_MAX:g} x (set the unit '
                    'near the link lengths, or drop the normalization block)')
    if len(masses) > 1:
        heavy, light = max(masses, key=masses.get), min(masses, key=masses.get)
        span = masses[heavy] / masses[light]
        if span > MASS_SPAN_MAX:
            causes.append(
                f'links.{heavy}.mass_kg = {masses[heavy]:g} is {span:.3g} x '
                f'links.{light}.mass_kg = {masses[light]:g}, expected link masses within '
                f'{MASS_SPAN_MAX:g} x of each other (in kg: check their unit)')
    return _LEAD + '; '.join(causes) if causes else ''


__all__ = ['blame', 'LENGTH_UNIT_RATIO_MAX', 'MASS_SPAN_MAX', 'MASS_UNIT_RATIO_MAX',
           'speed_blame', 'SPEED_UNIT_RATIO_MAX']
