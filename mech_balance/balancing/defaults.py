"""
The balancing defaults: the one home of every default the balancing options take.

The command line (``mech-balance balance``, ``record --balance``), the rig node's
``balance.*`` parameters and :func:`mech_balance.balancing.balance` all read them here; the
README's *Conventions* section lists them.
"""


DEFAULT_WEIGHTS = (0.5, 0.5)
"""Default objective weights (w1, w2) of the RMS shaking force and moment (seed 001 eq. 43):
the paper's best compromise, its cases a(2) and b(2).  The balance and record commands and
the rig node's ``balance.weights`` default to it."""


PAPER_MASS_FACTORS = (1.0, 5.0)
"""Link mass bounds as factors of the original mass (seed 001 eqs. 50b, 53b)."""


PAPER_DISTANCE_FACTORS = (0.5, 1.5)
"""Point-mass distance bounds as factors of the original l = sqrt(I_O/m) (eqs. 50c, 53c)."""


CENTROIDAL_MARGIN = 1e-2
"""Design margin of the realizability constraint: each link keeps a centroidal moment of
inertia >= this fraction of I_O (a lump of radius of gyration >= 0.1 l).  It is a requirement
of the design, not the definition of a body (:func:`mech_balance.core.equimomental.is_realizable`,
which only needs I_c above round-off): any margin above
:data:`mech_balance.core.equimomental.REALIZABLE_TOL` makes the design buildable.  Between 1e-2
and 0 the optimum moves by 0.3-0.7% on Hoeken and 0.4-3% on the carpet scraper; at 0 it is
the infimum over realizable designs, attained only by a point-mass link."""


CASES = ('a', 'b')
"""seed 001 sec. 4.1.2: (a) point masses of any sign, (b) non-negative point masses."""


DEFAULT_CASE = 'a'
"""Default point-mass case of the redistribution (seed 001 sec. 4.1.2): 'a', any sign."""


DEFAULT_DENSITY_KG_M3 = 7850.0
"""Counterweight material: steel."""


DEFAULT_MAX_THICKNESS_M = 0.02
"""Thickest disc allowed (m)."""


DEFAULT_MAX_RADIUS_FACTOR = 1.0
"""Disc centre at most this factor times the distance from the link origin to its farthest
joint point."""


DEFAULT_MAX_MASS_FACTOR = 5.0
"""Disc mass at most this factor times the link's own mass."""


DEFAULT_MAX_GYRATION_FACTOR = 2.0
"""The disc's radius of gyration about the link origin, sqrt(dI/dm) = sqrt(|r|^2 + R^2/2), at
most this factor times the link's joint reach (a disc of radius up to 2.45 x reach centred at
the reach, 2.8 x at the origin).  Not in issue 13's set, and needed: without it the closure
of the disc set holds an inertia without mass (dm -> 0, R -> infinity, dI > 0), which
optima use (the carpet scraper's links 5-7 at (0.5, 0.5)); with it dm = 0 forces dI = 0."""


DEFAULT_CLEARANCE_MARGIN_M = 0.003
"""Default least clearance between a counterweight and any other body over the cycle (m)."""
MAX_CLEARANCE_MARGIN_M = 1.0
"""Largest margin accepted (m)."""
SIDES = ('auto', 'above', 'below')
"""Where the discs go along z: ``auto`` (the side with room, per disc), ``above`` (+z beyond
the linkage) or ``below`` (-z)."""


COUNTERWEIGHT_RANGES = {
    'density_kg_m3': (1.0, 1e5),
    'max_thickness_m': (1e-4, 1.0),
    'max_radius_factor': (1e-3, 10.0),
    'max_mass_factor': (1e-3, 100.0),
    'max_gyration_factor': (1e-3, 100.0),
    'max_rim_radius_factor': (1e-3, 10.0),
}
"""The documented range of each counterweight option, (lowest, highest), both included.

Outside them the program is ill-posed for the solver or the design is no scene: above a
gyration factor of 100 the bound is off in effect, the closure of the disc set holds an
inertia without mass and the program loses its conditioning (at 1e6 on Hoeken's 12 crank and
rocker cases, 9 end uncertified with relative gaps of 5e-2 to 4 and one AlmostSolved: the
safe lower bound stays below the primal, but far below); a density below 1 kg/m^3 or a
thickness above 1 m gives discs whose radius or thickness the scene loader refuses, and
factors below 1e-3 bounds no solver resolves from a zero disc.  The rim bound (optional,
no default) above 10 x the joint reach leaves the other bounds binding and only worsens the
conditioning: at 100, with the other options at their wide ends, the relative gap is
1e-5..4e-5 (not certified) on Hoeken, the slider-crank and the carpet scraper."""


