"""
Forward dynamics (seed 000 eq. 39): tables, physics invariants, drives, stiffness, CLI.

The invariants: the tabulated I(psi), C and gravity terms agree with the core and with each
other (c1 = -I'/2, tau_G = -V'); a simulated motion, fed back to the core's inverse
dynamics, needs exactly the motor torque minus damping and rotor inertia; the energy
balance closes; a rig with (numerically) constant inertia follows the closed-form solution
of its linear drive equations.
"""

import copy
import json
import math

from mech_balance import schema as scene
from mech_balance.analysis import simulation
from mech_balance.cli import main as cli
from mech_balance.core import forward as simulate
from mech_balance.core.rig import rig_for
import numpy as np
from numpy.testing import assert_allclose
import pytest
from scipy.linalg import expm

STIFF = 'slider_crank_stiff'


def _scene(name, **changes):
    data, path = scene.load_data(name)
    data = copy.deepcopy(data)
    drive = data.pop('drive', None)
    data.update(changes)
    data['name'] = f'{data["name"]}_{abs(hash(repr(sorted(changes.items())))) % 10 ** 8}'
    return scene.from_dict(data, source=str(path)), drive


# ----------------------------------------------------------------------------- tables


def test_gravity_torque_is_minus_potential_slope():
    sc, _ = _scene('slider_crank', gravity_m_s2=[1.5, -9.81])
    rig = rig_for(sc)
    tables = simulate.RigTables(rig)
    psi = np.linspace(0.0, 2.0 * math.pi, 25)
    f = simulate.rig_functions(rig, psi)
    h = 1e-5
    dv = (np.array([tables.potential(x + h) for x in psi]) -
          np.array([tables.potential(x - h) for x in psi])) / (2 * h)
    scale = np.max(np.abs(f[2]))
    assert scale > 0.1
    assert_allclose(f[2], -dv, rtol=0, atol=1e-8 * scale)
    assert_allclose([tables.values(x)[1][4] for x in psi], -f[2], rtol=0, atol=1e-10 * scale)
    # the direct path's quadrature of V agrees with the series up to a constant
    direct = simulate.ForwardDynamics(sc, {}, rhs='direct').functions
    v_direct = np.array([direct.potential(x) for x in psi])
    v_table = np.array([tables.potential(x) for x in psi])
    assert_allclose(v_direct - v_direct[0], v_table - v_table[0], rtol=0,
                    atol=1e-10 * np.ptp(v_table))
    # and the core's driving torque at rest with gravity is -tau_G (a static balance)
    _, w = rig.evaluate(psi, ('bearing_reactions',), speed=0.0, accel=0.0)
    assert_allclose(w.driving_torque, -f[2], rtol=0, atol=1e-12 * scale)


def test_damping_coefficient_of_slider_and_pins():
    sc, _ = simulate.load('slider_crank')
    rig = rig_for(sc)
    r, rod = 0.04, 0.16
    psi = np.linspace(0.1, 6.2, 23)
    root = np.sqrt(rod * rod - (r * np.sin(psi)) ** 2)
    ds = -r * np.sin(psi) - r * r * np.sin(psi) * np.cos(psi) / root      # slide per crank rad
    dphi_rod = -r * np.cos(psi) / root                                     # rod angle rate
    c = simulate.rig_functions(rig, psi, {'S': 7.0, 'O': 0.3, 'A': 0.2, 'B': 0.1})[3]
    expected = 7.0 * ds ** 2 + 0.3 + 0.2 * (dphi_rod - 1.0) ** 2 + 0.1 * dphi_rod ** 2
    assert_allclose(c, expected, rtol=1e-12)


# ----------------------------------------------------------------------------- physics


def test_forward_solution_satisfies_inverse_dynamics_and_energy_balance():
    sc, drive = simulate.load(STIFF)
    rep = simulation.simulate(STIFF, 0.25)
    s = rep.summary
    assert s['method'] == 'Radau'
    assert s['inverse_dynamics_check_rel'] < 1e-9
    assert s['energy_residual_rel'] < 1e-6
    # the speed loop holds the setpoint
    assert abs(s['speed_mean_rad_s'] - sc.crank_speed_rad_s) < 1e-3 * sc.crank_speed_rad_s
    assert s['speed_ripple'] < 1e-2
    assert 0.0 < s['startup_time_s'] < 0.05


