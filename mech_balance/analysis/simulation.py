"""The report of a forward-dynamics run (``mech-balance simulate``): time series and figures."""

from dataclasses import dataclass
import math

from mech_balance import schema as scene_mod
from mech_balance.conventions import rms
from mech_balance.core import forward
from mech_balance.core.integrators import DEFAULT_RTOL
from mech_balance.schema import FRAME
import numpy as np

STARTUP_FRACTION = 0.95
"""Start-up time: when the crank speed first reaches this fraction of its steady mean."""
STEADY_TURNS = 2
"""Crank turns at the end of a run over which the steady-state figures are taken."""


@dataclass
class Report:
    """The time series of a simulation and its summary figures (SI)."""

    simulation: forward.Simulation
    t: np.ndarray              # (k,) s
    psi: np.ndarray            # rad
    speed: np.ndarray          # rad/s
    accel: np.ndarray          # rad/s^2
    motor_torque: np.ndarray   # N*m on the input shaft (through the gear)
    driving_effort: np.ndarray  # the rig's driving effort at (psi, psi', psi''): N*m or N
    shaking_force: np.ndarray  # (k, 3) N, frame axes
    shaking_moment: np.ndarray  # (k, 3) N*m about the rig's moment point, incl. the rotor's
    summary: dict


def input_axis(rig):
    """Return the unit ``(3,)`` frame axis the input turns about (planar: z; prismatic: None)."""
    if rig.joint_prismatic[rig.joint_names.index(rig.crank_joint)]:
        return None
    drawing = rig.drawing
    for name, _, direction in drawing.axes:
        if name == rig.crank_joint:
            flip = any(j == name and body == FRAME for j, body, _ in drawing.joints)
            axis = np.asarray(direction, dtype=float)
            return -axis if flip else axis
    return np.array([0.0, 0.0, 1.0]) if drawing.dimension == 2 else None


def report(sim, samples_per_turn=72, max_samples=20000):
    """Return the :class:`Report` of a simulation on a grid of ``samples_per_turn`` per turn."""
    model = sim.model
    t_end = float(sim.t[-1])
    turns = t_end * model.omega_ref / (2.0 * math.pi)
    k = int(min(max(samples_per_turn * turns, 200), max_samples)) + 1
    t = np.linspace(0.0, t_end, k)
    if sim.sol is not None:
        y = sim.sol(t)
    else:
        y = np.array([np.interp(t, sim.t, row) for row in sim.y])
    acc = np.empty(k)
    tau_m = np.empty(k)
    for i in range(k):
        acc[i], tau_m[i] = model.accel(y[:, i])
    rig = model.rig
    data = rig.at(y[0], speed=y[1], accel=acc, outputs=('shaking_wrench', 'driving_torque'))
    effort = data.series[rig.driving_series]
    ci = rig.joint_names.index(rig.crank_joint)
    rate = rig.at(y[0], speed=1.0, accel=0.0, outputs=()).joint_velocity[:, ci]  # dx/dpsi
    generalized = effort * rate
    f = np.array([model.functions.values(p)[0] for p in y[0]]).T
    expected = tau_m - f[3] * y[1] - model.added * acc
    torque_scale = max(np.max(np.abs(generalized)), np.max(np.abs(tau_m)),
                       np.max(np.abs(f[0] * acc)), np.max(np.abs(f[1] * y[1] ** 2)),
                       np.finfo(float).tiny)
    check = float(np.max(np.abs(generalized - expected)))
    spin = model.rotor / model.gear + model.drive.input_inertia_kg_m2   # H = spin psi'
    axis = input_axis(rig)
    moment = data.moment_Nm.copy()
    if axis is not None and spin:
        moment -= spin * acc[:, None] * axis
    tables = model.tables
    summary = {
        'scene': model.scene.name, 'kind': scene_mod.kind_of(rig).name,
        'method': sim.method, 'why': sim.reason,
        'rtol': sim.rtol, 'rhs': model.rhs_kind,
        'table_harmonics': None if tables is None else tables.harmonics,
        'table_error': None if tables is None else tables.error,
        'table_errors': None if tables is None else dict(tables.errors),
        'duration_s': t_end, 'steps': sim.steps, 'nfev': sim.nfev, 'njev': sim.njev,
        'nlu': sim.nlu, 'seconds': sim.seconds,
        'energy_residual_J': sim.energy_residual()[0],
        'energy_residual_rel': sim.energy_residual()[1],
        'inverse_dynamics_check_Nm': check,
        'inverse_dynamics_check_rel': check / torque_scale,
        'rotor_moment_included': bool(axis is not None or not spin),
        # a rig that evaluates no crank acceleration gives its wrench and effort at zero
        'rig_takes_accelerations': bool(np.allclose(data.crank_accel_rad_s2, acc, rtol=1e-12,
                                                    atol=0.0)),
        'worst_condition': float(np.max(data.condition)),
    }
    summary.update(_steady(t, y[0], y[1], tau_m, data.force_N, moment, model))
    return Report(sim, t, y[0], y[1], acc, tau_m, effort, data.force_N, moment, summary)


