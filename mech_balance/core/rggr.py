"""
RGGR spatial four-bar (seed 002, Hedaya): scene, kinematics, dynamics and balancing.

Geometry (seed 002, section 'Mechanism description and coordinate systems', eqs. 15-21)
    Oxyz is fixed to the frame.  The output axis DO passes through O, lies in the xz-plane
    and makes the angle beta with z; its unit vector is w3 = (sin beta, 0, cos beta).  The
    input (crank) axis AE is parallel to z through E = (0, l2, 0), so OE (along y) is the
    common normal of the two axes.  Q1 = (0, l2, l1) and Q3 = l3 * w3 are the feet of the
    perpendiculars from the crank pin B and the output pin C on their axes.  The crank angle
    phi1 is the angle of Q1B from x about z; the output angle phi3 that of Q3C from x' about
    w3, where Ox'y'z' is Oxyz turned by beta about y (eq. 19).  Then
    B = Q1 + a1 (cos phi1, sin phi1, 0) and C = Q3 + a3 (cos beta cos phi3, sin phi3,
    -sin beta cos phi3) (eqs. 16, 20).  The coupler BC is a thin rod of length a2 with
    spherical joints at both ends; c2 = |BG2|.

Link frames
    Q1uvw is fixed to the crank (w along z, u along Q1B) and Q3uvw to the output link (w along
    w3, u along Q3C).  A link's centre of mass (u, v, w) and its inertia parameters are given
    in its frame and about its pivot point Q1 or Q3: the moment of inertia I_ww about the axis
    of rotation and the paper's products I_wu = integral(w u dm), I_vw = integral(v w dm)
    (positive integrals; the inertia matrix carries -I_wu and -I_vw off the diagonal, eq. 53).
    For a rotation about a fixed axis these three are the only inertia parameters that enter
    the dynamics; I_uu, I_vv and I_uv do not.  The coupler's only inertia parameter is its
    transverse moment of inertia I = I_v = I_w about G2 (eq. 60).

Assembly branch (``assembly.branch``)
    Eq. 23 has two solutions phi3 = delta +/- acos(-D1 / sqrt(D2^2 + D3^2)) with
    delta = atan2(D3, D2).  ``branch = +1`` takes the + sign, ``-1`` the - sign.
    Geometrically, ``branch`` is the sign of the triple product w3 . (BC x Q3C): on branch +1
    the turn from the coupler direction B->C to the output-link direction Q3->C is
    counter-clockwise about the output axis w3.  The two branches meet only at dead-centre
    positions of the output link (the coupler BC lies in the plane containing the output axis
    and Q3C), where :func:`kinematics` raises instead of switching branch.

The shaking wrench follows ``mech_balance.conventions``: f = -dp/dt, n = -dH_O/dt about O in
the world axes, including the motor's reaction torque.  Gravity is not included (seed 002 and
the conventions consider inertia effects only).
"""

import dataclasses
import math

from mech_balance.conventions import cycle_angles
from mech_balance.core.rig import AddedBody, batch, BodyKinematics, BodyPoses, Drawing, \
    DrawingBody, RigData
import numpy as np


class AssemblyError(ValueError):
    """The RGGR cannot be assembled, or leaves its branch, at a crank angle (named)."""


DEG = math.pi / 180.0
"""One degree in rad (for messages)."""

BRANCH_SEPARATION_MIN = 1e-6
"""
Smallest sine of half the angle between the two solutions of eq. 23 that is accepted.

Below it the output link is at (or numerically indistinguishable from) a dead centre: the
branches meet, the output rates are unbounded and the branch is undefined.
"""

DEGENERATE_LOOP_TOL = 1e-12
"""sqrt(D2^2 + D3^2) relative to 2 a3 (|l1| + |l2| + a1) below which eq. 23 has no phi3 term."""

COUPLER_FRAME_MIN = 1e-9
"""h / a2 (eq. 43) below which the coupler frame of eqs. 42 and 44 is undefined."""

FULL_ROTATION_SAMPLES = 3600
"""Crank angles (one per 0.1 deg) at which the report functions check full-cycle mobility."""


# ---------------------------------------------------------------------------------------------
# Scene
# ---------------------------------------------------------------------------------------------