def test_coasting_rig_conserves_energy_with_gravity():
    sc, _ = _scene('hoeken', gravity_m_s2=[0.0, -9.81])
    model = simulate.ForwardDynamics(sc, {'initial_speed_rad_s': 6.0})
    sim = model.simulate(3.0, rtol=1e-10)
    residual, rel = sim.energy_residual()
    assert rel < 1e-8
    assert sim.final[model.i_w] == 0.0 and sim.final[model.i_d] == 0.0
    rep = simulation.report(sim)
    assert rep.summary['inverse_dynamics_check_rel'] < 1e-9


def test_table_and_direct_right_hand_sides_agree():
    sc, drive = simulate.load(STIFF)
    fast = simulate.ForwardDynamics(sc, drive, rhs='table')
    slow = simulate.ForwardDynamics(sc, drive, rhs='direct')
    assert fast.rhs_kind == 'table' and slow.rhs_kind == 'direct'
    y = fast.initial_state()
    y[1] = 20.0
    for psi in (0.3, 2.0, 4.0):
        y[0] = psi
        assert_allclose(fast.rhs(0.0, y), slow.rhs(0.0, y), rtol=1e-10, atol=1e-10)
        assert_allclose(fast.jac(0.0, y), slow.jac(0.0, y), rtol=1e-5, atol=1e-5)
    a = fast.simulate(0.01, method='Radau', rtol=1e-9)
    b = slow.simulate(0.01, method='Radau', rtol=1e-9)
    assert_allclose(a.final[:2], b.final[:2], rtol=1e-8)


def test_analytic_jacobian_matches_finite_differences():
    sc, drive = simulate.load(STIFF)
    d = simulate.drive_from_dict({
        'motor': {'stall_torque_Nm': 3.0, 'no_load_speed_rad_s': 50.0,
                  'electrical_time_constant_s': 1e-3, 'gear_ratio': 2.0,
                  'rotor_inertia_kg_m2': 1e-5},
        'speed_controller': {'kp_per_rad_s': 0.02, 'ki_per_rad': 0.3},
        'joint_damping': {'S': 3.0, 'A': 0.01}}, sc)
    model = simulate.ForwardDynamics(sc, d)
    y = np.array([1.1, 25.0, 0.4, 0.7, 0.0, 0.0])
    jm = model.jac(0.0, y)
    h = 1e-6
    for k in range(y.size):
        e = np.zeros(y.size)
        e[k] = h * max(1.0, abs(y[k]))
        fd = (model.rhs(0.0, y + e) - model.rhs(0.0, y - e)) / (2 * e[k])
        assert_allclose(jm[:, k], fd, rtol=1e-6, atol=1e-6 * np.max(np.abs(jm))), k


def _constant_inertia_scene():
    # Hoeken with the coupler and rocker 1e8 times lighter than the crank and the crank's
    # mass centre on its pivot: I(psi) is constant (to 1e-7; the mass ratio is 1e8).
    data, _ = scene.load_data('hoeken')
    data = copy.deepcopy(data)
    data['name'] = 'hoeken_constant_inertia'
    data['links']['crank']['com_m'] = [0.0, 0.0]
    data['links']['crank']['inertia_origin_kg_m2'] = 2.0e-3
    for name in ('coupler', 'rocker'):
        data['links'][name]['mass_kg'] *= 1e-8
        data['links'][name]['inertia_origin_kg_m2'] *= 1e-8
    return scene.from_dict(data, 'test')


@pytest.mark.parametrize('lag', [0.0, 0.02])
def test_constant_inertia_rig_follows_the_linear_drive_solution(lag):
    sc = _constant_inertia_scene()
    drive = {'motor': {'stall_torque_Nm': 0.05, 'no_load_speed_rad_s': 30.0,
                       'gear_ratio': 2.0, 'rotor_inertia_kg_m2': 1e-4,
                       'electrical_time_constant_s': lag},
             'speed_controller': {'kp_per_rad_s': 0.4, 'ki_per_rad': 2.0,
                                  'setpoint_rad_s': 5.0, 'voltage_limit': 10.0},
             'joint_damping': {'O1': 2e-3}, 'initial_speed_rad_s': 5.0}
    model = simulate.ForwardDynamics(sc, drive)
    f = model.tables.values(0.0)[0]
    i_tot = f[0] + model.rotor
    assert abs(model.tables.values(1.0)[0][0] - f[0]) < 1e-6 * f[0]
    # states (speed, z[, tau_m]); u = kp (w_s - w) + ki z; tau_line = ts (u - N w / w0)
    ts, w0, n, kp, ki, ws, c = 0.05, 30.0, 2.0, 0.4, 2.0, 5.0, 2e-3
    if lag:
        a = np.array([[-c / i_tot, 0.0, n / i_tot],
                      [-1.0, 0.0, 0.0],
                      [ts * (-kp - n / w0) / lag, ts * ki / lag, -1.0 / lag]])
        b = np.array([0.0, ws, ts * kp * ws / lag])
    else:
        a = np.array([[(n * ts * (-kp - n / w0) - c) / i_tot, n * ts * ki / i_tot],
                      [-1.0, 0.0]])
        b = np.array([n * ts * kp * ws / i_tot, ws])
    x0 = np.zeros(a.shape[0])
    x0[0] = 5.0
    # x' = A x + b  =>  x(t) = e^(At) x0 + A^-1 (e^(At) - 1) b
    t = 1.5
    e_at = expm(a * t)
    exact = e_at @ x0 + np.linalg.solve(a, (e_at - np.eye(a.shape[0])) @ b)
    sim = model.simulate(t, rtol=1e-10)
    names = ['speed', 'pi_integral'] + (['motor_torque'] if lag else [])
    got = np.array([sim.final[model.names.index(k)] for k in names])
    assert_allclose(got, exact, rtol=1e-6, atol=1e-7)
    assert sim.energy_residual()[1] < 1e-8