BOUND_RATIO_RANGE = (1e-6, 1e6)
"""Link mass and point-mass distance bounds of the redistribution must lie within these
factors of the link's original value: a bound of 5e-324 kg is below anything the solver
(relative accuracy 1e-9) can tell from zero, so the 'certified' link would be noise."""


EXTENT_FACTOR_RANGE = (0.1, 2.0)
"""The spatial redistribution's extent bound (``--extent-factor``, ``extent_factor``; per body
``extent_bounds`` over its reach): the RMS distance of a body's mass from its origin at most
this factor times its reach.  Both ends certified (relative gap <= 1e-5) on the spatial
built-ins with the mass factors at the ends of :data:`SPATIAL_MASS_FACTOR_RANGE` and weights
(0.5, 0.5), (1, 0), (0, 1) (largest 5.6e-6).  Outside: at 1e-2 the gap on spatial_two_loop
with mass factors (1, 1e6) was 5e-2; at 3 with (100, 100) and weights (0, 1) 1.0e-5 on
rssr_skew and 1.3e-5 on rggr, at 5 1.9e-5; at 100 and 1e3 on spatial_two_loop 1.1e-4 and
8.3e-3 (the certificate's box grows with the square of the extent), at 1e9 the lower bound
was -3.8e16 (spatial_two_loop) and -5e14 (rssr_skew)."""


SPATIAL_MASS_FACTOR_RANGE = (1e-6, 1e2)
"""Mass factors (``--mass-factors``, ``mass_factors``; per body ``mass_bounds`` over its
original mass) of the spatial redistribution: narrower than :data:`BOUND_RATIO_RANGE` at the
top.  Both ends certified on the spatial built-ins at the ends of :data:`EXTENT_FACTOR_RANGE`
(largest gap 5.6e-6).  Above 100, measured: (1e-6, 1e6) certified with the weights (0.5, 0.5)
(largest 1.3e-6) but not at extent 2 with weights (0, 1) on rggr_spatial (7.2e-3); (100,
1e6) on spatial_two_loop 5.4e-5, (10, 1e6) at extent 0.1 there 4.4e-5; (1e3, 1e3) on
rggr_spatial at extent 5 1.1e-5 (the complete balance of bodies 1e3 x heavier is met to the
solver's 1e-9 of their size: 1e-5 of the objective's unit); (1e6, 1e6) gap 1 on rssr_skew
and a solver failure on rggr_spatial."""


def check_range(name, value, lowest, highest, unit=''):
    """
    Return ``value`` as a float in [lowest, highest], else ValueError naming it and the range.

    The one check of the command line, :func:`mech_balance.balancing.counterweights` and the
    rig node's parameter validators.
    """
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
"""Point-mass distance bounds (and factors) of the redistribution within these factors of
the link's original l: the inertia about the origin scales with l^2, so 1e-2..1e2 spans
eight decades of I_O already (wider, the safe lower bound on Hoeken falls below zero)."""


ABSOLUTE_BOUND_RANGE = {'kg': (1e-6, 1e6), 'm': (1e-6, 1e3)}
"""Where a link mass (kg) or point-mass distance (m) bound may be set without the scene at
hand (the rig node's parameters): the redistribution checks :data:`BOUND_RATIO_RANGE`
against the link's original when it runs."""


def check_bound_pair(name, low, high, unit):
    """
    Raise ValueError unless ``low`` (and ``high``, None: no bound) lie in the unit's range.

    ``unit`` 'kg' or 'm' (:data:`ABSOLUTE_BOUND_RANGE`); the caller checks 0 < low <= high.
    """
    lowest, highest = ABSOLUTE_BOUND_RANGE[unit]
    for value in (low, high):
        if value is not None and not lowest <= value <= highest:
            raise ValueError(f'{name}: got {value:g} {unit}, expected bounds in '
                             f'[{lowest:g}, {highest:g}] {unit} (defaults.ABSOLUTE_BOUND_RANGE:'
                             ' a bound no solver can honour)')
