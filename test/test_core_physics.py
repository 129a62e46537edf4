"""
Physics checks of the planar core, independent of its velocity, acceleration and NOC code.

The reference quantities are built from *positions only* (link poses solved at nearby crank
angles) by finite differences: with a constant crank speed omega, d/dt = omega d/dpsi.
"""

from mech_balance import schema as scene
from mech_balance.analysis import cycle as analysis
from mech_balance.conventions import cycle_angles
from mech_balance.core.planar import dynamics
import numpy as np
from numpy.testing import assert_allclose
import pytest

PLANAR = [n for n, p in scene.builtin_scenes().items() if scene.load(n).kind == 'planar']
FD_STEP_RAD = 2e-3
# 8th-order central stencils for the first and second derivative
_OFFSETS = np.arange(-4, 5)
_D1 = np.array([1 / 280, -4 / 105, 1 / 5, -4 / 5, 0, 4 / 5, -1 / 5, 4 / 105, -1 / 280])
_D2 = np.array([-1 / 560, 8 / 315, -1 / 5, 8 / 5, -205 / 72, 8 / 5, -1 / 5, 8 / 315, -1 / 560])
REL_TOL = 1e-8


def _momentum_model(rig, psi):
    """Return mass-centre positions, link angles and their psi-derivatives from poses only."""
    lk = rig.linkage
    grid = (psi[None, :] + FD_STEP_RAD * _OFFSETS[:, None]).ravel()
    state = lk.solve(grid, need_rates=False)
    com = np.array([0j] + [complex(*link.com_m) for link in rig.scene.links])
    c = (state.pose.origin + state.pose.rot * com[:, None]).reshape(lk.nb, _OFFSETS.size, -1)
    phi = state.pose.phi.reshape(lk.nb, _OFFSETS.size, -1)
    c1 = np.einsum('k,bkp->bp', _D1, c) / FD_STEP_RAD
    c2 = np.einsum('k,bkp->bp', _D2, c) / FD_STEP_RAD ** 2
    phi1 = np.einsum('k,bkp->bp', _D1, phi) / FD_STEP_RAD
    phi2 = np.einsum('k,bkp->bp', _D2, phi) / FD_STEP_RAD ** 2
    return c[:, 4], c1, c2, phi1, phi2


def _cross(a, b):
    return a.real * b.imag - a.imag * b.real


@pytest.fixture(params=PLANAR)
def rig(request):
    return analysis.Rig(scene.load(request.param))


def test_shaking_wrench_is_minus_momentum_rate(rig):
    psi = cycle_angles(48)
    omega = rig.scene.crank_speed_rad_s
    state, w = rig.evaluate(psi, ('bearing_reactions',), speed=omega, accel=0.0)
    c, _, c2, _, phi2 = _momentum_model(rig, psi)
    m = rig.inertia.mass[:, None]
    i_c = np.array([0.0] + [lk.inertia_com_kg_m2 for lk in rig.scene.links])[:, None]
    acc_c = c2 * omega ** 2
    f_ref = -np.sum(m * acc_c, axis=0)                           # -dp/dt
    arm = c - rig.linkage.pivot
    n_ref = -np.sum(i_c * phi2 * omega ** 2 + _cross(arm, m * acc_c), axis=0)  # -dH_O/dt
    f_scale = np.max(np.abs(f_ref))
    assert_allclose(w.shaking_force.real, f_ref.real, rtol=0, atol=REL_TOL * f_scale)
    assert_allclose(w.shaking_force.imag, f_ref.imag, rtol=0, atol=REL_TOL * f_scale)
    assert_allclose(w.shaking_moment, n_ref, rtol=0, atol=REL_TOL * np.max(np.abs(n_ref)))


