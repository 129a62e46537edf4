"""
Forward dynamics from the Rig contract: every kind, checked against independent physics.

The functions of the ODE (I, c1, tau_G, c_eff) come from a rig's own inverse dynamics
(:func:`mech_balance.core.forward.rig_functions`).  Here they are held against the planar
core's closed forms (seed 000 eqs. 39-43: the formulas the planar forward dynamics used
before), a simulation against an ODE written from those closed forms, spatial coasting
against the rig's own kinetic energy (energy conservation), and every built-in through the
Python API and the command line.
"""

import copy
import json
import math

from mech_balance import schema as scene
from mech_balance.analysis import simulation
from mech_balance.cli import main as cli
from mech_balance.core import forward
from mech_balance.core.planar import dynamics
from mech_balance.core.rig import rig_for
from mech_balance.schema.spatial import spatial_to_dict
import numpy as np
from numpy.testing import assert_allclose
import pytest
from scipy.integrate import solve_ivp

BUILTINS = sorted(scene.builtin_scenes())
PLANAR = [n for n in BUILTINS if scene.load_data(n)[0].get('kind', 'planar') == 'planar']
SPATIAL = [n for n in BUILTINS if n not in PLANAR]
ENERGY_RTOL_FACTOR = 100.0
"""Energy drift of a coasting run per unit rtol and crank turn that is accepted (measured at
most 11 on the built-ins at rtol 1e-10, 3.3e-9 over three turns: DOP853's global error)."""


def _with_gravity(name, g=(1.5, -9.81)):
    data, path = scene.load_data(name)
    data = copy.deepcopy(data)
    data['gravity_m_s2'] = list(g)
    data['name'] = f'{data["name"]}_gravity'
    return scene.from_dict(data, source=str(path))


# ----------------------------------------------------------------------------- the functions


@pytest.mark.parametrize('name', PLANAR)
def test_functions_equal_the_planar_closed_forms(name):
    # the generic path (the rig's driving torque at three speed-acceleration pairs) against
    # seed 000 eqs. 39-43 written out for planar links (dynamics.generalized_inertia, ...)
    sc = _with_gravity(name)
    rig = rig_for(sc)
    psi = np.linspace(0.0, 2.0 * math.pi, 29) + 0.05
    damping = {j: 0.01 * (k + 1) for k, j in enumerate(rig.joint_names)}
    got = forward.rig_functions(rig, psi, damping)
    state, w = rig.evaluate(psi, ('shaking_wrench',), speed=1.0, accel=0.0)
    g = complex(*sc.gravity_m_s2)
    inertia = dynamics.generalized_inertia(state, rig.inertia)
    c1 = dynamics.coriolis_term(state, rig.inertia, w)
    tau_g = dynamics.gravity_power(state, rig.inertia, g)
    rates = rig.at(psi, speed=1.0, accel=0.0, outputs=()).joint_velocity
    c_eff = sum(c * rates[:, rig.joint_names.index(j)] ** 2 for j, c in damping.items())
    scale = np.max(np.abs(inertia))
    assert_allclose(got[0], inertia, rtol=0, atol=1e-12 * scale)
    assert_allclose(got[1], c1, rtol=0, atol=1e-12 * scale)
    assert_allclose(got[2], tau_g, rtol=0, atol=1e-12 * np.max(np.abs(tau_g)))
    assert_allclose(got[3], c_eff, rtol=1e-13)
    # the potential: the integral of the tau_G series, equal to -sum m g.c up to a constant
    tables = forward.RigTables(rig, damping)
    assert tables.ok, tables.errors
    v = dynamics.potential_energy(state, rig.inertia, g)
    table_v = np.array([tables.potential(x) for x in psi])
    assert_allclose(table_v - table_v[0], v - v[0], rtol=0,
                    atol=tables.errors['potential'] * np.ptp(v) + 1e-12 * np.ptp(v))


