"""
Balancing the RGGR spatial four-bar (seed 002).

Complete force balance by two weights (eqs. 1-14), the minimum RMS shaking moment
(eqs. 73-95) and the weights' design (eqs. 96-103).
"""

import dataclasses
import math
import time

from mech_balance.conventions import cycle_angles, DEFAULT_SAMPLES, rms
from mech_balance.core.rggr import check_full_rotation, kinematics, \
    shaking_moment_coefficients
from mech_balance.schema.rggr import PivotBody, RggrScene
import numpy as np


@dataclasses.dataclass(frozen=True)
class ForceBalance:
    """
    The force-balanced rig: ``scene`` with both weights fitted (products of inertia zero).

    ``output_weight_radius_m`` is r of eq. 14; ``coupler_mass_fraction`` is mu = c2 / a2.
    """

    scene: RggrScene
    crank_weight: PivotBody
    output_weight: PivotBody
    output_weight_radius_m: float
    coupler_mass_fraction: float


def force_balance(scene):
    """
    Return the :class:`ForceBalance` of ``scene`` from its ``balancing_design``.

    Any weights already in the scene are replaced.  The crank weight's I_ww (which has no
    influence at constant crank speed) is that of a point mass; both weights get zero
    products of inertia, which the shaking-moment optimization then sets.
    """
    if scene.design is None:
        raise ValueError('balancing_design: missing, expected {crank_weight_mass_kg, '
                         'output_weight_density_length_kg_m2} for the force balancing')
    g, cpl = scene.geometry, scene.coupler
    mu = cpl.centre_from_b_m / g.a2_m                                       # eq. 12
    m2 = cpl.mass_kg

    # seed 002, eqs. 4 and 6-8: m_b1 (u, v, w)_b1 = -m_o1 (u, v, w)_o1 - m2 a1 (1 - mu) e_u
    first_b1 = 0.0 - scene.crank.first_moment_kg_m()      # 0.0 - avoids -0.0 in reports
    first_b1[0] -= m2 * g.a1_m * (1.0 - mu)
    mb1 = scene.design.crank_weight_mass_kg
    centre_b1 = first_b1 / mb1
    crank_weight = PivotBody(
        mass_kg=mb1, centre_uvw_m=tuple(float(x) for x in centre_b1),
        inertia_ww_kg_m2=float(mb1 * (centre_b1[0] ** 2 + centre_b1[1] ** 2)),
        product_wu_kg_m2=0.0, product_vw_kg_m2=0.0)

    # seed 002, eqs. 5 and 9-11: m_b3 (u, v, w)_b3 = -m_o3 (u, v, w)_o3 - m2 a3 mu e_u
    first_b3 = 0.0 - scene.output.first_moment_kg_m()
    first_b3[0] -= m2 * g.a3_m * mu
    radial_first = math.hypot(first_b3[0], first_b3[1])
    if radial_first == 0.0:
        raise ValueError(
            'links.output: the output link needs no radial first moment m_b3 (u_b3, v_b3) = 0, '
            'expected a nonzero one for the cylindrical weight of seed 002 eqs. 13-14')
    # seed 002, eq. 13, reconstructed.  Printed: m_b3 = {pi r^2 L [(m3 u_b3)^2 +
    # (m3 v_b3)^2]}^(1/3) with 'where f is the density'.  The cylinder has m_b3 = rho pi r^2
    # L and, with the rotation axis on a generator, r^2 = u_b3^2 + v_b3^2 (eq. 14), hence
    # m_b3^3 = rho L pi [(m_b3 u_b3)^2 + (m_b3 v_b3)^2].  With rho L = m_o1 / a1^2 (printed
    # as 'beta L') this gives m_b3 / m_o1 = 8.5075, the paper's 8.5.
    rho_l = scene.design.output_weight_density_length_kg_m2
    mb3 = (rho_l * math.pi * radial_first ** 2) ** (1.0 / 3.0)
    centre_b3 = first_b3 / mb3
    radius = math.hypot(centre_b3[0], centre_b3[1])                          # eq. 14
    # I_b3w is printed (34.56) without a formula: a solid cylinder of radius r about one of
    # its generators has m r^2 / 2 + m r^2, whatever the inclination alpha of its end faces
    # (the faces shear the cylinder along its axis, conclusion 5).
    output_weight = PivotBody(
        mass_kg=mb3, centre_uvw_m=tuple(float(x) for x in centre_b3),
        inertia_ww_kg_m2=1.5 * mb3 * radius ** 2,
        product_wu_kg_m2=0.0, product_vw_kg_m2=0.0)

    balanced = dataclasses.replace(scene, crank_weight=crank_weight, output_weight=output_weight)
    return ForceBalance(scene=balanced, crank_weight=crank_weight, output_weight=output_weight,
                        output_weight_radius_m=radius, coupler_mass_fraction=mu)


