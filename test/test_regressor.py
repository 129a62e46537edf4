"""
Tests of the spatial regressor (core/regressor.py) and of the RGGR's body kinematics.

Three independent references: the RGGR rig's own shaking wrench (the spatial kind's
Newton-Euler, core/spatial/dynamics.py) against seed 002's parameters, finite differences
of the total momenta of a random spatial motion given in closed form, and finite
differences of the RGGR's drawn body poses.
"""

import math

from mech_balance import schema
from mech_balance.core import regressor
from mech_balance.core.rig import BodyKinematics, rig_for
import numpy as np
from numpy.testing import assert_allclose
import pytest

FD_STEP = 1e-3
"""Time (s) or crank-angle (rad) step of the finite differences."""
FD_WEIGHTS = np.array([1 / 280, -4 / 105, 1 / 5, -4 / 5, 0.0, 4 / 5, -1 / 5, 4 / 105, -1 / 280])
"""Eighth-order central first-derivative stencil over offsets -4..4."""
FD_OFFSETS = np.arange(-4, 5)
FD_RTOL = 1e-7
"""Finite-difference checks (issue 21): relative to the quantity's scale over the samples."""
CORE_RTOL = 1e-12
"""Regressor against the RGGR rig's own wrench, relative to its largest value."""
SEED_002 = {'crank': (0.5, (0.025, 0.0, 0.0), 4.1666666666666667e-4, 0.0, 0.0),
            'coupler': (1.5, 0.15, 0.01125),
            'output': (2.0, (0.10, 0.0, 0.0), 0.0275, 0.0, 0.0)}
"""Seed 002's example in SI (config/rggr.yaml): pivot links (m, centre (u, v, w), I_ww, I_wu,
I_vw about the pivot) and the coupler rod (m, distance of its centre from B, I about it)."""


def rggr_theta(spare=(0.7, 1.3)):
    """
    Return theta (30,) of the RGGR, built here from the seed-002 parameters (:data:`SEED_002`).

    I_uu, I_vv, I_uv of the pivot links do not enter a fixed-axis rotation: ``spare`` sets
    I_uu and I_vv (the tests prove they change nothing).
    """
    def pivot(body, extra):
        m, centre, i_ww, i_wu, i_vw = body
        t = np.zeros(10)
        t[0] = m
        t[1:4] = m * np.asarray(centre)
        t[4], t[6] = extra, 2.0 * extra
        t[7], t[8] = -i_wu, -i_vw   # tensor entries
        t[9] = i_ww
        return t
    m2, c2, i2 = SEED_002['coupler']
    i_b = i2 + m2 * c2 ** 2
    coupler = np.array([m2, m2 * c2, 0, 0, 0, 0, i_b, 0, 0, i_b])
    return np.concatenate([pivot(SEED_002['crank'], spare[0]), coupler,
                           pivot(SEED_002['output'], spare[1])])


@pytest.fixture(scope='module')
def rggr_rig():
    return rig_for(schema.load('rggr'))


@pytest.mark.parametrize('spare', [(0.0, 0.0), (0.7, 1.3)])
def test_regressor_reproduces_the_rggr_wrench(rggr_rig, spare):
    psi = np.linspace(0.0, 2.0 * math.pi, 73)[:-1]
    kin = rggr_rig.body_kinematics(psi)
    force, moment = regressor.wrench(kin, rggr_theta(spare),
                                     rggr_rig.moment_point_m)
    data = rggr_rig.at(psi)
    assert_allclose(force, data.force_N, rtol=0, atol=CORE_RTOL * np.abs(data.force_N).max())
    assert_allclose(moment, data.moment_Nm, rtol=0,
                    atol=CORE_RTOL * np.abs(data.moment_Nm).max())


def test_rggr_body_kinematics_at_several_speeds(rggr_rig):
    psi = np.array([0.1, 0.2, 0.3])
    speed = np.array([5.0, -10.0, 5.0])
    kin = rggr_rig.body_kinematics(psi, speed)
    force, _ = regressor.wrench(kin, rggr_theta())
    assert_allclose(force, rggr_rig.at(psi, speed).force_N, rtol=1e-12, atol=1e-12)
    assert kin.names == tuple(b.name for b in rggr_rig.drawing.bodies)