@pytest.mark.parametrize('name', BUILTINS)
def test_tables_are_checked_and_obey_one_dof_identities(name):
    sc, drive = forward.load(name)
    rig = rig_for(sc)
    tables = forward.RigTables(rig, drive.joint_damping)
    assert tables.ok and tables.error <= forward.TABLE_CHECK_TOL, tables.errors
    # the affine-quadratic form and, where the rig has both, I from the energy
    assert tables.errors['structure'] < 1e-12
    assert tables.errors.get('energy', 0.0) < 1e-12
    psi = np.linspace(0.0, 2.0 * math.pi, 31) + 0.2
    f = np.array([tables.values(x)[0] for x in psi]).T
    slope = np.array([tables.values(x)[1] for x in psi]).T
    scale = np.max(np.abs(f[0]))
    # seed 000 eqs. 40-41 for any one-dof system: C psi' = -(1/2) I'(psi) psi'^2
    assert_allclose(f[1], -0.5 * slope[0], rtol=0, atol=1e-10 * scale)
    # and the rig's effort at any (psi', psi'') is I psi'' - c1 psi'^2 - tau_G
    w, a = 2.7, -13.0
    data = rig.at(psi, speed=w, accel=a, outputs=('driving_torque',))
    rate = rig.at(psi, speed=1.0, accel=0.0, outputs=()).joint_velocity[
        :, rig.joint_names.index(rig.crank_joint)]
    q = data.series[rig.driving_series] * rate
    if np.allclose(data.crank_accel_rad_s2, a):
        assert_allclose(q, f[0] * a - f[1] * w * w - f[2], rtol=0,
                        atol=1e-11 * scale * (abs(a) + w * w))


def test_prismatic_input_needs_an_inertia_at_its_dead_centres():
    sc, drive = forward.load('pssr_skew')
    rig = rig_for(sc)
    assert rig.joint_prismatic[rig.joint_names.index(rig.crank_joint)]
    with pytest.raises(forward.DriveError, match=r'drive\.input_inertia_kg_m2: got 0\.0 .* '
                                                 r'near psi = (0|180) deg'):
        forward.ForwardDynamics(rig, forward.Drive())
    model = forward.ForwardDynamics(rig)
    assert model.added == drive.input_inertia_kg_m2 > 0.0
    inertia = [model.tables.values(x)[0][0] for x in (0.0, math.pi, 0.5 * math.pi)]
    # the slide stands at the dead centres: only the flywheel turns (I = m (ds/dpsi)^2 ...)
    assert abs(inertia[0]) < 1e-12 * inertia[2] and abs(inertia[1]) < 1e-12 * inertia[2]
    rep = simulation.simulate(sc, 0.3, rtol=1e-10)
    s = rep.summary
    assert s['inverse_dynamics_check_rel'] < 1e-10
    assert not s['rotor_moment_included']
    assert rep.driving_effort.shape == rep.t.shape          # N along the guide


# ----------------------------------------------------------------------------- agreement


def test_simulation_agrees_with_the_planar_closed_form_ode():
    # the reference: psi'' from seed 000 eq. 39 with I, C and tau_G evaluated by the planar
    # core's closed forms at every call (no tables, no generic path), same integrator
    sc = _with_gravity('hoeken', (0.0, -9.81))
    rig = rig_for(sc)
    g = complex(*sc.gravity_m_s2)
    c_o1 = 2e-3
    drive = {'initial_speed_rad_s': 6.0, 'joint_damping': {'O1': c_o1}}

    def reference(t, y):
        state, w = rig.evaluate(np.array([y[0]]), ('shaking_wrench',), speed=1.0, accel=0.0)
        inertia = dynamics.generalized_inertia(state, rig.inertia)[0]
        c1 = dynamics.coriolis_term(state, rig.inertia, w)[0]
        tau_g = dynamics.gravity_power(state, rig.inertia, g)[0]
        return [y[1], (c1 * y[1] ** 2 + tau_g - c_o1 * y[1]) / inertia]

    rtol, duration = 1e-11, 1.5
    model = forward.ForwardDynamics(sc, drive)
    sim = model.simulate(duration, method='DOP853', rtol=rtol)
    ref = solve_ivp(reference, (0.0, duration), model.initial_state()[:2], method='DOP853',
                    rtol=rtol, atol=model.atol(rtol)[:2])
    assert ref.success
    assert abs(sim.final[0] - sim.y[0, 0]) > 2.0 * math.pi      # more than a turn
    # within the integrator's tolerance: the two formulations agree better than the same
    # integrator at 100 times the tolerance agrees with itself
    loose = model.simulate(duration, method='DOP853', rtol=100.0 * rtol)
    scale = np.array([1.0, model.omega_ref])
    spread = np.abs(loose.final[:2] - sim.final[:2]) / scale
    diff = np.abs(sim.final[:2] - ref.y[:, -1]) / scale
    assert np.all(diff < spread), (diff, spread)


