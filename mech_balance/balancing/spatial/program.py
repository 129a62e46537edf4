"""The spatial cone program (Clarabel): each pseudo-inertia a 4x4 PSD block (:data:`J_MAP`)."""

import math

import clarabel
from mech_balance.balancing import certificate
from mech_balance.balancing.certificate import POWER_ALPHA, SVEC
from mech_balance.balancing.redistribution import ConeRows
from mech_balance.balancing.spatial.model import RANK_REL_TOL
from mech_balance.conic import run_solver, solve_tight
import numpy as np
import scipy.sparse as sp

TIGHT_TOL_SCALE = 1e-3
"""An uncertified program is solved again with Clarabel's tolerances this factor tighter."""


SIGMA_ENTRIES = ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2))
"""The order of Sigma's six entries (as the inertia entries of theta)."""
SIGMA_TO_INERTIA = np.array([[0, 0, 1, 0, 0, 1], [0, -1, 0, 0, 0, 0], [1, 0, 0, 0, 0, 1],
                             [0, 0, 0, -1, 0, 0], [0, 0, 0, 0, -1, 0], [1, 0, 1, 0, 0, 0]],
                            dtype=float)
"""I = tr(Sigma) 1 - Sigma: (I_xx, I_xy, I_yy, I_xz, I_yz, I_zz) from (S_xx, S_xy, ...)."""
INERTIA_TO_SIGMA = np.linalg.inv(SIGMA_TO_INERTIA)
"""Sigma = tr(I)/2 1 - I, the inverse map."""


def _j_map():
    """Return G (10, 10): svec(J(theta)) = G theta (Clarabel's scaled triangle)."""
    g = np.zeros((10, 10))
    for row, (i, j) in enumerate(SVEC):
        f = 1.0 if i == j else math.sqrt(2.0)
        if j < 3:
            g[row, 4:10] = f * INERTIA_TO_SIGMA[SIGMA_ENTRIES.index((min(i, j), max(i, j)))]
        elif i < 3:
            g[row, 1 + i] = f
        else:
            g[row, 0] = 1.0
    return g


J_MAP = _j_map()