def _rotation(axis, angle):
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros(np.shape(angle) + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    out[..., axis, axis] = 1.0
    out[..., i, i] = out[..., j, j] = c
    out[..., i, j], out[..., j, i] = -s, s
    return out


def random_motion(t, rng_seed, nb=3):
    """
    Return a closed-form spatial motion of nb bodies at times t: poses, rates, accelerations.

    R = Rz(a) Ry(b) Rx(c) with trigonometric angles, origin on a Lissajous curve: omega and
    alpha from the chain rule, written out here (not the code under test).
    """
    rng = np.random.default_rng(rng_seed)
    n = t.size
    rot = np.zeros((n, nb, 3, 3))
    origin, vel, acc, omega, alpha = (np.zeros((n, nb, 3)) for _ in range(5))
    ex, ey, ez = np.eye(3)
    for k in range(nb):
        amp, freq, phase = rng.uniform(0.2, 1.5, (3, 3)), rng.uniform(0.5, 3, (3, 3)), \
            rng.uniform(0, 6, (3, 3))
        ang = amp[0] * np.sin(freq[0] * t[:, None] + phase[0])             # (n, 3) a, b, c
        dang = amp[0] * freq[0] * np.cos(freq[0] * t[:, None] + phase[0])
        ddang = -freq[0] ** 2 * ang
        rz, ry, rx = (_rotation(ax, ang[:, i]) for i, ax in enumerate((2, 1, 0)))
        rot[:, k] = rz @ ry @ rx
        y1 = rz @ ey
        x2 = rz @ ry @ ex
        om1 = dang[:, :1] * ez
        om2 = om1 + dang[:, 1:2] * y1
        omega[:, k] = om2 + dang[:, 2:3] * x2
        alpha[:, k] = (ddang[:, :1] * ez + ddang[:, 1:2] * y1
                       + dang[:, 1:2] * np.cross(om1, y1)
                       + ddang[:, 2:3] * x2 + dang[:, 2:3] * np.cross(om2, x2))
        arg = freq[1] * t[:, None] + phase[1]
        origin[:, k] = amp[1] * np.sin(arg)
        vel[:, k] = amp[1] * freq[1] * np.cos(arg)
        acc[:, k] = -freq[1] ** 2 * origin[:, k]
    return rot, origin, vel, acc, omega, alpha


def random_theta(rng_seed, nb=3):
    """Return theta of nb physically realizable random bodies (PSD pseudo-inertia)."""
    rng = np.random.default_rng(rng_seed)
    out = []
    for _ in range(nb):
        pts = rng.normal(size=(5, 3)) * rng.uniform(0.05, 0.5)
        masses = rng.uniform(0.1, 2.0, 5)
        m = masses.sum()
        h = masses @ pts
        sigma = np.einsum('k,ki,kj->ij', masses, pts, pts)
        inertia = np.trace(sigma) * np.eye(3) - sigma
        out.append([m, *h, inertia[0, 0], inertia[0, 1], inertia[1, 1], inertia[0, 2],
                    inertia[1, 2], inertia[2, 2]])
    return np.concatenate(out)


def _derivative(fun, t0, step):
    values = np.array([fun(np.array([t0 + o * step]))[0] for o in FD_OFFSETS])
    return np.tensordot(FD_WEIGHTS, values, axes=(0, 0)) / step


@pytest.mark.parametrize('seed', range(5))
@pytest.mark.parametrize('gravity', [None, (0.3, -9.81, 1.0)])
def test_regressor_is_minus_the_momentum_rate(seed, gravity):
    theta = random_theta(seed)
    point = np.array([0.1, -0.2, 0.3])
    times = np.linspace(0.0, 2.0, 7)

    def p_and_h(t):
        rot, origin, vel, _, omega, _ = random_motion(t, seed + 100)
        return np.concatenate(regressor.momenta(rot, origin, vel, omega, theta, point), -1)

    rot, origin, _, acc, omega, alpha = random_motion(times, seed + 100)
    kin = BodyKinematics(('a', 'b', 'c'), rot, origin, omega, alpha, acc)
    force, moment = regressor.wrench(kin, theta, point, gravity)
    rate = np.array([_derivative(p_and_h, t, FD_STEP) for t in times])
    expected_f, expected_n = -rate[:, :3], -rate[:, 3:]
    if gravity is not None:   # the weight m g at each mass centre, carried by the frame
        g = np.asarray(gravity)
        t = theta.reshape(-1, 10)
        centres = origin + np.einsum('nkij,kj->nki', rot, t[:, 1:4]) / t[:, 0][None, :, None]
        weights = t[:, 0][None, :, None] * g
        expected_f = expected_f + weights.sum(1)
        expected_n = expected_n + np.cross(centres - point, weights).sum(1)
    assert_allclose(force, expected_f, rtol=0, atol=FD_RTOL * np.abs(expected_f).max())
    assert_allclose(moment, expected_n, rtol=0, atol=FD_RTOL * np.abs(expected_n).max())


def test_the_regressor_is_linear_per_body():
    seed = 7
    rot, origin, _, acc, omega, alpha = random_motion(np.linspace(0, 1, 4), seed)
    kin = BodyKinematics(('a', 'b', 'c'), rot, origin, omega, alpha, acc)
    y = regressor.wrench_regressor(kin, (0.0, 0.0, 0.0))
    assert y.shape == (4, 6, 30)
    theta = random_theta(seed)
    total = y @ theta
    parts = sum(y[:, :, 10 * k:10 * k + 10] @ theta[10 * k:10 * k + 10] for k in range(3))
    assert_allclose(total, parts, rtol=1e-14, atol=1e-14 * np.abs(total).max())


def test_rggr_body_kinematics_against_finite_differences_of_its_poses(rggr_rig):
    omega1 = rggr_rig.scene.crank_speed_rad_s
    psi0 = np.array([0.3, 1.7, 4.0])
    kin = rggr_rig.body_kinematics(psi0)

    def poses(psi):
        bodies = rggr_rig.at(psi, outputs=('kinematics',)).bodies
        return bodies.rotation[:, 1:], bodies.origin_m[:, 1:]

    def velocity(psi):
        return np.array([_derivative(lambda y: poses(y)[1], float(psi[0]), FD_STEP)
                         * omega1])

    for i, p in enumerate(psi0):
        rot_d = _derivative(lambda x: poses(x)[0], p, FD_STEP) * omega1
        rot = poses(np.array([p]))[0][0]
        w_hat = rot_d @ np.swapaxes(rot, -1, -2)           # dR/dt R^T = omega^
        omega_fd = np.stack([w_hat[:, 2, 1], w_hat[:, 0, 2], w_hat[:, 1, 0]], -1)
        assert_allclose(omega_fd, kin.omega_rad_s[i], rtol=0,
                        atol=FD_RTOL * np.abs(kin.omega_rad_s).max())
        assert_allclose(rot, kin.rotation[i], rtol=0, atol=1e-15)
        alpha_fd = _derivative(lambda x: rggr_rig.body_kinematics(x).omega_rad_s, p,
                               FD_STEP) * omega1
        assert_allclose(alpha_fd, kin.alpha_rad_s2[i], rtol=0,
                        atol=FD_RTOL * np.abs(kin.alpha_rad_s2).max())
        acc_fd = _derivative(velocity, p, FD_STEP) * omega1
        assert_allclose(poses(np.array([p]))[1][0], kin.origin_m[i], rtol=0, atol=1e-15)
        assert_allclose(acc_fd, kin.accel_origin_m_s2[i], rtol=0,
                        atol=FD_RTOL * np.abs(kin.accel_origin_m_s2).max())


def test_pseudo_inertia_of_a_body_is_psd_and_of_a_non_body_is_not():
    theta = random_theta(3, nb=1)
    assert np.linalg.eigvalsh(regressor.pseudo_inertia(theta)).min() >= 0.0
    rod = regressor.parameters(2.0, (0.5, 0.0, 0.0), np.diag([0.0, 0.1, 0.1]))
    assert np.linalg.eigvalsh(regressor.pseudo_inertia(rod)).min() >= -1e-15
    bad = rod.copy()
    bad[4] += 1.0   # I_xx > I_yy + I_zz: the triangle inequality fails
    assert np.linalg.eigvalsh(regressor.pseudo_inertia(bad)).min() < 0.0


def test_bad_kinematics_is_refused():
    rot = np.zeros((2, 1, 3, 3))
    good = np.zeros((2, 1, 3))
    with pytest.raises(ValueError, match=r'kinematics.omega_rad_s: got shape \(2, 3\)'):
        regressor.wrench_regressor(BodyKinematics(('a',), rot, good, good[:, 0], good, good))
    with pytest.raises(ValueError, match='gravity_m_s2'):
        regressor.wrench_regressor(BodyKinematics(('a',), rot, good, good, good, good),
                                   gravity_m_s2=(0.0, np.nan, 0.0))
    with pytest.raises(TypeError, match='expected BodyKinematics'):
        regressor.wrench_regressor(object())