# ---------------------------------------------------------------------------------------------
# Kinematics
# ---------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class RggrKinematics:
    """
    Closed-form kinematics over ``n`` crank angles; vectors are ``(n, 3)`` in Oxyz, SI.

    ``crank_axes`` and ``output_axes`` are ``(n, 3, 3)`` with the link frame's unit vectors
    u, v, w as columns.  ``coupler_m`` is A2 = C - B; ``loop_residual_m`` is |BC| - a2.
    """

    crank_angle_rad: np.ndarray
    crank_speed_rad_s: float
    output_angle_rad: np.ndarray
    output_rate_rad_s: np.ndarray
    output_accel_rad_s2: np.ndarray
    crank_axes: np.ndarray
    output_axes: np.ndarray
    pin_b_m: np.ndarray
    pin_b_vel_m_s: np.ndarray
    pin_b_acc_m_s2: np.ndarray
    pin_c_m: np.ndarray
    pin_c_vel_m_s: np.ndarray
    pin_c_acc_m_s2: np.ndarray
    coupler_m: np.ndarray
    coupler_vel_m_s: np.ndarray
    coupler_acc_m_s2: np.ndarray
    crank_centre_m: np.ndarray
    crank_centre_acc_m_s2: np.ndarray
    coupler_centre_m: np.ndarray
    coupler_centre_vel_m_s: np.ndarray
    coupler_centre_acc_m_s2: np.ndarray
    output_centre_m: np.ndarray
    output_centre_acc_m_s2: np.ndarray
    loop_residual_m: np.ndarray


def _crank_angles(crank_angle_rad):
    phi1 = np.asarray(crank_angle_rad, dtype=float)
    if phi1.ndim == 0:
        phi1 = phi1.reshape(1)
    if phi1.ndim != 1 or phi1.size == 0:
        raise AssemblyError(
            f'crank_angle_rad: got shape {phi1.shape}, expected (n,) with n >= 1')
    if not np.all(np.isfinite(phi1)):
        raise AssemblyError('crank_angle_rad: got non-finite values, expected finite angles '
                            'in rad')
    return phi1


def _check_assembly(phi1, cos_half, sin_half, amp, amp_scale):
    """Raise ValueError naming the first crank angle where eq. 23 has no regular solution."""
    degenerate = amp <= DEGENERATE_LOOP_TOL * amp_scale
    if np.any(degenerate):
        k = int(np.argmax(degenerate))
        raise AssemblyError(
            f'crank angle {phi1[k] / DEG:.6g} deg: D2 = D3 = 0 in seed 002 eq. 23, so phi3 '
            'is undetermined (output pin on the output axis or geometry degenerate); '
            'expected a geometry with sqrt(D2^2 + D3^2) > 0')
    apart = np.abs(cos_half) > 1.0
    if np.any(apart):
        k = int(np.argmax(apart))
        raise AssemblyError(
            f'crank angle {phi1[k] / DEG:.6g} deg: the RGGR linkage cannot be assembled '
            f'(|D1| / sqrt(D2^2 + D3^2) = {abs(cos_half[k]):.6g}, expected <= 1 by seed 002 '
            'eq. 23); the coupler length geometry.a2_m does not fit this crank position')
    merged = sin_half < BRANCH_SEPARATION_MIN
    if np.any(merged):
        k = int(np.argmax(merged))
        raise AssemblyError(
            f'crank angle {phi1[k] / DEG:.6g} deg: the two assembly branches meet '
            f'(sine of half their separation {sin_half[k]:.3g}, expected >= '
            f'{BRANCH_SEPARATION_MIN:g}); the output link is at a dead centre where the '
            'branch is undefined and the output rates are unbounded')


def _pivot_centre(q_m, axes, centre_uvw, rate, accel):
    """
    Position, velocity and acceleration of a point fixed in a link turning about w.

    seed 002, eqs. 27/50 (crank, rate = omega, accel = 0) and eqs. 28/52 (output link).
    """
    u, v, w = centre_uvw
    rho = u * axes[:, :, 0] + v * axes[:, :, 1] + w * axes[:, :, 2]
    turned = u * axes[:, :, 1] - v * axes[:, :, 0]      # w x rho
    radial = u * axes[:, :, 0] + v * axes[:, :, 1]      # -w x (w x rho)
    pos = q_m + rho
    vel = rate[:, None] * turned
    acc = accel[:, None] * turned - (rate ** 2)[:, None] * radial
    return pos, vel, acc


