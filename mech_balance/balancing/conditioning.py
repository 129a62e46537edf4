"""The scene value that makes a cone program ill-posed: docs/balancing.md#ill-scaled-scenes."""

import math

_LEAD = '; the scene makes it ill-scaled: '
"""How the text of a cause begins (a failed solve's reason continues with it)."""
SPEED_UNIT_RATIO_MAX = 10.0
"""A crank speed above this many times ``normalization.omega_rad_s`` is named."""
MASS_UNIT_RATIO_MAX = 1e6
"""The heaviest moving link above this many times ``normalization.mass_kg`` is named."""
LENGTH_UNIT_RATIO_MAX = 1e3
"""The largest link reach above this many times ``normalization.length_m`` is named."""
MASS_SPAN_MAX = 1e6
"""Moving link masses spanning more than this ratio (heaviest over lightest) are named."""


def _unit_cause(what, value, unit_key, unit, limit, near):
    """Return the cause naming a scene value far above its objective unit, or None."""
    ratio = value / unit
    if ratio > limit:
        return (f'{what} {ratio:.3g} x normalization.{unit_key} = {unit:g}, the unit of the '
                f'objective, expected at most {limit:g} x (set the unit near the {near}, or '
                'drop the normalization block)')
    return None


def blame(scene, units=None, speed_rad_s=None):
    """Return the text naming every scene value that makes the program ill-posed ('' if none)."""
    causes = []
    masses = {lk.name: float(lk.mass_kg) for lk in scene.links
              if math.isfinite(float(lk.mass_kg)) and float(lk.mass_kg) > 0.0}
    reaches = {lk.name: max([math.hypot(*p) for p in lk.points.values()] + [0.0])
               for lk in scene.links}
    if units is not None:
        if speed_rad_s is not None:
            speed, omega = abs(float(speed_rad_s)), abs(float(units.omega_rad_s))
            ratio = speed / omega
            if ratio > SPEED_UNIT_RATIO_MAX:
                causes.append(
                    f'crank.speed_rad_s = {speed:g} is {ratio:.3g} x normalization.omega_rad_s '
                    f'= {omega:g}, the unit of the objective (its data goes as the square, '
                    f'{ratio ** 2:.3g}), expected a crank speed at most '
                    f'{SPEED_UNIT_RATIO_MAX:g} x normalization.omega_rad_s (set it near the '
                    'crank speed, or drop the normalization block)')
        if masses:
            heavy = max(masses, key=masses.get)
            causes.append(_unit_cause(f'links.{heavy}.mass_kg = {masses[heavy]:g} is',
                                      masses[heavy], 'mass_kg', float(units.mass_kg),
                                      MASS_UNIT_RATIO_MAX, 'link masses'))
        far = max(reaches, key=reaches.get) if reaches else None
        if far is not None and reaches[far] > 0.0:
            causes.append(_unit_cause(f'links.{far}.points reach {reaches[far]:g} m,',
                                      reaches[far], 'length_m', float(units.length_m),
                                      LENGTH_UNIT_RATIO_MAX, 'link lengths'))
    if len(masses) > 1:
        heavy, light = max(masses, key=masses.get), min(masses, key=masses.get)
        span = masses[heavy] / masses[light]
        if span > MASS_SPAN_MAX:
            causes.append(
                f'links.{heavy}.mass_kg = {masses[heavy]:g} is {span:.3g} x '
                f'links.{light}.mass_kg = {masses[light]:g}, expected link masses within '
                f'{MASS_SPAN_MAX:g} x of each other (in kg: check their unit)')
    causes = [c for c in causes if c]
    return _LEAD + '; '.join(causes) if causes else ''


__all__ = ['blame', 'LENGTH_UNIT_RATIO_MAX', 'MASS_SPAN_MAX', 'MASS_UNIT_RATIO_MAX',
           'SPEED_UNIT_RATIO_MAX']