def _steady(t, psi, speed, tau, force, moment, model):
    """Return start-up time and steady-state figures over the last ``STEADY_TURNS`` turns."""
    out = {}
    travelled = np.abs(psi - psi[0])
    turns_done = travelled[-1] / (2.0 * math.pi)
    if turns_done >= STEADY_TURNS + 0.5:
        window = travelled >= travelled[-1] - STEADY_TURNS * 2.0 * math.pi
        out['steady_window_turns'] = STEADY_TURNS
    else:
        window = t >= 0.5 * t[-1]
        out['steady_window_turns'] = float(
            (travelled[-1] - travelled[window][0]) / (2.0 * math.pi))
    out['steady_window_s'] = [float(t[window][0]), float(t[-1])]
    s = speed[window]
    mean = float(np.mean(s))
    out['speed_mean_rad_s'] = mean
    out['speed_min_rad_s'] = float(np.min(s))
    out['speed_max_rad_s'] = float(np.max(s))
    out['speed_ripple'] = float((np.max(s) - np.min(s)) / abs(mean)) if mean else math.inf
    reached = np.nonzero(np.abs(speed) >= STARTUP_FRACTION * abs(mean))[0]
    out['startup_time_s'] = float(t[reached[0]]) if reached.size and mean else None
    # RMS over the uniform time samples of the steady window (conventions.rms over time, not
    # over p crank angles: in a simulation the crank speed is not constant)
    out['motor_torque_rms_Nm'] = float(rms(tau[window]))
    out['motor_torque_max_Nm'] = float(np.max(np.abs(tau)))
    force, moment = np.linalg.norm(force, axis=1), np.linalg.norm(moment, axis=1)
    out['shaking_force_rms_N'] = float(rms(force[window]))
    out['shaking_force_max_N'] = float(np.max(force))
    out['shaking_moment_rms_Nm'] = float(rms(moment[window]))
    out['shaking_moment_max_Nm'] = float(np.max(moment))
    return out