def kinematics(scene, crank_angle_rad):
    """
    Return the closed-form :class:`RggrKinematics` at the crank angles ``(n,)`` in rad.

    Raises ValueError naming the crank angle where the linkage cannot be assembled or is at
    a dead centre (the branch is never switched silently).
    """
    phi1 = _crank_angles(crank_angle_rad)
    g = scene.geometry
    om = scene.crank_speed_rad_s
    l1, l2, l3, a1, a2, a3 = g.l1_m, g.l2_m, g.l3_m, g.a1_m, g.a2_m, g.a3_m
    sb, cb = math.sin(g.beta_rad), math.cos(g.beta_rad)
    c1, s1 = np.cos(phi1), np.sin(phi1)
    n = phi1.size

    # seed 002, eqs. 24-26
    d1 = (l1 ** 2 + l2 ** 2 + l3 ** 2 - 2.0 * l1 * l3 * cb + a1 ** 2 - a2 ** 2 + a3 ** 2
          - 2.0 * l3 * a1 * sb * c1 + 2.0 * l2 * a1 * s1)
    d2 = 2.0 * a3 * (l1 * sb - a1 * cb * c1)
    d3 = -2.0 * a3 * (l2 + a1 * s1)

    # seed 002, eq. 23, D1 + D2 cos(phi3) + D3 sin(phi3) = 0, solved in closed form:
    # D2 cos + D3 sin = R cos(phi3 - delta), R = hypot(D2, D3), delta = atan2(D3, D2), so
    # phi3 = delta + branch * acos(-D1 / R).  The paper only says 'the suitable value is
    # chosen according to the initial mechanism position'; the branch is the scene's.
    amp = np.hypot(d2, d3)
    amp_scale = 2.0 * a3 * (abs(l1) + abs(l2) + a1)
    with np.errstate(divide='ignore', invalid='ignore'):
        cos_half = -d1 / amp
    sin_half = np.sqrt(np.clip(1.0 - cos_half ** 2, 0.0, None))
    _check_assembly(phi1, cos_half, sin_half, amp, amp_scale)
    phi3 = np.arctan2(d3, d2) + scene.branch * np.arccos(cos_half)
    phi3 = np.mod(phi3 + math.pi, 2.0 * math.pi) - math.pi
    c3, s3 = np.cos(phi3), np.sin(phi3)
    den = d2 * s3 - d3 * c3          # = branch * R * sin_half, never near zero here

    # seed 002, eqs. 30-33
    d4 = 2.0 * a1 * om * (l2 * c1 + l3 * sb * s1)
    d5 = 2.0 * a1 * a3 * om * cb * s1
    d6 = -2.0 * a1 * a3 * om * c1
    rate = (d4 + d5 * c3 + d6 * s3) / den

    # seed 002, eqs. 47-49 (the text prints l_3 / Gamma for phi3; D7 is d(D4)/dt, and the
    # printed D8, D9 agree with differentiating eq. 30 once more, which we re-derived)
    d7 = 2.0 * a1 * om ** 2 * (l3 * sb * c1 - l2 * s1)
    d8 = 2.0 * a1 * a3 * om ** 2 * cb * c1 - rate * (d2 * rate + 4.0 * a1 * a3 * om * c1)
    d9 = 2.0 * a1 * a3 * om ** 2 * s1 - rate * (d3 * rate + 4.0 * a1 * a3 * om * cb * s1)
    accel = (d7 + d8 * c3 + d9 * s3) / den

    zeros, ones = np.zeros(n), np.ones(n)
    # link frames: crank Q1uvw (eq. 27), output Q3uvw = Ry(beta) Rz(phi3) (eqs. 19, 28)
    crank_axes = np.stack([np.stack([c1, s1, zeros], -1),
                           np.stack([-s1, c1, zeros], -1),
                           np.stack([zeros, zeros, ones], -1)], -1)
    output_axes = np.stack([np.stack([cb * c3, s3, -sb * c3], -1),
                            np.stack([-cb * s3, c3, sb * s3], -1),
                            np.tile([sb, 0.0, cb], (n, 1))], -1)
    q1 = np.array([0.0, l2, l1])                  # seed 002, eq. 15
    q3 = l3 * np.array([sb, 0.0, cb])             # seed 002, eqs. 17, 19

    u1, v1 = crank_axes[:, :, 0], crank_axes[:, :, 1]
    u3, v3 = output_axes[:, :, 0], output_axes[:, :, 1]
    pin_b = q1 + a1 * u1                          # seed 002, eq. 16
    pin_b_vel = a1 * om * v1
    pin_b_acc = -a1 * om ** 2 * u1
    pin_c = q3 + a3 * u3                          # seed 002, eq. 20
    pin_c_vel = a3 * rate[:, None] * v3
    pin_c_acc = a3 * (accel[:, None] * v3 - (rate ** 2)[:, None] * u3)
    coupler = pin_c - pin_b                       # seed 002, eq. 21
    coupler_vel = pin_c_vel - pin_b_vel           # seed 002, eq. 34
    coupler_acc = pin_c_acc - pin_b_acc           # seed 002, eq. 72 (garbled print; this is
    #                                               the derivative of eq. 34)

    crank_total, output_total = scene.crank_total(), scene.output_total()
    g1, _, g1_acc = _pivot_centre(q1, crank_axes, crank_total.centre_uvw_m,
                                  np.full(n, om), zeros)
    g3, _, g3_acc = _pivot_centre(q3, output_axes, output_total.centre_uvw_m, rate, accel)
    mu = scene.coupler.centre_from_b_m / a2         # seed 002, eq. 12
    g2 = pin_b + mu * coupler                       # seed 002, eq. 29
    g2_vel = pin_b_vel + mu * coupler_vel
    g2_acc = pin_b_acc + mu * coupler_acc           # seed 002, eq. 51

    return RggrKinematics(
        crank_angle_rad=phi1, crank_speed_rad_s=om, output_angle_rad=phi3,
        output_rate_rad_s=rate, output_accel_rad_s2=accel,
        crank_axes=crank_axes, output_axes=output_axes,
        pin_b_m=pin_b, pin_b_vel_m_s=pin_b_vel, pin_b_acc_m_s2=pin_b_acc,
        pin_c_m=pin_c, pin_c_vel_m_s=pin_c_vel, pin_c_acc_m_s2=pin_c_acc,
        coupler_m=coupler, coupler_vel_m_s=coupler_vel, coupler_acc_m_s2=coupler_acc,
        crank_centre_m=g1, crank_centre_acc_m_s2=g1_acc,
        coupler_centre_m=g2, coupler_centre_vel_m_s=g2_vel, coupler_centre_acc_m_s2=g2_acc,
        output_centre_m=g3, output_centre_acc_m_s2=g3_acc,
        loop_residual_m=np.linalg.norm(coupler, axis=1) - a2)


