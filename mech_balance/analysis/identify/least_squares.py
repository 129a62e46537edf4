"""The weighted least squares of the inertial parameters, and the base parameters."""

from dataclasses import dataclass
import math

from mech_balance.analysis import cycle as analysis
from mech_balance.analysis.identify.model import IdentifyError, PARAMETER_UNITS, regressor
import numpy as np
import scipy.linalg

RANK_RTOL = 1e-7
"""Singular values at or below this fraction of the largest span the regressor's null space."""
WEIGHT_PASSES = 3
"""Least-squares passes, each channel weighted by the previous pass's residual noise."""
COEFF_PRINT_RTOL = 1e-6
"""Coefficients of a combination below this are left out of its printed form."""
REDUCE_CHUNK = 4096
"""Samples per regressor evaluation in :func:`reduce_samples` (bounds the memory)."""


def measurements(wrench, effort, t_wrench, t_effort, motion):
    """Return (stamps, (p, c) measurement matrix) at the wrench stamps inside the valid span."""
    wrench = np.asarray(wrench, dtype=float)
    if wrench.ndim != 2 or wrench.shape[1] != 3:
        raise IdentifyError(f'wrench: got shape {wrench.shape}, expected (samples, 3): '
                            'force x, force y, moment z')
    t_w = np.asarray(t_wrench, dtype=float).ravel()
    if t_w.size != wrench.shape[0]:
        raise IdentifyError(f'wrench: {t_w.size} stamps and {wrench.shape[0]} samples, '
                            'expected one stamp per sample')
    if not (np.isfinite(wrench).all() and np.isfinite(t_w).all()):
        raise IdentifyError('wrench: non-finite value, expected finite forces and moments')
    inside = (t_w >= motion.t_s[0]) & (t_w <= motion.t_s[-1])
    meas = wrench[inside]
    if effort is not None:
        eff = np.asarray(effort, dtype=float).ravel()
        t_e = np.asarray(t_effort, dtype=float).ravel()
        if not np.isfinite(eff).all():
            raise IdentifyError('effort: non-finite value, expected finite torques')
        meas = np.column_stack([meas, np.interp(t_w[inside], t_e, eff)])
    return t_w[inside], meas


@dataclass
class Reduction:
    """What the weighted least squares needs of all samples (:func:`reduce_samples`)."""

    samples: int
    names: tuple
    factors: list           # per channel: R factor (n+1, n+1) of the centred [Y_c | r_c]
    ys_mean: np.ndarray     # (c, n) per channel mean of the scaled columns
    r0_mean: np.ndarray     # (c,) mean of measured minus the scene's model
    rms_before: np.ndarray  # (c,) RMS of the centred r0
    sigma: np.ndarray       # (c,) standard deviation of the measurements
    size: np.ndarray        # (c,) RMS over samples of the scaled regressor row norm
    residual: float         # worst loop-closure residual of the kinematic solutions
    cond: float             # worst Jacobian condition number


def reduce_samples(scene, psi, speed, accel, meas, torque, theta0, scale, chunk=REDUCE_CHUNK):
    """Return the :class:`Reduction` of the samples (QR, ``chunk`` samples at a time)."""
    nc = meas.shape[1]
    factors = [None] * nc
    names, residual, cond, squares = (), 0.0, 0.0, np.zeros(nc)
    rig = analysis.Rig(scene)                       # built (its branch traced) once
    for a in range(0, psi.size, chunk):
        k = slice(a, a + chunk)
        reg = regressor(scene, psi[k], speed[k], accel[k], torque=torque, rig=rig)
        y = reg.wrench if reg.torque is None else np.concatenate(
            [reg.wrench, reg.torque[:, None, :]], axis=1)
        names, residual, cond = reg.names, max(residual, reg.residual), max(cond, reg.cond)
        ys = y * scale                              # scaled columns: theta = scale * u
        r0 = meas[k] - y @ theta0                   # measured minus the scene's model
        squares += np.sum(ys ** 2, axis=(0, 2))
        for c in range(nc):
            block = np.column_stack([np.ones(ys.shape[0]), ys[:, c, :], r0[:, c],
                                     meas[k, c]])
            if factors[c] is not None:
                block = np.vstack([factors[c], block])
            factors[c] = np.linalg.qr(block, mode='r')
    p, n = psi.size, theta0.size
    means = np.array([f[0, 1:] / f[0, 0] for f in factors])     # (c, n + 2)
    centred = [f[1:, 1:] for f in factors]
    return Reduction(
        samples=p, names=names, factors=[f[:n + 1, :n + 1] for f in centred],
        ys_mean=means[:, :n], r0_mean=means[:, n],
        rms_before=np.array([np.linalg.norm(f[:, n]) for f in centred]) / math.sqrt(p),
        sigma=np.array([np.linalg.norm(f[:, n + 1]) for f in centred]) / math.sqrt(p),
        size=np.sqrt(squares / p), residual=residual, cond=cond)