def test_open_loop_motor_settles_on_its_line():
    sc = _constant_inertia_scene()
    model = simulate.ForwardDynamics(sc, {'motor': {'stall_torque_Nm': 0.05,
                                                    'no_load_speed_rad_s': 30.0,
                                                    'voltage_fraction': 0.5},
                                          'joint_damping': {'O1': 1e-3}})
    assert model.initial_speed() == 0.0
    sim = model.simulate(4.0, rtol=1e-10)
    # steady state: ts (u - w / w0) = c w  =>  w = ts u / (c + ts / w0)
    expected = 0.05 * 0.5 / (1e-3 + 0.05 / 30.0)
    i_tot = model.tables.values(0.0)[0][0]
    tau = i_tot / (1e-3 + 0.05 / 30.0)
    assert_allclose(sim.final[1], expected * (1.0 - math.exp(-4.0 / tau)), rtol=1e-7)


# ----------------------------------------------------------------------------- stiffness


def test_stiff_speed_loop_is_detected_and_integrated_implicitly():
    sc, drive = simulate.load(STIFF)
    st = simulate.ForwardDynamics(sc, drive).stiffness()
    assert st.stiff and st.method == 'Radau'
    assert st.ratio > 1e3
    assert 'stiff' in st.reason and 'Radau' in st.reason and 'stability' in st.reason


def test_high_damping_is_detected_as_stiff():
    sc, _ = simulate.load('slider_crank')
    soft = simulate.ForwardDynamics(sc, {'joint_damping': {'O': 1e-4}}).stiffness()
    hard = simulate.ForwardDynamics(sc, {'joint_damping': {'O': 50.0}}).stiffness()
    assert not soft.stiff and soft.method == 'DOP853'
    assert hard.stiff and hard.method == 'Radau'
    # the eigenvalue of a damped rotor: c / I at the stiffest angle
    inertia = simulate.rig_functions(rig_for(sc), np.linspace(0, 2 * np.pi, 721))[0]
    assert_allclose(hard.lambda_max, 50.0 / np.min(inertia), rtol=2e-2)


@pytest.mark.parametrize('name', ['hoeken', 'slider_crank', 'carpet_scraper'])
def test_builtin_rigs_without_drive_are_not_stiff(name):
    sc, drive = simulate.load(name)
    assert not simulate.ForwardDynamics(sc, drive).stiffness().stiff