def coupler_frame(kin):
    """
    Return the coupler frame G2uvw, ``(n, 3, 3)`` with U, V, W as columns.

    seed 002, eqs. 38, 42-44: U along BC, V parallel to the xy-plane (the paper's choice for
    the coupler's idle spin), W = U x V.  Undefined where BC is parallel to z (h = 0).
    """
    a = kin.coupler_m
    a2 = np.linalg.norm(a, axis=1)
    h = np.hypot(a[:, 0], a[:, 1])                                    # eq. 43
    bad = h < COUPLER_FRAME_MIN * a2
    if np.any(bad):
        k = int(np.argmax(bad))
        raise AssemblyError(
            f'crank angle {kin.crank_angle_rad[k] / DEG:.6g} deg: coupler parallel to z '
            f'(h / a2 = {h[k] / a2[k]:.3g}, expected >= {COUPLER_FRAME_MIN:g}), so the frame '
            'of seed 002 eq. 42 is undefined')
    u = a / a2[:, None]                                               # eq. 38
    v = np.stack([a[:, 1], -a[:, 0], np.zeros_like(h)], -1) / h[:, None]  # eq. 42
    w = np.stack([a[:, 0] * a[:, 2], a[:, 1] * a[:, 2], -h ** 2], -1) / (a2 * h)[:, None]
    return np.stack([u, v, w], -1)                                    # eq. 44 for W


def coupler_angular_velocity(kin):
    """
    Return the coupler's angular velocity without its idle spin, ``(n, 3)`` in rad/s.

    seed 002, eqs. 45-46, returned as Omega_v V + Omega_w W.  Reconstruction: eq. 36 prints
    (dA2/dt)_w = a2 Omega_v, but dA2/dt = Omega x A2 gives -a2 Omega_v; eq. 45 as printed
    (Omega_v = dA2z/dt / h) follows from the corrected sign, so eqs. 45-46 are used as
    printed.  The result equals U x dU/dt, the form :func:`shaking_moment_coefficients` uses.
    """
    axes = coupler_frame(kin)
    a, da = kin.coupler_m, kin.coupler_vel_m_s
    a2 = np.linalg.norm(a, axis=1)
    h = np.hypot(a[:, 0], a[:, 1])
    omega_v = da[:, 2] / h                                                   # eq. 45
    omega_w = (a[:, 1] * da[:, 0] - a[:, 0] * da[:, 1]) / (a2 * h)           # eq. 46
    return omega_v[:, None] * axes[:, :, 1] + omega_w[:, None] * axes[:, :, 2]


# ---------------------------------------------------------------------------------------------
# Dynamics
# ---------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class RggrDynamics:
    """
    Shaking wrench about O and driving torque over ``n`` crank angles (SI).

    ``shaking_force_N`` and ``shaking_moment_Nm`` are ``(n, 3)`` in Oxyz (sign convention:
    ``mech_balance.conventions``); ``driving_torque_Nm`` ``(n,)`` is the motor torque on the
    crank about +z (the crank axis w1).
    """

    kinematics: RggrKinematics
    shaking_force_N: np.ndarray
    shaking_moment_Nm: np.ndarray
    driving_torque_Nm: np.ndarray


def _pivots(geometry):
    sb, cb = math.sin(geometry.beta_rad), math.cos(geometry.beta_rad)
    q1 = np.array([0.0, geometry.l2_m, geometry.l1_m])      # seed 002, eq. 15
    q3 = geometry.l3_m * np.array([sb, 0.0, cb])            # seed 002, eqs. 17, 19
    return q1, q3