@dataclasses.dataclass(frozen=True)
class ShakingMomentOptimum:
    """
    Products of inertia J1..J4 minimizing the RMS shaking moment over ``samples`` angles.

    ``inertia_parameters_kg_m2`` = (I_1wu, I_1vw, I_3wu, I_3vw) of the links with weights;
    ``gram_matrix`` (5, 5) is F_ij of eq. 93 (index 0 for J0 = 1); the normal-equation
    residual is max_i |sum_j F_ij J_j + F_i0| / max |F_ij| (eq. 94, i = 1..4).
    """

    inertia_parameters_kg_m2: np.ndarray
    moment_rms_at_scene_Nm: float
    moment_rms_optimal_Nm: float
    gram_matrix: np.ndarray
    normal_equation_residual: float
    rank: int
    samples: int
    moment_rms_lower_bound_Nm: float = None   # safe: no J has a smaller RMS moment


def optimize_shaking_moment(scene, samples=DEFAULT_SAMPLES):
    """
    Return the :class:`ShakingMomentOptimum` of ``scene`` (meant for a force-balanced one).

    seed 002, eqs. 89-95: M_r^2 = sum F_ij J_i J_j is quadratic in J, so its minimum is the
    linear least-squares solution of f J = -f0 stacked over the samples (eq. 91's integral
    is the RMS of ``mech_balance.conventions`` over equally spaced angles).  Solved by an
    orthogonal factorization (numpy.linalg.lstsq), equivalent to eq. 94 without squaring
    its condition number.
    """
    angles = cycle_angles(samples)
    kin = kinematics(scene, angles)
    f0, f = shaking_moment_coefficients(scene, kin)
    n = angles.size
    design = f.reshape(3 * n, 4)
    target = -f0.reshape(3 * n)
    j_opt, _, rank, _ = np.linalg.lstsq(design, target, rcond=None)
    residual = design @ j_opt - target
    columns = np.concatenate([f0.reshape(3 * n, 1), design], axis=1)
    gram = columns.T @ columns / n                                           # eq. 93
    normal = gram[1:, 1:] @ j_opt + gram[1:, 0]                              # eq. 94
    scale = float(np.max(np.abs(gram[1:, 1:]))) or 1.0
    current = f0 + f @ scene.inertia_parameters_kg_m2()
    optimal = float(math.sqrt(residual @ residual / n))
    return ShakingMomentOptimum(
        inertia_parameters_kg_m2=j_opt,
        moment_rms_at_scene_Nm=float(rms(current)),
        moment_rms_optimal_Nm=optimal,
        gram_matrix=gram,
        normal_equation_residual=float(np.max(np.abs(normal)) / scale),
        rank=int(rank), samples=n,
        moment_rms_lower_bound_Nm=min(least_squares_lower_bound(design, target, residual)
                                      / math.sqrt(n), optimal))


def least_squares_lower_bound(design, target, residual):
    """
    Return a safe lower bound on ``min_J ||design J - target||`` (:mod:`.certificate`).

    The problem as a cone program ``min s s.t. ||target - design J|| <= s`` in Clarabel's
    form, the dual point (1, -r/||r||) of the residual r = design J - target (dual residual
    design' r / ||r||, the normal equations), and the box of the level set
    ``||design J|| <= ||r|| + ||target||`` (:func:`.certificate.level_set_bounds`).
    """
    from mech_balance.balancing import certificate
    rows, cols = design.shape
    norm_r = float(np.linalg.norm(residual))
    if norm_r == 0.0:
        return 0.0
    q = np.zeros(cols + 1)
    q[cols] = 1.0
    a = np.zeros((rows + 1, cols + 1))
    a[0, cols] = -1.0
    a[1:, :cols] = design
    b = np.concatenate([[0.0], target])
    z = np.concatenate([[1.0], residual / norm_r])   # -(target - design J) / ||r||
    lo, hi = np.full(cols + 1, -np.inf), np.full(cols + 1, np.inf)
    lo[:cols], hi[:cols], _ = certificate.level_set_bounds(
        design, norm_r + float(np.linalg.norm(target)), lo[:cols], hi[:cols])
    lo[cols], hi[cols] = 0.0, norm_r * (1.0 + 4.0 * certificate.UNIT_ROUNDOFF)
    bound = certificate.safe_lower_bound(q, a, b, [('soc', rows + 1)], z, lo, hi)
    return max(bound.value, 0.0)