def test_driving_power_is_kinetic_energy_rate(rig):
    psi = cycle_angles(48)
    omega = rig.scene.crank_speed_rad_s
    _, w = rig.evaluate(psi, ('bearing_reactions',), speed=omega, accel=0.0)
    _, c1, c2, phi1, phi2 = _momentum_model(rig, psi)
    m = rig.inertia.mass[:, None]
    i_c = np.array([0.0] + [lk.inertia_com_kg_m2 for lk in rig.scene.links])[:, None]
    # dT/dt = sum m v.a + I_c w alpha, all from finite differences of positions
    v, a = c1 * omega, c2 * omega ** 2
    power = np.sum(m * (v.real * a.real + v.imag * a.imag) + i_c * phi1 * phi2 * omega ** 3,
                   axis=0)
    assert_allclose(w.driving_torque * omega, power, rtol=0,
                    atol=REL_TOL * np.max(np.abs(power)))


def test_reactions_sum_to_the_shaking_wrench(rig):
    """Seed 001 eq. 41/47: frame bearing loads plus motor reaction equal eq. 39's wrench."""
    psi = cycle_angles(36)
    _, w = rig.evaluate(psi, ('bearing_reactions',))
    sc = rig.scene
    force = np.zeros(psi.size, dtype=complex)
    moment = -w.driving_torque.copy()                 # the motor stator reacts on the frame
    for jt in sc.joints:
        if scene.FRAME not in (jt.link_a, jt.link_b):
            continue
        on_link = w.reaction_force[jt.name] * (1 if jt.link_a == scene.FRAME else -1)
        mom_link = w.reaction_moment[jt.name] * (1 if jt.link_a == scene.FRAME else -1)
        point = w.reaction_point[jt.name]      # where the joint's moment is taken about
        if jt.name == sc.crank_joint:
            mom_link = 0.0
        force -= on_link
        moment -= mom_link + _cross(point - rig.linkage.pivot, on_link)
    scale = np.max(np.abs(w.shaking_force))
    assert_allclose(force.real, w.shaking_force.real, rtol=0, atol=1e-12 * scale)
    assert_allclose(force.imag, w.shaking_force.imag, rtol=0, atol=1e-12 * scale)
    assert_allclose(moment, w.shaking_moment, rtol=0,
                    atol=1e-12 * np.max(np.abs(w.shaking_moment)))
    assert w.consistency < 1e-12 * np.max(np.abs(w.driving_torque))


def test_generalized_inertia_is_twice_kinetic_energy(rig):
    psi = cycle_angles(24)
    omega = rig.scene.crank_speed_rad_s
    state, _ = rig.evaluate(psi, ('kinematics',), speed=omega, accel=0.0)
    _, c1, _, phi1, _ = _momentum_model(rig, psi)
    m = rig.inertia.mass[:, None]
    i_c = np.array([0.0] + [lk.inertia_com_kg_m2 for lk in rig.scene.links])[:, None]
    two_t = np.sum(m * np.abs(c1) ** 2 + i_c * phi1 ** 2, axis=0)   # 2T / omega^2
    got = dynamics.generalized_inertia(state, rig.inertia)
    assert_allclose(got, two_t, rtol=REL_TOL)


def test_coriolis_term_is_half_inertia_derivative(rig):
    """Seed 000 eq. 39 with psi'' = 0: C psi' = -(1/2) dI/dpsi psi'^2."""
    psi = cycle_angles(24)
    omega = rig.scene.crank_speed_rad_s
    state, w = rig.evaluate(psi, ('driving_torque',), speed=omega, accel=0.0)
    grid = (psi[None, :] + FD_STEP_RAD * _OFFSETS[:, None]).ravel()
    st_grid, _ = rig.evaluate(grid, ('kinematics',), speed=omega, accel=0.0)
    inertia = dynamics.generalized_inertia(st_grid, rig.inertia).reshape(_OFFSETS.size, -1)
    d_inertia = _D1 @ inertia / FD_STEP_RAD
    got = dynamics.coriolis_term(state, rig.inertia, w)
    ref = -0.5 * d_inertia * omega ** 2
    assert_allclose(got, ref, rtol=0, atol=REL_TOL * np.max(np.abs(ref)))


