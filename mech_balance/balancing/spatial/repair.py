"""The constraints of a spatial redistribution at a design, and the repair of solver round-off."""

import math

from mech_balance.balancing.spatial.model import coordinates, program_units, PSD_ROUNDOFF
from mech_balance.core import regressor
import numpy as np

VIOLATION_TOL = 16.0 * np.finfo(float).eps
"""A design meets a constraint violated by at most this (units of its body's mass and reach)."""
REPAIR_GROWTH = 2.0
"""The realizability repair multiplies its step by this factor until the body is PSD."""
REPAIR_STEPS = 60
"""Most steps of the realizability repair."""


class RealizableChecks:
    """The constraints of a redistribution at a design, and the repair of round-off."""

    def __init__(self, model, free_idx, mlo, mhi, extent):
        self.model, self.free, self.mlo, self.mhi, self.extent = \
            model, free_idx, mlo, mhi, extent

    def _body(self, theta, k):
        """Return body k's violations: mass low, mass high, J not PSD, extent (its units)."""
        t = theta[10 * k:10 * k + 10]
        m0, r0 = program_units(self.model, k, self.mlo[k], self.mhi[k], self.extent[k])
        d = np.array([1.0 / (math.sqrt(m0) * r0)] * 3 + [1.0 / math.sqrt(m0)])
        j = regressor.pseudo_inertia(t) * np.outer(d, d)
        eig = np.linalg.eigvalsh(j)
        return [(self.mlo[k] - t[0]) / m0, (t[0] - self.mhi[k]) / m0,
                -float(eig[0]) - PSD_ROUNDOFF * float(np.abs(eig).max()),
                (0.5 * (t[4] + t[6] + t[9]) - t[0] * self.extent[k] ** 2) / (m0 * r0 * r0)]

    def violation(self, theta):
        """Return the worst constraint violation, >= 0 (units of each body's mass and reach)."""
        return float(max([0.0] + [max(self._body(theta, k)) for k in self.free]))

    def anchor(self, near=None):
        """Return a design strictly inside every bound (``near``: keep its mass, first moment)."""
        theta = self.model.theta.copy()
        for k in self.free:
            body = self.model.bodies[k]
            m = 0.5 * (self.mlo[k] + self.mhi[k]) if near is None else \
                min(max(float(near[10 * k]), self.mlo[k]), self.mhi[k])
            r2 = self.extent[k] ** 2
            if body.basis.shape[1] == 10:
                h = np.zeros(3) if near is None else np.array(near[10 * k + 1:10 * k + 4])
                size = float(np.linalg.norm(h))
                if size > 0.5 * m * math.sqrt(r2):
                    h = h * (0.5 * m * math.sqrt(r2) / size)
                sigma = np.outer(h, h) / m + (m * r2 - float(h @ h) / m) / 6.0 * np.eye(3)
                i_o = np.trace(sigma) * np.eye(3) - sigma
                target = np.array([m, *h, i_o[0, 0], i_o[0, 1], i_o[1, 1], i_o[0, 2],
                                   i_o[1, 2], i_o[2, 2]])
                theta[10 * k:10 * k + 10] = target
            else:   # a body on a line (m, its first and second moment along it)
                theta[10 * k:10 * k + 10] = body.basis @ self._line_anchor(body, m, r2, near, k)
        return theta

    @staticmethod
    def _line_anchor(body, m, r2, near, k):
        """Return y = (m, mu1, mu2) of a body on a line strictly inside its bounds."""
        def spread(y):
            """Return tr(Sigma) of the coordinates y."""
            t = body.basis @ y
            return 0.5 * (t[4] + t[6] + t[9])
        mu1 = 0.0 if near is None else float(coordinates(body, near[10 * k:10 * k + 10])[1])
        for _ in range(60):
            y = np.array([m, mu1, mu1 * mu1 / m])
            unit = spread(np.array([0.0, 0.0, 1.0]))
            room = m * r2 - spread(y)
            if room > 0.0 and unit > 0.0:
                y[2] += 0.5 * room / unit
                return y
            mu1 = 0.0 if abs(mu1) < 1e-300 else 0.5 * mu1
        return np.array([m, 0.0, 0.0])

    def feasible(self, theta):
        """Return True if theta meets every constraint to :data:`VIOLATION_TOL`."""
        return self.violation(theta) <= VIOLATION_TOL

    def clip_masses(self, theta):
        """Return theta with each free body's mass clipped into its bounds (a line body scaled)."""
        theta = theta.copy()
        for k in self.free:
            m = theta[10 * k]
            target = min(max(m, self.mlo[k]), self.mhi[k])
            if m > 0.0 and target != m:
                if self.model.bodies[k].basis.shape[1] == 10:
                    theta[10 * k] = target
                else:
                    theta[10 * k:10 * k + 10] *= target / m
        return theta

    def repair(self, theta, keep_force=False, objective=None):
        """Return (theta, pull): theta moved onto the feasible set (``pull``: to the anchor)."""
        if self.feasible(theta):
            return theta, 0.0
        if not keep_force:
            theta = self.clip_masses(theta)
            if self.feasible(theta):
                return theta, 0.0
        spread, worst = self._spread(theta)
        if keep_force:
            return spread, worst
        found = [(spread, worst)] if self.feasible(spread) else []
        anchor = self.anchor(theta)
        if not self.feasible(anchor):
            anchor = self.anchor()
        if self.feasible(anchor):
            lo, hi = 0.0, 1.0
            for _ in range(REPAIR_STEPS):
                mid = 0.5 * (lo + hi)
                if self.feasible((1 - mid) * theta + mid * anchor):
                    hi = mid
                else:
                    lo = mid
            found.append(((1 - hi) * theta + hi * anchor, hi))
        if not found:
            return spread, worst
        if objective is None:
            return found[0]
        return min(found, key=lambda pair: objective(pair[0]))   # both feasible: the better

    def _spread(self, theta):
        """Return (theta, step): each body's least isotropic spread that makes J PSD."""
        theta = theta.copy()
        worst = 0.0
        for k in self.free:
            if self._body(theta, k)[2] <= VIOLATION_TOL:
                continue
            body = self.model.bodies[k]
            m0, r0 = program_units(self.model, k, self.mlo[k], self.mhi[k], self.extent[k])
            spread = body.basis @ coordinates(body, np.array([0, 0, 0, 0, 2, 0, 2, 0, 0, 2.0]))
            step = max(self._body(theta, k)[2], np.finfo(float).eps) * m0 * r0 * r0
            for _ in range(REPAIR_STEPS):
                trial = theta.copy()
                trial[10 * k:10 * k + 10] += step * spread
                if self._body(trial, k)[2] <= VIOLATION_TOL:
                    theta = trial
                    worst = max(worst, step / (m0 * r0 * r0))
                    break
                step *= REPAIR_GROWTH
        return theta, worst


__all__ = ['RealizableChecks', 'REPAIR_GROWTH', 'REPAIR_STEPS', 'VIOLATION_TOL']
