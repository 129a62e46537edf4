"""
The spatial shaking wrench as a linear map of the bodies' inertial parameters (the regressor).

Ten parameters per moving body in pinocchio's order (:data:`PARAMETERS`), about the body
origin in body axes; docs/core.md#the-spatial-regressor-coreregressorpy.
"""

from mech_balance.core.rig import BodyKinematics
from mech_balance.rotations import skew
import numpy as np

PARAMETERS = ('m', 'h_x', 'h_y', 'h_z', 'I_xx', 'I_xy', 'I_yy', 'I_xz', 'I_yz', 'I_zz')
"""The ten inertial parameters of one body, in the order of the regressor's columns."""
N_PARAMETERS = len(PARAMETERS)


def inertia_product_matrix(v):
    """Return ``L(v)`` ``(..., 3, 6)``: ``I v = L(v) i6``, i6 the tensor's six entries."""
    v = np.asarray(v, dtype=float)
    out = np.zeros(v.shape[:-1] + (3, 6))
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    out[..., 0, 0], out[..., 0, 1], out[..., 0, 3] = x, y, z
    out[..., 1, 1], out[..., 1, 2], out[..., 1, 4] = x, y, z
    out[..., 2, 3], out[..., 2, 4], out[..., 2, 5] = x, y, z
    return out


def inertia_matrix(params):
    """Return the ``(..., 3, 3)`` inertia tensors of ``(..., 6)`` [I_xx, I_xy, I_yy, ...]."""
    p = np.asarray(params, dtype=float)
    xx, xy, yy, xz, yz, zz = (p[..., i] for i in range(6))
    return np.stack([np.stack([xx, xy, xz], -1), np.stack([xy, yy, yz], -1),
                     np.stack([xz, yz, zz], -1)], -2)


def parameters(mass_kg, centre_m, inertia_centre_kg_m2):
    """Return theta ``(10,)`` from mass, mass centre and centroidal inertia (body axes, SI)."""
    c = np.asarray(centre_m, dtype=float)
    i_o = np.asarray(inertia_centre_kg_m2, dtype=float) + mass_kg * (
        np.dot(c, c) * np.eye(3) - np.outer(c, c))
    return np.array([mass_kg, *(mass_kg * c), i_o[0, 0], i_o[0, 1], i_o[1, 1], i_o[0, 2],
                     i_o[1, 2], i_o[2, 2]])


def pseudo_inertia(theta):
    """
    Return the ``(4, 4)`` pseudo-inertia J = [[Sigma, h], [h^T, m]] of theta (Wensing 2017).

    Sigma = integral(r r^T dm) = tr(I)/2 1 - I about the body origin; the body exists (a
    non-negative mass density produces theta) iff J is positive semi-definite.
    """
    t = np.asarray(theta, dtype=float)
    inertia = inertia_matrix(t[4:10])
    out = np.empty((4, 4))
    out[:3, :3] = 0.5 * np.trace(inertia) * np.eye(3) - inertia
    out[:3, 3] = out[3, :3] = t[1:4]
    out[3, 3] = t[0]
    return out


def _check(kin):
    if not isinstance(kin, BodyKinematics):
        raise TypeError(f'kinematics: got {type(kin).__name__}, expected BodyKinematics')
    rot = np.asarray(kin.rotation, dtype=float)
    if rot.ndim != 4 or rot.shape[2:] != (3, 3):
        raise ValueError(f'kinematics.rotation: got shape {rot.shape}, expected (n, nb, 3, 3)')
    shape = rot.shape[:2] + (3,)
    for name in ('origin_m', 'omega_rad_s', 'alpha_rad_s2', 'accel_origin_m_s2'):
        value = np.asarray(getattr(kin, name), dtype=float)
        if value.shape != shape:
            raise ValueError(f'kinematics.{name}: got shape {value.shape}, expected {shape}')
    return rot