def format_report(rep, rows=20):
    """Return the simulation report as text: summary, then a time table."""
    s = rep.summary
    model = rep.simulation.model
    d = model.drive
    lines = [f'scene: {s["scene"]} (kind {s["kind"]}, {model.scene.source})']
    if d.motor is None:
        lines.append('drive: no motor - the rig coasts from '
                     f'{model.initial_speed():g} rad/s, no damping unless configured')
    else:
        m = d.motor
        text = (f'drive: DC motor {m.stall_torque_Nm:g} N*m stall, {m.no_load_speed_rad_s:g} '
                f'rad/s no-load, gear {m.gear_ratio:g}, rotor {m.rotor_inertia_kg_m2:g} '
                f'kg*m^2, T_e {m.electrical_time_constant_s:g} s')
        if d.speed_controller is not None:
            c = d.speed_controller
            text += (f'; PI kp {c.kp_per_rad_s:g}/(rad/s), ki {c.ki_per_rad:g}/rad, setpoint '
                     f'{model.setpoint:g} rad/s, |u| <= {c.voltage_limit:g}')
        else:
            text += f'; constant voltage fraction {m.voltage_fraction:g}'
        lines.append(text)
    if d.joint_damping:
        lines.append('joint damping: ' + ', '.join(f'{k} {v:g}' for k, v in
                                                   d.joint_damping.items()))
    if d.input_inertia_kg_m2:
        lines.append(f'input flywheel: {d.input_inertia_kg_m2:g} kg*m^2'
                     + ('' if s['rotor_moment_included'] else
                        ' (its reaction moment is not in the shaking moment: the axis of a '
                        'yoke crank of a prismatic input is not part of the scene)'))
    errors = s['table_errors'] or {}
    if not s['rig_takes_accelerations']:
        lines.append(f'warning: the rig of kind {s["kind"]} evaluates no crank acceleration: the '
                     'motion is exact (inertia from its kinetic energy), but its shaking wrench '
                     'and driving effort below are those at zero crank acceleration')
    lines += [
        f'method: {s["method"]} (rtol {s["rtol"]:g}) - {s["why"]}',
        'right-hand side: ' + (
            'Fourier tables of I, C, tau_G, c_eff, V from the inverse dynamics of the rig, '
            f'{s["table_harmonics"]} harmonics; model error (largest relative deviation from '
            f'the rig at the mid-points) {s["table_error"]:.1e}: '
            + ', '.join(f'{k} {v:.1e}' for k, v in errors.items())
            if s['rhs'] == 'table' else 'the inverse dynamics of the rig at every call'),
        f'cost: {s["steps"]} steps, {s["nfev"]} right-hand-side evaluations, {s["njev"]} '
        f'Jacobians, {s["nlu"]} LU decompositions, {s["seconds"] * 1e3:.1f} ms',
        '',
        f'{"t s":>10}{"psi deg":>12}{"speed rad/s":>14}{"motor N*m":>12}'
        f'{"|f_sh| N":>12}{"|n_sh| N*m":>12}',
        '-' * 72,
    ]
    idx = np.unique(np.linspace(0, rep.t.size - 1, rows).round().astype(int))
    for i in idx:
        lines.append(f'{rep.t[i]:>10.4g}{math.degrees(rep.psi[i]):>12.2f}'
                     f'{rep.speed[i]:>14.6g}{rep.motor_torque[i]:>12.5g}'
                     f'{np.linalg.norm(rep.shaking_force[i]):>12.5g}'
                     f'{np.linalg.norm(rep.shaking_moment[i]):>12.5g}')
    lines += ['-' * 72]
    start = s['startup_time_s']
    lines += [
        f'start-up: {STARTUP_FRACTION:.0%} of the steady mean speed after '
        + (f'{start:.4g} s' if start is not None else 'never'),
        f'steady state (last {s["steady_window_turns"]:.3g} turns, t = '
        f'{s["steady_window_s"][0]:.4g}..{s["steady_window_s"][1]:.4g} s): mean speed '
        f'{s["speed_mean_rad_s"]:.6g} rad/s, ripple (max - min)/mean = {s["speed_ripple"]:.4g}',
        f'motor torque on the input shaft: time-RMS {s["motor_torque_rms_Nm"]:.5g} N*m '
        f'(steady), max {s["motor_torque_max_Nm"]:.5g} N*m',
        f'shaking force: time-RMS {s["shaking_force_rms_N"]:.5g} N (steady), max '
        f'{s["shaking_force_max_N"]:.5g} N; shaking moment: time-RMS '
        f'{s["shaking_moment_rms_Nm"]:.5g} N*m, max {s["shaking_moment_max_Nm"]:.5g} N*m',
        f'energy balance: motor work - dissipation - change of energy = '
        f'{s["energy_residual_J"]:.3e} J ({s["energy_residual_rel"]:.1e} relative)',
        f'inverse-dynamics check: rig driving effort vs motor - damping - rotor: '
        f'{s["inverse_dynamics_check_Nm"]:.3e} N*m ({s["inverse_dynamics_check_rel"]:.1e} '
        'relative)',
        f'worst Jacobian condition number on the path: {s["worst_condition"]:.4g}',
    ]
    return '\n'.join(lines)


def simulate(name_or_scene, duration_s, method='auto', rtol=DEFAULT_RTOL, rhs='table',
             drive=None):
    """
    Integrate a scene or rig of any kind with its drive (or ``drive``); return the report.

    ``name_or_scene``: a built-in name, a path, a scene or a :class:`~mech_balance.core.rig.Rig`.
    """
    sc = forward.load(name_or_scene)[0] if isinstance(name_or_scene, str) else name_or_scene
    model = forward.ForwardDynamics(sc, drive, rhs=rhs)  # a scene or a rig of any kind
    sim = model.simulate(duration_s, method=method, rtol=rtol, dense_output=True)
    return report(sim)
