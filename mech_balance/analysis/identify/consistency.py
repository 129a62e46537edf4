"""The physically consistent calibration: two Clarabel cone programs (docs/identification.md)."""

from dataclasses import dataclass
import math

from mech_balance.analysis.identify.model import IdentifyError
from mech_balance.conic import solver_settings
import numpy as np

MIN_MASS_REL = 1e-3
"""Every calibrated link's mass at least this fraction of its scene mass."""
INERTIA_MARGIN_REL = 1e-7
"""The centroidal inertia at least this fraction of the link's m l^2 (above round-off)."""
CONFIDENCE_SE = 3.0
"""The data's confidence region: every combination within this many standard errors."""
LS_TIE_REL = 1e-9
"""Constrained least squares: the pull towards the scene, times the largest sv^2."""
ACTIVE_REL = 1e-5
"""A consistency constraint whose slack is below this (relative) is reported active."""


@dataclass
class Consistency:
    """
    How the calibrated parameters were made physically consistent (:func:`consistent`).

    ``stage``: ``exact`` or ``least squares``; ``residual_growth``: relative; ``max_shift_se``:
    the largest change in standard errors; ``active``: the constraints at their bound.
    """

    stage: str
    residual_growth: float
    max_shift_se: float
    within_confidence: bool
    active: list
    solver_status: str
    iterations: int

    def describe(self):
        """Return the result in words."""
        if self.stage == 'exact':
            text = ('physically consistent: the identified combinations reproduced exactly, '
                    "the non-identifiable directions closest to the scene in each link's scale")
        else:
            text = ('no physically consistent set reproduces the identified combinations: '
                    'constrained least squares, residual grows by '
                    f'{100.0 * self.residual_growth:.3g}%, combinations moved by up to '
                    f'{self.max_shift_se:.3g} standard errors ('
                    + ('within' if self.within_confidence else 'OUTSIDE')
                    + f' the {CONFIDENCE_SE:g}-SE confidence region)')
        if self.active:
            text += '; active: ' + ', '.join(self.active)
        return text

    def to_dict(self):
        """Return the result as a plain dict."""
        return {'stage': self.stage, 'residual_growth': self.residual_growth,
                'max_shift_se': self.max_shift_se,
                'within_confidence': bool(self.within_confidence),
                'active_constraints': list(self.active), 'solver_status': self.solver_status,
                'iterations': int(self.iterations)}


def consistency_cones(scene, theta0, scale):
    """Return ``(A, b, cones)``: Clarabel's consistency cones on the scaled deviation u."""
    import clarabel
    n = theta0.size
    y0 = theta0 / scale
    rows_a, rows_b, cones = [], [], []
    for i in range(len(scene.links)):
        km, kx, ky, ki = 4 * i, 4 * i + 1, 4 * i + 2, 4 * i + 3
        row = np.zeros((1, n))
        row[0, km] = -1.0
        rows_a.append(row)
        rows_b.append([y0[km] - MIN_MASS_REL])
        cones.append(clarabel.NonnegativeConeT(1))
        soc = np.zeros((4, n))
        soc[0, km], soc[0, ki] = -1.0, -1.0
        soc[1, kx] = -2.0
        soc[2, ky] = -2.0
        soc[3, km], soc[3, ki] = -1.0, 1.0
        inertia = y0[ki] - INERTIA_MARGIN_REL
        rows_a.append(soc)
        rows_b.append([y0[km] + inertia, 2.0 * y0[kx], 2.0 * y0[ky], y0[km] - inertia])
        cones.append(clarabel.SecondOrderConeT(4))
    return np.vstack(rows_a), np.concatenate(rows_b), cones


def _solve_qp(p_mat, q_vec, a_mat, b_vec, cones):
    """Return Clarabel's solution of min x^T P x / 2 + q^T x subject to b - A x in cones."""
    import clarabel
    import scipy.sparse as sp
    return clarabel.DefaultSolver(sp.csc_matrix(np.triu(p_mat)), np.asarray(q_vec, float),
                                  sp.csc_matrix(a_mat), np.asarray(b_vec, float), cones,
                                  solver_settings()).solve()


def _solved(status):
    return str(status) in ('Solved', 'AlmostSolved')


def consistent(scene, theta0, scale, v1, sv, du, chi2_ls, se_u):
    """
    Return ``(u, Consistency)``: the physically consistent scaled deviation from the scene.

    ``v1`` ``(n, r)``, ``sv``: row space and singular values; ``du``, ``chi2_ls``: the least
    squares and its residual; ``se_u``: standard errors.  Raises :class:`IdentifyError`.
    """
    import clarabel
    n = theta0.size
    a_c, b_c, cones = consistency_cones(scene, theta0, scale)
    stage = 'exact'
    sol = _solve_qp(2.0 * np.eye(n), np.zeros(n), np.vstack([v1.T, a_c]),
                    np.concatenate([v1.T @ du, b_c]),
                    [clarabel.ZeroConeT(v1.shape[1]), *cones])
    if not _solved(sol.status):
        stage = 'least squares'
        gram = v1 * sv ** 2 @ v1.T
        tie = LS_TIE_REL * float(sv[0]) ** 2
        unseen = np.eye(n) - v1 @ v1.T               # the directions the data cannot see
        sol = _solve_qp(2.0 * (gram + tie * unseen), -2.0 * gram @ du, a_c, b_c, cones)
        if not _solved(sol.status):
            raise IdentifyError(f'no physically consistent parameter set found (Clarabel '
                                f'{sol.status}): expected a positive mass and centroidal '
                                'inertia per link to be reachable')
    u = np.array(sol.x)
    shift = sv * (v1.T @ (u - du))
    growth = math.sqrt(1.0 + float(shift @ shift) / max(chi2_ls, 1e-300)) - 1.0
    moved = np.abs(v1.T @ (u - du)) / np.where(se_u > 0.0, se_u, np.inf)
    max_se = float(np.max(moved)) if moved.size else 0.0
    active = []
    y = (theta0 + scale * u) / scale
    for i, lk in enumerate(scene.links):
        m, hx, hy, i_o = y[4 * i:4 * i + 4]
        if m <= MIN_MASS_REL * (1.0 + ACTIVE_REL):
            active.append(f'links.{lk.name}.mass_kg > 0')
        if m * (i_o - INERTIA_MARGIN_REL) - hx * hx - hy * hy <= ACTIVE_REL * m * i_o:
            active.append(f'links.{lk.name}.inertia_com_kg_m2 >= 0')
    if stage == 'exact':
        growth, max_se = 0.0, 0.0
    return u, Consistency(stage, growth, max_se, max_se <= CONFIDENCE_SE, active,
                          str(sol.status), int(sol.iterations))