def shaking_moment_coefficients(scene, kin):
    """
    Return ``(f0, f)`` with the shaking moment about O equal to ``f0 + f @ J``.

    seed 002, eqs. 73-88: ``f0`` ``(n, 3)`` holds every term not multiplied by a product of
    inertia (eqs. 77-79, J0 = 1) and ``f`` ``(n, 3, 4)`` the coefficients of
    J = (I_1wu, I_1vw, I_3wu, I_3vw) (eqs. 80-88), the products of the crank and output link
    with their weights about Q1 and Q3.  Valid for any mass distribution (balanced or not).
    """
    # Reconstruction: the list defining J1..J4 ('these parameters are denoted as follows:')
    # is missing from the text.  Matching eqs. 80-88 with the J terms of eqs. 56 and 59 gives
    # J1 = I_1wu, J2 = I_1vw, J3 = I_3wu, J4 = I_3vw; eqs. 83-84 print l_3/i_3 for phi3 and
    # eq. 78 prints x'_g1 for x_g1.
    om = kin.crank_speed_rad_s
    crank, output, cpl = scene.crank_total(), scene.output_total(), scene.coupler
    q1, q3 = _pivots(scene.geometry)
    u1, v1 = kin.crank_axes[:, :, 0], kin.crank_axes[:, :, 1]
    u3, v3, w3 = (kin.output_axes[:, :, i] for i in range(3))
    rate = kin.output_rate_rad_s[:, None]
    accel = kin.output_accel_rad_s2[:, None]

    # seed 002, eqs. 53-56: moment of link 1's inertia forces about O without the J terms;
    # the I_1w term vanishes because the crank turns at constant speed.
    moment_crank = -np.cross(q1, crank.mass_kg * kin.crank_centre_acc_m_s2)
    # seed 002, eqs. 57-59 without the J terms (eq. 59 prints '+ m3 l3 x''_g3' in its y row;
    # eq. 57 and eq. 78 have the minus sign used here: -Q3 x m3 a_g3).
    moment_output = (-output.inertia_ww_kg_m2 * accel * w3
                     - np.cross(q3, output.mass_kg * kin.output_centre_acc_m_s2))
    # seed 002, eqs. 60-63, reconstructed.  Eq. 63 prints -I [dV/dt alpha_v + dV/dt Omega_v
    # + ...]; the derivative of eq. 62's first term is I (alpha_v V + Omega_v dV/dt + alpha_w W
    # + Omega_w dW/dt), and eq. 61 prints dx_g1/dt where dx_g2/dt is meant.  Omega_v V +
    # Omega_w W is the angular velocity normal to the rod, U x dU/dt with U = A2 / a2, so the
    # coupler's angular momentum about G2 is I U x dU/dt and its rate I U x d2U/dt2 - the
    # same quantity, free of the V-parallel-to-xy spin convention and of its singularity.
    a2 = scene.geometry.a2_m
    moment_coupler = (-cpl.transverse_inertia_kg_m2 / a2 ** 2
                      * np.cross(kin.coupler_m, kin.coupler_acc_m_s2)
                      - np.cross(kin.coupler_centre_m, cpl.mass_kg * kin.coupler_centre_acc_m_s2))
    f0 = moment_crank + moment_coupler + moment_output                       # eqs. 77-79

    f = np.stack([om ** 2 * v1,                       # eqs. 80-82: f_1 = om^2 (-s1, c1, 0)
                  -om ** 2 * u1,                      # eqs. 80-82: f_2 = om^2 (-c1, -s1, 0)
                  accel * u3 + rate ** 2 * v3,        # eqs. 83, 85, 86
                  accel * v3 - rate ** 2 * u3], -1)   # eqs. 84, 87, 88
    return f0, f


def dynamics(scene, crank_angle_rad):
    """
    Return the :class:`RggrDynamics` of ``scene`` at the crank angles ``(n,)`` in rad.

    Shaking force -(sum m_i a_Gi) (time derivative of seed 002 eq. 1), shaking moment
    f0 + f J about O (eqs. 73-75), driving torque from the power balance.
    """
    kin = kinematics(scene, crank_angle_rad)
    crank, output, cpl = scene.crank_total(), scene.output_total(), scene.coupler
    force = -(crank.mass_kg * kin.crank_centre_acc_m_s2
              + cpl.mass_kg * kin.coupler_centre_acc_m_s2
              + output.mass_kg * kin.output_centre_acc_m_s2)
    f0, f = shaking_moment_coefficients(scene, kin)
    moment = f0 + f @ scene.inertia_parameters_kg_m2()                       # eqs. 73-75

    # Driving torque (not derived in seed 002): with the crank at constant speed, torque *
    # omega = dT/dt, where T = 1/2 I_3w phi3'^2 (I_3w about the output axis) + 1/2 m2 |v_G2|^2
    # + 1/2 I |dU/dt|^2 (the crank's kinetic energy is constant).
    a2 = scene.geometry.a2_m
    power = (output.inertia_ww_kg_m2 * kin.output_rate_rad_s * kin.output_accel_rad_s2
             + cpl.mass_kg * np.einsum('ij,ij->i', kin.coupler_centre_vel_m_s,
                                       kin.coupler_centre_acc_m_s2)
             + cpl.transverse_inertia_kg_m2 / a2 ** 2
             * np.einsum('ij,ij->i', kin.coupler_vel_m_s, kin.coupler_acc_m_s2))
    return RggrDynamics(kinematics=kin, shaking_force_N=force, shaking_moment_Nm=moment,
                        driving_torque_Nm=power / kin.crank_speed_rad_s)