@pytest.mark.parametrize('name', BUILTINS)
def test_coasting_conserves_the_rigs_own_energy(name):
    # no motor, no damping, no gravity on the built-ins: the rig's kinetic energy (its own
    # output, not the tables) plus the flywheel's stays constant along the run
    sc, drive = forward.load(name)
    rig = rig_for(sc)
    model = forward.ForwardDynamics(rig, {'input_inertia_kg_m2': drive.input_inertia_kg_m2})
    rtol, turns = 1e-10, 3.0
    duration = turns * 2.0 * math.pi / abs(sc.crank_speed_rad_s)
    sim = model.simulate(duration, rtol=rtol, dense_output=True)
    t = np.linspace(0.0, duration, 241)
    y = sim.sol(t)
    data = rig.at(y[0], speed=y[1], accel=0.0, outputs=('kinetic_energy',))
    energy = data.series['kinetic_energy'] + 0.5 * model.added * y[1] ** 2
    drift = np.max(np.abs(energy - energy[0])) / energy[0]
    assert np.ptp(y[1]) > 1e-3 * abs(y[1, 0])          # the speed does vary
    assert drift < ENERGY_RTOL_FACTOR * rtol * turns, drift
    assert sim.energy_residual()[1] < ENERGY_RTOL_FACTOR * rtol * turns


@pytest.mark.parametrize('name', BUILTINS)
def test_cli_simulate_every_builtin(name, capsys):
    sc = scene.load(name)
    turns, rtol = 1.5, 1e-10
    duration = turns * 2.0 * math.pi / abs(sc.crank_speed_rad_s)
    assert cli.main(['simulate', '--scene', name, '--duration', f'{duration:.6g}',
                     '--rtol', f'{rtol:g}', '--json']) == 0
    s = json.loads(capsys.readouterr().out)
    assert s['scene'] == sc.name and s['rhs'] == 'table'
    assert s['table_error'] <= forward.TABLE_CHECK_TOL
    assert s['energy_residual_rel'] < ENERGY_RTOL_FACTOR * rtol * turns
    if s['rig_takes_accelerations']:
        assert s['inverse_dynamics_check_rel'] < 1e-9
    for key in ('shaking_force_rms_N', 'shaking_moment_rms_Nm', 'speed_mean_rad_s'):
        assert math.isfinite(s[key]) and s[key] > 0.0
    assert cli.main(['simulate', '--scene', name, '--duration', f'{duration:.6g}',
                     '--rows', '4']) == 0
    out = capsys.readouterr().out
    assert 'model error' in out and 'energy balance' in out


# ----------------------------------------------------------------------------- spatial drives


def test_spatial_motor_speed_loop_and_damping():
    sc = scene.load('rssr_skew')
    rig = rig_for(sc)
    w_set = sc.crank_speed_rad_s
    drive = {'motor': {'stall_torque_Nm': 5.0, 'no_load_speed_rad_s': 150.0,
                       'rotor_inertia_kg_m2': 2e-5, 'gear_ratio': 2.0},
             'speed_controller': {'kp_per_rad_s': 0.05, 'ki_per_rad': 0.5},
             'joint_damping': {'D': 2e-3, 'B_yaw': 1e-4}}
    model = forward.ForwardDynamics(rig, drive)
    # c_eff = sum c (dq/dpsi)^2 from the joint coordinates' own finite differences
    psi = np.linspace(0.3, 6.0, 7)
    h = 1e-6
    q = [rig.at(psi + s, speed=1.0, accel=0.0, outputs=()).joint_position for s in (-h, h)]
    slope = (q[1] - q[0]) / (2.0 * h)
    expected = sum(c * slope[:, rig.joint_names.index(j)] ** 2
                   for j, c in drive['joint_damping'].items())
    got = np.array([model.tables.values(x)[0][3] for x in psi])
    assert_allclose(got, expected, rtol=1e-7)
    rep = simulation.simulate(sc, 0.6, rtol=1e-9, drive=drive)
    s = rep.summary
    assert s['energy_residual_rel'] < 1e-7
    assert s['inverse_dynamics_check_rel'] < 1e-10
    assert abs(s['speed_mean_rad_s'] - w_set) < 2e-2 * w_set
    # the rotor turns about the crank's axis: its reaction is in the shaking moment
    assert s['rotor_moment_included']
    axis = np.array(next(j for j in sc.joints if j.name == sc.crank_joint).axis)
    assert_allclose(simulation.input_axis(rig), axis / np.linalg.norm(axis), rtol=1e-15)
    data = rig.at(rep.psi, speed=rep.speed, accel=rep.accel, outputs=('shaking_wrench',))
    spin = 2.0 * 2e-5 * rep.accel              # N J_r psi'' about the axis
    assert_allclose(rep.shaking_moment - data.moment_Nm,
                    -spin[:, None] * simulation.input_axis(rig), rtol=0, atol=1e-12)