def test_slider_crank_generalized_inertia_matches_seed000_eq40():
    rig = analysis.Rig(scene.load('slider_crank'))
    psi = cycle_angles(36)
    state, _ = rig.evaluate(psi, ('kinematics',), speed=1.0, accel=0.0)
    sc = rig.scene
    crank, rod, slider = sc.links
    pose = state.pose
    o, a_pt = rig.linkage.pivot, pose.origin[2]
    r1 = pose.rot[1] * complex(*crank.com_m)              # O1 -> C1
    r12 = a_pt - o                                        # O1 -> A
    r2 = pose.rot[2] * complex(*rod.com_m)                # A -> C2
    r_theta = state.omega[2]                              # influence coefficients at psi' = 1
    r_s = state.vel[3].real
    eq40 = (crank.inertia_com_kg_m2 + crank.mass_kg * np.abs(r1) ** 2
            + r_theta ** 2 * rod.inertia_com_kg_m2
            + rod.mass_kg * np.abs(r12 + r_theta * r2) ** 2 + slider.mass_kg * r_s ** 2)
    assert_allclose(dynamics.generalized_inertia(state, rig.inertia), eq40, rtol=1e-13)
    # and the influence coefficients of seed 000 eq. 32.  Reconstruction: eq. 32 prints
    # r_theta = -j^T r12 / j^T r23, but multiplying eq. 30 by j^T gives (since j^T E = i^T)
    # i^T (r12 + r_theta r23) = 0, i.e. r_theta = -i^T r12 / i^T r23 = -r cos(psi)/(l cos(theta)).
    # The printed form evaluates to +1 for an in-line slider (j^T r23 = -j^T r12): a misprint.
    r23 = pose.origin[3] - a_pt
    assert_allclose(r_theta, -r12.real / r23.real, rtol=1e-12, atol=1e-15)
    with np.errstate(divide='ignore', invalid='ignore'):
        printed = -r12.imag / r23.imag
    assert not np.allclose(r_theta[1:], printed[1:])
    assert_allclose(r_s, -_cross(r23, r12) / r23.real, rtol=1e-12, atol=1e-15)


def test_wrench_is_linear_in_inertial_parameters():
    rig = analysis.Rig(scene.load('hoeken'))
    psi = cycle_angles(30)
    state, _ = rig.evaluate(psi, ('bearing_reactions',))
    rng = np.random.default_rng(7)
    t1, t2 = rng.normal(size=12), rng.normal(size=12)
    need = {'bearing_reactions'}

    def wrench(theta):
        w = dynamics.inverse_dynamics(rig.linkage, state, dynamics.inertia_from_vector(theta),
                                      need=need)
        reactions = np.array(list(w.reaction_force.values())).ravel()
        return np.concatenate([w.shaking_force.real, w.shaking_force.imag,
                               w.shaking_moment, w.driving_torque,
                               reactions.real, reactions.imag])
    assert_allclose(wrench(t1 + 2 * t2), wrench(t1) + 2 * wrench(t2), rtol=1e-12, atol=1e-12)


def test_only_needed_outputs_are_computed():
    rig = analysis.Rig(scene.load('hoeken'))
    psi = cycle_angles(12)
    state, w = rig.evaluate(psi, ('kinematics',))
    assert w is None and state.acc is None
    _, w = rig.evaluate(psi, ('shaking_wrench',))
    assert w.driving_torque is None and w.reaction_force is None
    _, w = rig.evaluate(psi, ('driving_torque',))
    assert w.driving_torque is not None and w.reaction_force is None
    _, w_all = rig.evaluate(psi, ('bearing_reactions',))
    assert_allclose(w.driving_torque, w_all.driving_torque, rtol=1e-12)


def test_position_solution_closes_and_is_periodic():
    for name in PLANAR:
        rig = analysis.Rig(scene.load(name))
        psi = np.concatenate([cycle_angles(90), cycle_angles(90) + 2 * np.pi,
                              cycle_angles(90) - 4 * np.pi])
        state, _ = rig.evaluate(psi, ('kinematics',))
        assert np.max(state.residual) < 1e-12, name
        rot = state.pose.rot.reshape(rig.linkage.nb, 3, -1)
        assert_allclose(rot[:, 1], rot[:, 0], atol=1e-12)
        assert_allclose(rot[:, 2], rot[:, 0], atol=1e-12)