def check_full_rotation(scene, samples=FULL_ROTATION_SAMPLES):
    """Raise ValueError if the crank cannot turn a full revolution on the scene's branch."""
    return kinematics(scene, cycle_angles(samples))


# ---------------------------------------------------------------------------------------------
# Complete force balancing (seed 002, eqs. 1-14)
# ---------------------------------------------------------------------------------------------


# ---------------------------------------------------------------------------------------------
# Minimum RMS shaking moment (seed 002, eqs. 73-95) and weight design (eqs. 96-103)
# ---------------------------------------------------------------------------------------------


# ---------------------------------------------------------------------------------------------
# Reports for the command line
# ---------------------------------------------------------------------------------------------


# ---------------------------------------------------------------------------------------------
# The Rig protocol
# ---------------------------------------------------------------------------------------------

JOINTS = ('crank', 'output')
"""Joint names of an RGGR rig: its crank and output axes (the spherical joints of the coupler
have no single coordinate)."""
CAPABILITIES = frozenset({'kinematics', 'shaking_wrench', 'driving_torque', 'kinetic_energy',
                          'balancing_weights', 'body_kinematics'})
"""What the RGGR rig computes and how it can be balanced (:attr:`Rig.capabilities`)."""


class RggrRig:
    """
    An RGGR scene behind the Rig protocol (:mod:`mech_balance.core.rig`).

    Joints: ``crank`` (phi1, omega) and ``output`` (phi3 about the output axis, seed 002 eq. 23,
    and its rate).  Seed 002's model turns the crank at constant speed: each sample is
    evaluated at its own crank speed with zero crank acceleration (an acceleration passed in
    is not used).  At zero speed every inertia load vanishes and the driving torque is its
    limit, 0 (the model has no gravity).  The shaking wrench is about the origin O of the
    frame (on the output axis, the foot of the common normal of the two axes).
    """

    moment_point = 'the origin O of the RGGR frame'
    moment_point_m = (0.0, 0.0, 0.0)
    driving_series = 'driving_torque'
    capabilities = CAPABILITIES
    joint_names = JOINTS
    joint_prismatic = (False,) * len(JOINTS)
    crank_joint = JOINTS[0]
    crank_index = 0
    outputs = ('kinematics', 'shaking_wrench', 'driving_torque')

    def __init__(self, scene, cache=True):
        self.scene = scene  # nothing is cached: ``cache`` is the protocol's argument
        self.name = scene.name
        check_full_rotation(scene)
        self._drawing = None

    def with_scene(self, scene):
        """Return the rig of another design of the same RGGR."""
        return RggrRig(scene)

    def at(self, psi, speed=None, accel=None, outputs=None):
        """Return the :class:`RigData` at crank angles ``psi`` (rad) and speeds (rad/s)."""
        speed = self.scene.crank_speed_rad_s if speed is None else speed
        psi, speed, _ = batch(psi, speed, 0.0 if accel is None else accel)
        want = set(outputs or ('shaking_wrench', 'driving_torque'))
        n = psi.size
        position, velocity = np.zeros((n, 2)), np.zeros((n, 2))
        effort, force, moment = np.zeros((n, 2)), np.zeros((n, 3)), np.zeros((n, 3))
        energy = np.zeros(n)
        residual = np.zeros(n)
        kins = []
        for value in np.unique(speed):
            sel = speed == value
            sc = dataclasses.replace(self.scene, crank_speed_rad_s=float(value))
            with np.errstate(divide='ignore', invalid='ignore'):  # torque 0/0 at rest
                dyn = dynamics(sc, psi[sel])
            kin = dyn.kinematics
            kins.append((sel, kin))
            position[sel] = np.column_stack([psi[sel], kin.output_angle_rad])
            velocity[sel] = np.column_stack([speed[sel], kin.output_rate_rad_s])
            effort[sel, 0] = dyn.driving_torque_Nm if value != 0.0 else 0.0
            force[sel], moment[sel] = dyn.shaking_force_N, dyn.shaking_moment_Nm
            residual[sel] = np.abs(kin.loop_residual_m) / self.scene.geometry.a2_m
            if 'kinetic_energy' in want:
                energy[sel] = kinetic_energy(sc, kin)
        series = {}
        if want & {'driving_torque', 'bearing_reactions'}:
            series['driving_torque'] = effort[:, 0].copy()
        if 'kinetic_energy' in want:
            series['kinetic_energy'] = energy
        kinematics_only = not want & {'shaking_wrench', 'driving_torque', 'bearing_reactions'}
        return RigData(
            psi, speed, np.zeros(n), position, velocity,
            None if kinematics_only else effort,
            None if kinematics_only else force, None if kinematics_only else moment,
            JOINTS, series=series, residual=residual, condition=np.ones(n),
            near_singular=np.zeros(n, dtype=bool), poses=lambda: self._poses(psi, kins),
            native=None)

    def body_kinematics(self, psi, speed=None, accel=None):
        """
        Return the :class:`BodyKinematics` of crank, coupler and output at crank angles ``psi``.

        Exact, from the closed-form kinematics (:func:`body_kinematics`); each sample at its
        own crank speed with zero crank acceleration, as :meth:`at`.  The bodies' frames are
        those of :meth:`RigData.bodies` (coupler: seed 002 eq. 44, origin at B).
        """
        speed = self.scene.crank_speed_rad_s if speed is None else speed
        psi, speed, _ = batch(psi, speed, 0.0 if accel is None else accel)
        n = psi.size
        names = ('crank', 'coupler', 'output')
        arrays = [np.zeros((n, 3, 3, 3))] + [np.zeros((n, 3, 3)) for _ in range(4)]
        for value in np.unique(speed):
            sel = speed == value
            sc = dataclasses.replace(self.scene, crank_speed_rad_s=float(value))
            part = body_kinematics(sc, kinematics(sc, psi[sel]))
            for whole, piece in zip(arrays, (part.rotation, part.origin_m, part.omega_rad_s,
                                             part.alpha_rad_s2, part.accel_origin_m_s2)):
                whole[sel] = piece
        return BodyKinematics(names, *arrays)

    def _poses(self, psi, kins):
        g = self.scene.geometry
        n = psi.size
        origin = np.zeros((n, 4, 3))
        rot = np.zeros((n, 4, 3, 3))
        rot[:, 0] = np.eye(3)
        for sel, kin in kins:
            origin[sel, 1] = (0.0, g.l2_m, g.l1_m)                            # Q1
            origin[sel, 2] = kin.pin_b_m                                       # B
            origin[sel, 3] = g.l3_m * np.array([math.sin(g.beta_rad), 0.0,
                                                math.cos(g.beta_rad)])         # Q3
            rot[sel, 1] = kin.crank_axes
            rot[sel, 3] = kin.output_axes
            try:
                rot[sel, 2] = coupler_frame(kin)
            except ValueError:  # coupler parallel to z: its frame is undefined, not its line
                u = kin.coupler_m / g.a2_m
                rot[sel, 2] = _frame_along(u)
        return BodyPoses(('frame', 'crank', 'coupler', 'output'), origin, rot)

    @property
    def drawing(self):
        """Return the RGGR's :class:`Drawing` (3-D; bodies in their own frames)."""
        if self._drawing is None:
            g = self.scene.geometry
            w3 = (math.sin(g.beta_rad), 0.0, math.cos(g.beta_rad))
            q3 = tuple(g.l3_m * x for x in w3)
            sc = self.scene
            c2 = sc.coupler.centre_from_b_m
            crank, output = sc.crank_total(), sc.output_total()
            bodies = (
                DrawingBody('crank', {'Q1': (0.0, 0.0, 0.0), 'B': (g.a1_m, 0.0, 0.0)},
                            ('Q1', 'B'), tuple(crank.centre_uvw_m), crank.mass_kg,
                            _weight_drawing('crank weight', sc.crank_weight)),
                DrawingBody('coupler', {'B': (0.0, 0.0, 0.0), 'C': (g.a2_m, 0.0, 0.0)},
                            ('B', 'C'), (c2, 0.0, 0.0), sc.coupler.mass_kg),
                DrawingBody('output', {'Q3': (0.0, 0.0, 0.0), 'C': (g.a3_m, 0.0, 0.0)},
                            ('Q3', 'C'), tuple(output.centre_uvw_m), output.mass_kg,
                            _weight_drawing('output weight', sc.output_weight)))
            frame = {'O': (0.0, 0.0, 0.0), 'E': (0.0, g.l2_m, 0.0),
                     'Q1': (0.0, g.l2_m, g.l1_m), 'Q3': q3}
            joints = (('B', 'coupler', 'B'), ('C', 'coupler', 'C'))
            axes = (('crank axis', (0.0, g.l2_m, 0.0), (0.0, 0.0, 1.0)),
                    ('output axis', (0.0, 0.0, 0.0), w3))
            self._drawing = Drawing(3, frame, bodies, joints, axes)
        return self._drawing


