"""
The balancing defaults: the one home of every default the balancing options take.

The command line (``mech-balance balance``, ``record --balance``), the rig node's
``balance.*`` parameters and :func:`mech_balance.balancing.balance` all read them here; the
README's *Balancing defaults* table lists them.
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
of the design, not the definition of a body (:func:`mech_balance.equimomental.is_realizable`,
which only needs I_c above round-off): any margin above
:data:`mech_balance.equimomental.REALIZABLE_TOL` makes the design buildable.  Between 1e-2
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
