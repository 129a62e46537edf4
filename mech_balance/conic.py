"""
Every cone program the package solves (Clarabel): its settings, and the run with retries.

A tolerance is stated once here; :func:`run_solver` returns a :class:`Solve`.
"""

from dataclasses import dataclass
import time

import clarabel
import numpy as np
import scipy.sparse as sp

SOLVER_TOL = 1e-9
"""Clarabel's relative and absolute gap and feasibility tolerances."""
SOLVER_MAX_ITER = 200
"""Interior-point iterations before giving up."""
RETRY_SETTINGS = (
    {},
    {'equilibrate_max_iter': 50, 'static_regularization_constant': 1e-7, 'max_iter': 400},
    {'presolve_enable': False, 'iterative_refinement_max_iter': 50,
     'static_regularization_constant': 1e-10, 'max_iter': 400},
    {'equilibrate_enable': False, 'max_iter': 400, 'tol_scale': 10.0},
)
"""Clarabel settings tried in turn until a solve ends Solved (more equilibration, another
static regularization without presolve, no equilibration with tolerances 10x looser)."""
SOLVED = ('Solved', 'AlmostSolved')
"""Statuses whose point is used; anything else after every retry is a failed stage."""
INFEASIBLE = ('PrimalInfeasible', 'AlmostPrimalInfeasible')
"""Statuses that prove (or nearly) the constraints have no common point."""


def solver_settings(**extra):
    """Return Clarabel's settings, ``extra`` overriding them (``tol_scale``: tolerances)."""
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


def solve_once(q, a, b, cones, **extra):
    """Return Clarabel's solution of ``min q'x s.t. a x + s = b, s in K`` (``a`` csc (m, n))."""
    p = sp.csc_matrix((q.size, q.size))
    return clarabel.DefaultSolver(p, q, a, b, cones, solver_settings(**extra)).solve()


@dataclass
class Solve:
    """One cone program as solved: the solution, the data (for the certificate), attempts."""

    sol: object
    status: str
    attempts: tuple        # the status of every attempt, in order
    q: np.ndarray
    a: object              # scipy csc (m, n)
    b: np.ndarray
    cones: list
    seconds: float

    @property
    def ok(self):
        """Return True if the solver's point is usable (Solved or AlmostSolved)."""
        return self.status in SOLVED and np.all(np.isfinite(np.asarray(self.sol.x)))

    def why(self):
        """Return a plain reason for a failed solve (every attempt's status)."""
        return (f'Clarabel status {self.status} after {len(self.attempts)} attempts '
                f'({", ".join(self.attempts)}; retries: more equilibration, other '
                'regularization without presolve, looser tolerances)')


def run_solver(q, a, b, cones):
    """Solve ``min q'x s.t. a x + s = b, s in K`` with Clarabel, retrying until Solved."""
    q = np.asarray(q, dtype=float)
    a = sp.csc_matrix(a)
    b = np.asarray(b, dtype=float)
    attempts, best, best_rank, t0 = [], None, None, time.perf_counter()
    for extra in RETRY_SETTINGS:
        sol = solve_once(q, a, b, cones, **extra)
        status = str(sol.status)
        attempts.append(status)
        finite = bool(np.all(np.isfinite(np.asarray(sol.x))))
        if status == 'Solved' and finite or status in INFEASIBLE:
            best = sol
            break
        rank = (status == 'AlmostSolved' and finite, finite)
        if best is None or rank > best_rank:
            best, best_rank = sol, rank
    return Solve(best, str(best.status), tuple(attempts), q, a, b, cones,
                 time.perf_counter() - t0)


def solve_tight(q, a, b, cones, tol_scale, max_iter=400):
    """Return a :class:`Solve` of one solve with Clarabel's tolerances scaled by ``tol_scale``."""
    q = np.asarray(q, dtype=float)
    a = sp.csc_matrix(a)
    b = np.asarray(b, dtype=float)
    t0 = time.perf_counter()
    sol = solve_once(q, a, b, cones, tol_scale=tol_scale, max_iter=max_iter)
    return Solve(sol, str(sol.status), (f'{sol.status} (tolerances x {tol_scale:g})',), q, a,
                 b, cones, time.perf_counter() - t0)


__all__ = ['INFEASIBLE', 'RETRY_SETTINGS', 'run_solver', 'Solve', 'SOLVED', 'solve_once',
           'solve_tight', 'solver_settings', 'SOLVER_MAX_ITER', 'SOLVER_TOL']