WEIGHT_DRAWING_DENSITY_KG_M3 = 7850.0
"""A balancing weight is drawn as a steel sphere of its mass (drawing only, like the URDF)."""


def _weight_drawing(name, weight):
    """Return a balancing weight as an :class:`AddedBody` (a sphere of its mass), or ()."""
    if weight is None or not weight.mass_kg > 0.0:
        return ()
    r = (3.0 * weight.mass_kg / (4.0 * math.pi * WEIGHT_DRAWING_DENSITY_KG_M3)) ** (1.0 / 3.0)
    return (AddedBody(name, tuple(float(x) for x in weight.centre_uvw_m), r, 2.0 * r,
                      weight.mass_kg),)


def kinetic_energy(scene, kin):
    """
    Return the kinetic energy of the three moving links, ``(n,)`` J.

    T = I_1ww omega^2 / 2 (crank about its fixed axis) + I_3ww phi3'^2 / 2 (output) +
    m2 |v_G2|^2 / 2 + I |dU/dt|^2 / 2 (the thin-rod coupler, U = (C - B) / a2): the same
    terms as the driving torque's power balance (:func:`dynamics`).
    """
    crank, output, cpl = scene.crank_total(), scene.output_total(), scene.coupler
    a2 = scene.geometry.a2_m
    omega = kin.crank_speed_rad_s
    return (0.5 * crank.inertia_ww_kg_m2 * omega ** 2
            + 0.5 * output.inertia_ww_kg_m2 * kin.output_rate_rad_s ** 2
            + 0.5 * cpl.mass_kg * np.einsum('ij,ij->i', kin.coupler_centre_vel_m_s,
                                            kin.coupler_centre_vel_m_s)
            + 0.5 * cpl.transverse_inertia_kg_m2 / a2 ** 2
            * np.einsum('ij,ij->i', kin.coupler_vel_m_s, kin.coupler_vel_m_s))