class ConeProgram(ConeRows):
    """The program by blocks of rows by cone; ``box_lo``/``box_hi`` hold every feasible y."""

    def __init__(self, basis, offset, units):
        self.basis = np.asarray(basis, dtype=float)
        self.offset = np.asarray(offset, dtype=float)
        self.units = units
        self.nd = self.basis.shape[1]
        super().__init__(self.nd + 2)
        self.q = np.zeros(self.nx)
        self.box_lo = np.full(self.nx, -math.inf)
        self.box_hi = np.full(self.nx, math.inf)
        self.cw = []
        self.norm_maps = []
        self.balanceable = None

    def theta(self, x):
        """Return the parameters (10 nb,) of a solution x."""
        return self.offset + self.basis @ np.asarray(x, dtype=float)[:self.nd]

    def epigraphs(self, maps, w):
        """Add t_f >= RMS force, t_n >= RMS moment (normalized) and the objective."""
        for i, (mat, unit) in enumerate(((maps.force, self.units.force_N),
                                         (maps.moment, self.units.moment_Nm))):
            g = mat / unit
            a = np.zeros((1 + g.shape[0], self.nx))
            a[0, self.nd + i] = -1.0
            a[1:, :self.nd] = -g @ self.basis
            self.add('soc', a, np.concatenate([[0.0], g @ self.offset]))
            self.q[self.nd + i] = w[i]
            self.norm_maps.append((g @ self.basis, g @ self.offset))
        self.box_lo[self.nd:] = 0.0

    def mass_rows(self, cols, b_k, lo, hi, m0):
        """Add lo <= m <= hi of the body with design columns ``cols`` (rows in units m0)."""
        a = np.zeros((2, self.nx))
        a[0, cols], a[1, cols] = -b_k[0] / m0, b_k[0] / m0
        self.add('nonneg', a, [-lo / m0, hi / m0])

    def psd(self, cols, b_k, m0, r0):
        """Add J(theta_k) PSD, as D J D with D = diag(1/(sqrt(m0) r0) 1, 1/sqrt(m0))."""
        d = np.array([1.0 / (math.sqrt(m0) * r0)] * 3 + [1.0 / math.sqrt(m0)])
        scale = np.array([d[i] * d[j] for i, j in SVEC])
        a = np.zeros((10, self.nx))
        a[:, cols] = -(scale[:, None] * J_MAP) @ b_k
        self.add('psd', a, np.zeros(10))

    def extent(self, cols, b_k, radius, m0, r0):
        """Add tr(Sigma) = tr(I)/2 <= m radius^2 (units m0 r0^2)."""
        row = 0.5 * (b_k[4] + b_k[6] + b_k[9]) - radius ** 2 * b_k[0]
        a = np.zeros((1, self.nx))
        a[0, cols] = row / (m0 * r0 * r0)
        self.add('nonneg', a, [0.0])

    def force_null(self, maps):
        """Add RMS shaking force = 0 (rows of the force map's range); False if impossible."""
        g = maps.force / self.units.force_N
        mat, c = g @ self.basis, g @ self.offset
        u, sv, vt = np.linalg.svd(mat, full_matrices=False)
        rank = int(np.sum(sv > RANK_REL_TOL * sv[0])) if sv.size and sv[0] > 0 else 0
        a = np.zeros((rank, self.nx))
        a[:, :self.nd] = vt[:rank]
        self.add('zero', a, -(u[:, :rank].T @ c) / sv[:rank])
        outside = c - u[:, :rank] @ (u[:, :rank].T @ c)
        self.null = (vt[:rank], u[:, :rank], sv[:rank])
        self.force_norm = g
        return float(np.linalg.norm(outside)) <= RANK_REL_TOL * max(np.linalg.norm(c), 1e-300)

    def project_null(self, theta):
        """Return theta moved (least change of y) onto the force map's null space exactly."""
        rows, u, sv = self.null
        y = np.linalg.lstsq(self.basis, theta - self.offset, rcond=None)[0]
        g_y = rows @ y + (u.T @ (self.force_norm @ self.offset)) / sv
        return self.offset + self.basis @ (y - rows.T @ g_y)

    def counterweight(self, x, j):
        """Return (dm, dh, Sigma (3, 3), s) of counterweight j in SI."""
        c, m0, r0 = self.cw[j]
        v = np.asarray(x, dtype=float)[c:c + 11]
        sigma = np.zeros((3, 3))
        for i, (a, b) in enumerate(SIGMA_ENTRIES):
            sigma[a, b] = sigma[b, a] = v[4 + i] * m0 * r0 * r0
        return float(v[0] * m0), v[1:4] * m0 * r0, sigma, float(v[10] * m0 * r0 * r0)

    def assemble(self):
        """Return (A csc, b, clarabel cones, [(kind, rows)])."""
        a = sp.csc_matrix(np.vstack([blk[1] for blk in self.blocks]))
        b = np.concatenate([blk[2] for blk in self.blocks])
        make = {'zero': clarabel.ZeroConeT, 'nonneg': clarabel.NonnegativeConeT,
                'soc': clarabel.SecondOrderConeT, 'psd': lambda n: clarabel.PSDTriangleConeT(4),
                'pow': lambda n: clarabel.PowerConeT(POWER_ALPHA)}
        layout = [(kind, blk.shape[0]) for kind, blk, _ in self.blocks]
        return a, b, [make[kind](n) for kind, n in layout], layout

    def solve(self, tol_scale=None):
        """Solve with :func:`mech_balance.conic.run_solver` (``tol_scale``: ``solve_tight``)."""
        a, b, cones, layout = self.assemble()
        if tol_scale is None:
            run = run_solver(self.q, a, b, cones)
        else:
            run = solve_tight(self.q, a, b, cones, tol_scale)
        run.layout = layout
        return run

    def box(self, primal):
        """Return the certificate's box: explicit bounds, the epigraphs' from norm bounds."""
        lo, hi = self.box_lo.copy(), self.box_hi.copy()
        for i, (g, c) in enumerate(self.norm_maps):
            bound = certificate.norm_bound(g, c, lo[:self.nd], hi[:self.nd])
            if self.q[self.nd + i] > 0.0:
                bound = min(bound, primal / self.q[self.nd + i] * (1.0 + 1e-12))
            hi[self.nd + i] = bound
        return lo, hi


__all__ = ['ConeProgram', 'INERTIA_TO_SIGMA', 'J_MAP', 'SIGMA_ENTRIES', 'SIGMA_TO_INERTIA',
           'TIGHT_TOL_SCALE']