def test_spatial_drive_is_read_written_and_checked():
    data, path = scene.load_data('rssr_skew')
    data = copy.deepcopy(data)
    data['drive'] = {'input_inertia_kg_m2': 1e-4, 'joint_damping': {'C_pitch': 1e-5}}
    sc = scene.from_dict(data, source=str(path))
    assert forward.drive_of(sc).input_inertia_kg_m2 == 1e-4
    again = scene.from_dict(spatial_to_dict(sc), source=str(path))
    assert again.drive == sc.drive
    data['drive'] = {'joint_damping': {'C': 1e-5}}
    with pytest.raises(forward.DriveError, match=r'drive\.joint_damping\.C: no such joint, '
                                                 r'expected one of A, B_yaw'):
        forward.ForwardDynamics(scene.from_dict(data, source=str(path)))
    data['drive'] = {'input_inertia_kg_m2': -1.0}
    with pytest.raises(ValueError, match=r'drive\.input_inertia_kg_m2: got -1\.0, expected '
                                         r'a number >= 0'):
        scene.from_dict(data, source=str(path))


# ----------------------------------------------------------------------------- the contract


class _Limited:
    """A rig that hides capabilities or drops the crank acceleration (contract variants)."""

    def __init__(self, rig, drop=(), no_accel=False):
        self._rig, self.no_accel = rig, no_accel
        self.capabilities = rig.capabilities - set(drop)

    def __getattr__(self, name):
        return getattr(self._rig, name)

    def at(self, psi, speed=None, accel=None, outputs=None):
        return self._rig.at(psi, speed, 0.0 if self.no_accel else accel, outputs)


def test_a_rig_without_inverse_dynamics_is_refused_in_one_line():
    rig = _Limited(rig_for(scene.load('rssr_skew')), drop={'driving_torque'})
    with pytest.raises(ValueError, match=r"^simulate: rig 'rssr_skew' of kind 'spatial' "
                                         r'lacks the capability driving_torque'):
        forward.ForwardDynamics(rig)


def test_a_rig_without_accelerations_takes_its_inertia_from_the_energy():
    real = rig_for(scene.load('spatial_two_loop'))
    blind = _Limited(real, no_accel=True)
    psi = np.linspace(0.0, 6.0, 13)
    assert_allclose(forward.rig_functions(blind, psi), forward.rig_functions(real, psi),
                    rtol=1e-12, atol=1e-15)
    rep = simulation.simulate(blind, 0.05, rtol=1e-10)
    ref = simulation.simulate(real, 0.05, rtol=1e-10)
    assert_allclose(rep.simulation.final[:2], ref.simulation.final[:2], rtol=1e-9)
    assert not rep.summary['rig_takes_accelerations'] and ref.summary['rig_takes_accelerations']
    with pytest.raises(ValueError, match='evaluates no crank acceleration and lacks the '
                                         'capability kinetic_energy'):
        forward.ForwardDynamics(_Limited(real, drop={'kinetic_energy'}, no_accel=True))


@pytest.mark.parametrize('name', ['rssr_skew', 'pssr_skew'])
def test_table_and_direct_right_hand_sides_agree_on_spatial_rigs(name):
    sc, drive = forward.load(name)
    d = {'input_inertia_kg_m2': drive.input_inertia_kg_m2,
         'motor': {'stall_torque_Nm': 2.0, 'no_load_speed_rad_s': 80.0,
                   'rotor_inertia_kg_m2': 1e-5},
         'speed_controller': {'kp_per_rad_s': 0.05, 'ki_per_rad': 0.5}}
    fast = forward.ForwardDynamics(sc, d, rhs='table')
    slow = forward.ForwardDynamics(sc, d, rhs='direct')
    assert fast.rhs_kind == 'table' and slow.rhs_kind == 'direct'
    y = fast.initial_state()
    y[1] = 0.8 * sc.crank_speed_rad_s
    for psi in (0.3, 2.0, 4.0):
        y[0] = psi
        assert_allclose(fast.rhs(0.0, y), slow.rhs(0.0, y), rtol=1e-10, atol=1e-10)
        assert_allclose(fast.jac(0.0, y), slow.jac(0.0, y), rtol=1e-5, atol=1e-5)
    duration = 0.3 * 2.0 * math.pi / abs(sc.crank_speed_rad_s)
    a = fast.simulate(duration, rtol=1e-10)
    b = slow.simulate(duration, rtol=1e-10)
    assert_allclose(a.final[:2], b.final[:2], rtol=1e-8)