def body_kinematics(scene, kin):
    """
    Return the :class:`BodyKinematics` (crank, coupler, output) of :class:`RggrKinematics`.

    Crank: origin Q1, omega = omega z; output: origin Q3, omega = phi3' w3, alpha = phi3'' w3
    (fixed axes, seed 002 eqs. 27-28).  Coupler: origin B, the frame U V W of seed 002 eq. 44
    (:func:`coupler_frame`), whose angular velocity is U x dU/dt (the rod's, eqs. 45-46)
    plus the spin s U that keeps V parallel to the xy-plane, s = dV/dt . W; its
    acceleration is U x d2U/dt2 + ds/dt U + s dU/dt.  The spin carries no load for the thin
    rod (no inertia about U), so any frame convention gives the same wrench; this one is
    the derivative of the drawn frame (finite differences of :class:`BodyPoses` agree).
    """
    n = kin.crank_angle_rad.size
    g = scene.geometry
    q1, q3 = _pivots(g)
    rot = np.empty((n, 3, 3, 3))
    origin = np.zeros((n, 3, 3))
    omega = np.zeros((n, 3, 3))
    alpha = np.zeros((n, 3, 3))
    acc = np.zeros((n, 3, 3))
    rot[:, 0], rot[:, 2] = kin.crank_axes, kin.output_axes
    rot[:, 1] = coupler_frame(kin)
    origin[:, 0], origin[:, 1], origin[:, 2] = q1, kin.pin_b_m, q3
    omega[:, 0, 2] = kin.crank_speed_rad_s
    w3 = kin.output_axes[:, :, 2]
    omega[:, 2] = kin.output_rate_rad_s[:, None] * w3
    alpha[:, 2] = kin.output_accel_rad_s2[:, None] * w3
    acc[:, 1] = kin.pin_b_acc_m_s2
    a, da, dda = kin.coupler_m, kin.coupler_vel_m_s, kin.coupler_acc_m_s2
    u, du, ddu = (x / g.a2_m for x in (a, da, dda))
    # V = p / h with p = (A_y, -A_x, 0), h = |p| (eqs. 42-43) and its first two derivatives
    zero = np.zeros(n)
    p = np.stack([a[:, 1], -a[:, 0], zero], -1)
    dp = np.stack([da[:, 1], -da[:, 0], zero], -1)
    ddp = np.stack([dda[:, 1], -dda[:, 0], zero], -1)
    h = np.linalg.norm(p, axis=1)[:, None]
    dh = np.einsum('ij,ij->i', p, dp)[:, None] / h
    ddh = (np.einsum('ij,ij->i', dp, dp) + np.einsum('ij,ij->i', p, ddp))[:, None] / h \
        - dh ** 2 / h
    v = p / h
    dv = dp / h - p * dh / h ** 2
    ddv = ddp / h - 2.0 * dp * dh / h ** 2 - p * ddh / h ** 2 + 2.0 * p * dh ** 2 / h ** 3
    w = np.cross(u, v)
    dw = np.cross(du, v) + np.cross(u, dv)
    spin = np.einsum('ij,ij->i', dv, w)[:, None]
    dspin = (np.einsum('ij,ij->i', ddv, w) + np.einsum('ij,ij->i', dv, dw))[:, None]
    omega[:, 1] = np.cross(u, du) + spin * u
    alpha[:, 1] = np.cross(u, ddu) + dspin * u + spin * du
    return BodyKinematics(('crank', 'coupler', 'output'), rot, origin, omega, alpha, acc)


def _frame_along(u):
    """Return ``(n, 3, 3)`` frames whose first column is the unit vector ``u``."""
    helper = np.zeros_like(u)
    helper[:, 0] = 1.0
    v = np.cross(u, helper)
    small = np.linalg.norm(v, axis=1) < 1e-6
    helper[small] = (0.0, 1.0, 0.0)
    v = np.cross(u, helper)
    v /= np.linalg.norm(v, axis=1)[:, None]
    return np.stack([u, v, np.cross(u, v)], -1)
