"""
The settings of every cone program the package solves (Clarabel): one place.

The balancing's programs (:mod:`mech_balance.balancing`) and the identification's
physically consistent calibration (:mod:`mech_balance.analysis.identify`) all take their
solver settings here, so a tolerance is stated once.
"""

import clarabel

SOLVER_TOL = 1e-9
"""Clarabel's relative and absolute gap and feasibility tolerances."""
SOLVER_MAX_ITER = 200
"""Interior-point iterations before giving up."""


def solver_settings(**extra):
    """
    Return Clarabel's settings for every cone program of the balancing (quiet, tolerances).

    ``extra``: settings to override (one entry of :data:`RETRY_SETTINGS`; ``tol_scale``
    multiplies the tolerances).
    """
    extra = dict(extra)
    tol = SOLVER_TOL * extra.pop('tol_scale', 1.0)
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.max_iter = SOLVER_MAX_ITER
    settings.tol_gap_abs = settings.tol_gap_rel = tol
    settings.tol_feas = tol
    for key, value in extra.items():
        setattr(settings, key, value)
    return settings