def wrench_regressor(kin, moment_point_m=(0.0, 0.0, 0.0), gravity_m_s2=None):
    """
    Return Y ``(n, 6, 10 nb)``: [force (3); moment about the point (3)] = Y @ theta.

    ``theta`` stacks the ten parameters of every body of ``kin.names``; frame axes.  With
    ``gravity_m_s2`` ``(3,)`` the links' weight on the frame is added (what a force sensor
    under the frame reads; not part of the shaking wrench).
    """
    rot = _check(kin)
    n, nb = rot.shape[:2]
    omega = np.asarray(kin.omega_rad_s, dtype=float)
    alpha = np.asarray(kin.alpha_rad_s2, dtype=float)
    acc = np.asarray(kin.accel_origin_m_s2, dtype=float)
    arm = np.asarray(kin.origin_m, dtype=float) - np.asarray(moment_point_m, dtype=float)
    w_hat = skew(omega)
    # d/dt (R h) = omega x R h; second derivative (alpha^ + omega^ omega^) R h
    spin = (skew(alpha) + w_hat @ w_hat) @ rot                       # (n, nb, 3, 3)
    dp = np.zeros((n, nb, 3, 4))                                     # dp/dt = dp @ [m, h]
    dp[..., 0] = acc
    dp[..., 1:] = spin
    if gravity_m_s2 is not None:
        g = np.asarray(gravity_m_s2, dtype=float)
        if g.shape != (3,) or not np.all(np.isfinite(g)):
            raise ValueError(f'gravity_m_s2: got {gravity_m_s2!r}, expected 3 finite m/s^2')
        acc = acc - g        # the weight m g at the mass centre acts like an acceleration -g
        dp[..., 0] = acc
    out = np.zeros((n, nb, 6, 10))
    out[:, :, :3, :4] = -dp
    out[:, :, 3:, :4] = -skew(arm) @ dp
    out[:, :, 3:, 1:4] += skew(acc) @ rot                            # -(R h x a_o)
    om_b = np.einsum('nkji,nkj->nki', rot, omega)                    # R^T omega
    al_b = np.einsum('nkji,nkj->nki', rot, alpha)
    euler = inertia_product_matrix(al_b) + skew(om_b) @ inertia_product_matrix(om_b)
    out[:, :, 3:, 4:] = -rot @ euler
    return out.transpose(0, 2, 1, 3).reshape(n, 6, nb * 10)


def wrench(kin, theta, moment_point_m=(0.0, 0.0, 0.0), gravity_m_s2=None):
    """Return the shaking force and moment ``(n, 3)`` each of the parameters ``(10 nb,)``."""
    y = wrench_regressor(kin, moment_point_m, gravity_m_s2)
    w = y @ np.asarray(theta, dtype=float)
    return w[:, :3], w[:, 3:]


def momenta(rotation, origin_m, velocity_origin_m_s, omega_rad_s, theta,
            moment_point_m=(0.0, 0.0, 0.0)):
    """Return the total momentum and angular momentum about the point, ``(n, 3)`` each."""
    t = np.asarray(theta, dtype=float).reshape(-1, 10)
    rot = np.asarray(rotation, dtype=float)
    h_w = np.einsum('nkij,kj->nki', rot, t[:, 1:4])
    v = np.asarray(velocity_origin_m_s, dtype=float)
    om = np.asarray(omega_rad_s, dtype=float)
    p = t[:, 0][None, :, None] * v + np.cross(om, h_w)
    inertia_w = rot @ inertia_matrix(t[:, 4:10])[None] @ np.swapaxes(rot, -1, -2)
    arm = np.asarray(origin_m, dtype=float) - np.asarray(moment_point_m, dtype=float)
    h_o = np.cross(arm, p) + np.einsum('nkij,nkj->nki', inertia_w, om) + np.cross(h_w, v)
    return p.sum(axis=1), h_o.sum(axis=1)


__all__ = ['inertia_matrix', 'inertia_product_matrix', 'momenta', 'N_PARAMETERS',
           'PARAMETERS', 'parameters', 'pseudo_inertia', 'wrench', 'wrench_regressor']