@dataclasses.dataclass(frozen=True)
class BalancingWeightDesign:
    """
    Both balancing weights with the optimal products of inertia, and alpha and gamma.

    ``alpha_rad`` is the inclination of the output weight's end faces to its axis and
    ``gamma_rad`` the angle from the link's uw-plane to the plane of the faces' major axes
    (seed 002, Fig. 2).  ``scene`` is the force-balanced rig with these weights (its J
    equals the optimum).
    """

    scene: RggrScene
    crank_weight: PivotBody
    output_weight: PivotBody
    output_weight_radius_m: float
    alpha_rad: float
    gamma_rad: float


def design_balancing_weights(balance, optimum):
    """
    Return the :class:`BalancingWeightDesign` giving the links the optimal J1..J4.

    seed 002, eqs. 96-103.  The crank weight may be 'designed in a similar way, or in any form
    which gives I_1wu and I_1vw the values obtained' (text after eq. 103): only its products
    are returned.
    """
    j = optimum.inertia_parameters_kg_m2
    scene = balance.scene
    crank_weight = dataclasses.replace(
        balance.crank_weight,
        product_wu_kg_m2=float(j[0] - scene.crank.product_wu_kg_m2),
        product_vw_kg_m2=float(j[1] - scene.crank.product_vw_kg_m2))
    weight = balance.output_weight
    ib3wu = float(j[2] - scene.output.product_wu_kg_m2)
    ib3vw = float(j[3] - scene.output.product_vw_kg_m2)
    ub, vb, wb = weight.centre_uvw_m
    m, r = weight.mass_kg, balance.output_weight_radius_m
    # seed 002, eqs. 96-97: products about the weight's centre B3 in axes u', v', w' parallel
    # to the link's u, v, w.
    iwu_c = ib3wu - m * wb * ub
    ivw_c = ib3vw - m * vb * wb
    # seed 002, eqs. 98-101, reconstructed.  Eq. 98 prints I_w'u' = I_w''u'' cos^2(alpha)
    # - I_w''v'' sin^2(alpha) and eq. 99 is missing.  u'' makes the angle gamma with u' about
    # the common axis w' = w'', so the products transform as I_w'u' = I_w''u'' cos(gamma) -
    # I_v''w'' sin(gamma) and I_v'w' = I_w''u'' sin(gamma) + I_v''w'' cos(gamma).  The end
    # faces w'' = -u'' cot(alpha) +/- L/2 give I_w''u'' = -m r^2 / (4 tan(alpha)) (eq. 100)
    # and I_v''w'' = 0 (eq. 101).  Hence:
    magnitude = math.hypot(iwu_c, ivw_c)
    alpha = math.atan2(m * r ** 2, 4.0 * magnitude)                          # eq. 102
    # eq. 103 prints gamma = atan(I_v'w' / I_w'u'); the quadrant follows from I_w''u'' < 0:
    # cos(gamma) = -I_w'u' / |I_w''u''|, sin(gamma) = -I_v'w' / |I_w''u''|.
    gamma = math.atan2(-ivw_c, -iwu_c) % (2.0 * math.pi) if magnitude > 0.0 else 0.0
    output_weight = dataclasses.replace(weight, product_wu_kg_m2=ib3wu, product_vw_kg_m2=ib3vw)
    designed = dataclasses.replace(scene, crank_weight=crank_weight, output_weight=output_weight)
    return BalancingWeightDesign(
        scene=designed, crank_weight=crank_weight, output_weight=output_weight,
        output_weight_radius_m=r, alpha_rad=alpha, gamma_rad=gamma)


@dataclasses.dataclass(frozen=True)
class BalanceResult:
    """Force balance, shaking-moment optimum and weight design of one scene."""

    force_balance: ForceBalance
    optimum: ShakingMomentOptimum
    design: BalancingWeightDesign
    solve_time_s: float


def balance_scene(scene, samples=DEFAULT_SAMPLES):
    """Return the :class:`BalanceResult` of ``scene`` (force balance, optimum, weight design)."""
    start = time.perf_counter()
    balance = force_balance(scene)
    check_full_rotation(balance.scene)
    optimum = optimize_shaking_moment(balance.scene, samples)
    design = design_balancing_weights(balance, optimum)
    return BalanceResult(force_balance=balance, optimum=optimum, design=design,
                         solve_time_s=time.perf_counter() - start)