def test_simulation_is_scale_invariant():
    # lengths x1e-3, masses x1e5, speeds x1e2: torques scale by M L^2 W^2, damping by
    # M L^2 W (revolute) or M W (prismatic), kp by 1/W, time by 1/W
    data, _ = scene.load_data(STIFF)
    L, M, W = 1e-3, 1e5, 1e2
    big = copy.deepcopy(data)
    big['name'] = 'stiff_scaled'
    for pts in [big['frame']['points']] + [lk['points'] for lk in big['links'].values()]:
        for k, v in pts.items():
            pts[k] = [v[0] * L, v[1] * L]
    for lk in big['links'].values():
        lk['mass_kg'] *= M
        lk['com_m'] = [x * L for x in lk['com_m']]
        lk['inertia_com_kg_m2'] *= M * L * L
    big['crank']['speed_rad_s'] *= W
    big['assembly']['joint_displacements_m'] = {
        k: v * L for k, v in big['assembly']['joint_displacements_m'].items()}
    big['normalization'] = {'mass_kg': 0.8 * M, 'length_m': 0.04 * L,
                            'omega_rad_s': data['normalization']['omega_rad_s'] * W}
    d = big['drive']
    d['motor']['stall_torque_Nm'] *= M * L * L * W * W
    d['motor']['no_load_speed_rad_s'] *= W
    d['motor']['rotor_inertia_kg_m2'] *= M * L * L
    d['speed_controller']['kp_per_rad_s'] /= W
    d['speed_controller']['setpoint_rad_s'] *= W
    d['joint_damping'] = {'O': d['joint_damping']['O'] * M * L * L * W,
                          'S': d['joint_damping']['S'] * M * W}
    models = []
    for raw in (data, big):
        raw = copy.deepcopy(raw)
        drive = raw.pop('drive')
        sc = scene.from_dict(raw, 'test')
        models.append(simulate.ForwardDynamics(sc, simulate.drive_from_dict(drive, sc)))
    ref_model, big_model = models
    assert_allclose(big_model.stiffness().ratio, ref_model.stiffness().ratio, rtol=1e-9)
    a = ref_model.simulate(0.1, method='Radau', rtol=1e-10)
    b = big_model.simulate(0.1 / W, method='Radau', rtol=1e-10)
    assert_allclose(b.final[0], a.final[0], rtol=1e-9)
    assert_allclose(b.final[1] / W, a.final[1], rtol=1e-8)
    assert abs(a.steps - b.steps) <= 0.05 * a.steps      # same work in scaled units


# ----------------------------------------------------------------------------- interface


def test_scene_without_drive_coasts_from_its_crank_speed():
    sc, drive = simulate.load('slider_crank')
    assert drive == simulate.Drive()
    model = simulate.ForwardDynamics(sc, drive)
    assert model.initial_speed() == sc.crank_speed_rad_s
    assert model.names == ['psi', 'speed', 'motor_work', 'damping_loss']


def test_scene_carries_its_drive():
    sc, drive = simulate.load(STIFF)
    assert isinstance(sc.drive, dict) and simulate.drive_of(sc) == drive
    assert simulate.ForwardDynamics(sc).drive == drive
    assert simulate.ForwardDynamics(sc, simulate.Drive()).motor is None
    assert drive.motor.stall_torque_Nm == 40.0
    assert drive.joint_damping == {'O': 1e-3, 'S': 50.0}


@pytest.mark.parametrize('method', simulate.METHODS)
def test_every_method_runs(method):
    sc, drive = simulate.load('slider_crank')
    model = simulate.ForwardDynamics(sc, drive)
    sim = model.simulate(0.05, method=method, rtol=1e-7)
    ref = model.simulate(0.05, method='DOP853', rtol=1e-12)
    assert sim.method == method and 'requested' in sim.reason
    assert abs(sim.final[0] - ref.final[0]) < 1e-4


@pytest.mark.parametrize('kwargs, match', [
    ({'method': 'Euler'}, r'method: got .Euler., expected auto or one of'),
    ({'rtol': 0.0}, r'rtol: got 0\.0, expected a number > 0'),
    ({'rtol': 1.0}, r'rtol: got 1\.0, expected 1e-14 <= rtol <= 0\.1'),
    ({'duration_s': -1.0}, r'duration_s: got -1\.0, expected a number > 0'),
    ({'duration_s': float('nan')}, r'duration_s: got nan, expected a finite number'),
])
def test_bad_simulation_arguments(kwargs, match):
    sc, drive = simulate.load('slider_crank')
    model = simulate.ForwardDynamics(sc, drive)
    args = {'duration_s': 0.1, **kwargs}
    with pytest.raises(ValueError, match=match):
        model.simulate(**args)


def test_cli_simulate_stiff_scene(capsys):
    assert cli.main(['simulate', '--scene', STIFF, '--duration', '0.1', '--rows', '5']) == 0
    out = capsys.readouterr().out
    assert 'method: Radau' in out and 'stiff' in out
    assert 'ripple' in out and 'shaking force' in out and 'energy balance' in out
    assert cli.main(['simulate', '--scene', STIFF, '--duration', '0.05', '--json']) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary['method'] == 'Radau' and summary['nfev'] > 0


def test_cli_simulate_bad_duration_exits_2(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(['simulate', '--scene', STIFF, '--duration', '-1'])
    assert exc.value.code == 2
    assert 'expected a finite number > 0' in capsys.readouterr().err
