"""The forward dynamics' integrators and default tolerances (no imports: the parser reads them)."""


DEFAULT_RTOL = 1e-8
"""Relative tolerance of a simulation when the caller does not say."""
REFERENCE_RTOL = 1e-12
"""Relative tolerance of the reference solutions of :mod:`mech_balance.bench.accuracy`."""
EXPLICIT_METHODS = ('RK45', 'DOP853')
IMPLICIT_METHODS = ('Radau', 'BDF')
METHODS = EXPLICIT_METHODS + IMPLICIT_METHODS + ('LSODA',)
"""Integrators of :func:`scipy.integrate.solve_ivp` that :func:`simulate` accepts."""
