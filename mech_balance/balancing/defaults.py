"""The one home of every balancing default (the README's *Conventions* lists them)."""


DEFAULT_WEIGHTS = (0.5, 0.5)
"""Default objective weights (w1, w2) of the RMS shaking force and moment (seed 001 eq. 43)."""
PAPER_MASS_FACTORS = (1.0, 5.0)
"""Link mass bounds as factors of the original mass (seed 001 eqs. 50b, 53b)."""
PAPER_DISTANCE_FACTORS = (0.5, 1.5)
"""Point-mass distance bounds as factors of the original l = sqrt(I_O/m) (eqs. 50c, 53c)."""
CENTROIDAL_MARGIN = 1e-2
"""Realizability margin: each link keeps a centroidal moment of inertia >= this x I_O."""
CASES = ('a', 'b')
"""seed 001 sec. 4.1.2: (a) point masses of any sign, (b) non-negative point masses."""
DEFAULT_CASE = 'a'
"""Default point-mass case of the redistribution (seed 001 sec. 4.1.2): 'a', any sign."""
DEFAULT_DENSITY_KG_M3 = 7850.0
"""Counterweight material: steel."""
DEFAULT_MAX_THICKNESS_M = 0.02
"""Thickest disc allowed (m)."""
DEFAULT_MAX_RADIUS_FACTOR = 1.0
"""Disc centre at most this factor times the link's joint reach."""
DEFAULT_MAX_MASS_FACTOR = 5.0
"""Disc mass at most this factor times the link's own mass."""
DEFAULT_MAX_GYRATION_FACTOR = 2.0
"""The disc's radius of gyration about the link origin at most this x the link's joint reach."""
DEFAULT_CLEARANCE_MARGIN_M = 0.003
"""Default least clearance between a counterweight and any other body over the cycle (m)."""
MAX_CLEARANCE_MARGIN_M = 1.0
"""Largest margin accepted (m)."""
SIDES = ('auto', 'above', 'below')
"""Where the discs go along z: ``auto`` (the side with room, per disc), ``above`` or ``below``."""
COUNTERWEIGHT_RANGES = {
    'density_kg_m3': (1.0, 1e5),
    'max_thickness_m': (1e-4, 1.0),
    'max_radius_factor': (1e-3, 10.0),
    'max_mass_factor': (1e-3, 100.0),
    'max_gyration_factor': (1e-3, 100.0),
    'max_rim_radius_factor': (1e-3, 10.0),
}
"""The range of each counterweight option, (lowest, highest), both included."""
BOUND_RATIO_RANGE = (1e-6, 1e6)
"""Link mass and distance bounds of the redistribution lie within these factors of the original."""
EXTENT_FACTOR_RANGE = (0.1, 2.0)
"""The spatial redistribution's extent bound as a factor of a body's reach, where it certifies."""
SPATIAL_MASS_FACTOR_RANGE = (1e-6, 1e2)
"""Mass factors of the spatial redistribution, where it certifies."""


def check_range(name, value, lowest, highest, unit=''):
    """Return ``value`` as a float in [lowest, highest], else a ValueError naming the range."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f'{name}: got {value!r}, expected a number in [{lowest:g}, '
                         f'{highest:g}]{unit}') from None
    if not lowest <= v <= highest:   # NaN fails too
        raise ValueError(f'{name}: got {v:g}, expected a number in [{lowest:g}, '
                         f'{highest:g}]{unit} (the range in which the program is '
                         'well-posed and its design loads as a scene)')
    return v


def check_counterweight_option(option, value, name=None):
    """Return a counterweight option (a key of :data:`COUNTERWEIGHT_RANGES`) checked."""
    lowest, highest = COUNTERWEIGHT_RANGES[option]
    unit = {'density_kg_m3': ' kg/m^3', 'max_thickness_m': ' m'}.get(option, '')
    return check_range(name or option, value, lowest, highest, unit)


DISTANCE_RATIO_RANGE = (1e-2, 1e2)
"""Point-mass distance bounds (and factors) of the redistribution within these x the original l."""
ABSOLUTE_BOUND_RANGE = {'kg': (1e-6, 1e6), 'm': (1e-6, 1e3)}
"""Where a link mass (kg) or point-mass distance (m) bound may be set without the scene."""


def check_bound_pair(name, low, high, unit):
    """Raise ValueError unless ``low`` and ``high`` (None: no bound) lie in ``unit``'s range."""
    lowest, highest = ABSOLUTE_BOUND_RANGE[unit]
    for value in (low, high):
        if value is not None and not lowest <= value <= highest:
            raise ValueError(f'{name}: got {value:g} {unit}, expected bounds in '
                             f'[{lowest:g}, {highest:g}] {unit} (defaults.ABSOLUTE_BOUND_RANGE:'
                             ' a bound no solver can honour)')
