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