@dataclass
class WeightedFit:
    """The bias-free weighted least squares in scaled coordinates (:func:`weighted_fit`)."""

    singular_values: np.ndarray   # of the weighted, scaled regressor
    vt: np.ndarray                # its right singular vectors (rows)
    rank: int
    du: np.ndarray                # minimum-norm scaled deviation from the scene
    sigma: np.ndarray             # (c,) noise level per channel (the weights)
    res_sq: np.ndarray            # (c,) residual sum of squares per channel
    s2: float                     # residual variance of the weighted problem

    @property
    def row_space(self):
        """Return the ``(n, rank)`` basis of what the data determines."""
        return self.vt[:self.rank].T


def weighted_fit(red, nparam, nc):
    """Return the :class:`WeightedFit` of a :class:`Reduction` (``nc`` channels)."""
    p = red.samples
    sigma = np.where(red.sigma > 0.0, red.sigma, 1.0)
    for _ in range(WEIGHT_PASSES):
        stacked = np.vstack([f / s for f, s in zip(red.factors, sigma)])
        u_mat, sv, vt = np.linalg.svd(stacked[:, :nparam], full_matrices=False)
        if not sv.size or sv[0] <= 0.0:
            raise IdentifyError('recording: the measured motion excites no inertial '
                                'parameter, expected a turning crank')
        rank = int(np.sum(sv > RANK_RTOL * sv[0]))
        du = vt[:rank].T @ ((u_mat[:, :rank].T @ stacked[:, nparam]) / sv[:rank])
        step = np.append(-du, 1.0)
        res_sq = np.array([float(np.sum((f @ step) ** 2)) for f in red.factors])
        new_sigma = np.sqrt(res_sq / max(p - 1 - nparam / nc, 1.0))
        sigma = np.where(new_sigma > 0.0, new_sigma, sigma)
    dof = max(p * nc - rank - nc, 1)
    s2 = float(np.sum(res_sq / sigma ** 2)) / dof
    return WeightedFit(sv, vt, rank, du, sigma, res_sq, s2)


@dataclass
class Combination:
    """One identifiable combination of parameters: ``sum coefficients[j] theta_j``."""

    base: str                 # the base parameter (coefficient 1)
    unit: str
    coefficients: np.ndarray  # (4 n,) on theta (SI)
    estimate: float
    std_error: float
    scene_value: float
    text: str
    calibrated_value: float = math.nan   # of the (physically consistent) calibrated scene

    def value(self, theta):
        """Return the combination of a parameter vector (e.g. the truth)."""
        return float(self.coefficients @ np.asarray(theta, dtype=float))

    def to_dict(self):
        """Return the combination as a plain dict."""
        return {'base': self.base, 'unit': self.unit, 'combination': self.text,
                'coefficients': [float(c) for c in self.coefficients],
                'estimate': self.estimate, 'std_error': self.std_error,
                'scene_value': self.scene_value, 'calibrated_value': self.calibrated_value}


def base_parameters(v1t, scale, names, theta, theta0, cov, theta_cal):
    """
    Return the :class:`Combination` list of the row space ``v1t`` (scaled coordinates).

    Base parameters by pivoted QR; estimates of ``theta``, ``theta0`` and ``theta_cal``.
    """
    rank = v1t.shape[0]
    _, _, piv = scipy.linalg.qr(v1t, pivoting=True, mode='economic')
    base = np.sort(piv[:rank])
    unit_rows = np.linalg.solve(v1t[:, base], v1t)   # coefficient 1 on its own base
    out = []
    for k, j in enumerate(base):
        coeff_u = unit_rows[k]
        coeff = coeff_u * scale[j] / scale         # on theta (SI), 1 on theta_j
        coeff[base] = np.where(base == j, 1.0, 0.0)
        terms = []
        for i in np.argsort(-np.abs(coeff_u)):
            if abs(coeff_u[i]) <= COEFF_PRINT_RTOL:
                continue
            if i == j:
                terms.insert(0, names[i])
            else:
                c = coeff[i]
                terms.append(f'{"-" if c < 0 else "+"} {abs(c):.6g} {names[i]}')
        out.append(Combination(
            base=names[j], unit=PARAMETER_UNITS[j % 4], coefficients=coeff,
            estimate=float(coeff @ theta),
            std_error=float(math.sqrt(max(coeff @ cov @ coeff, 0.0))),
            scene_value=float(coeff @ theta0), text=' '.join(terms),
            calibrated_value=float(coeff @ theta_cal)))
    return out
