"""
The RGGR's command-line reports: the ``analyze`` and ``balance`` tables.

SI values or the paper's dimensionless view (by m_o1, a1 and omega).
"""

import dataclasses
import math

from mech_balance.analysis.report import Report
from mech_balance.balancing import rggr as rggr_balancing
from mech_balance.conventions import cycle_angles, DEFAULT_SAMPLES, normalize_force, \
    normalize_moment, rms
from mech_balance.core.rggr import check_full_rotation, dynamics
from mech_balance.schema.rggr import KIND
import numpy as np


class _View:
    """SI values or the paper's dimensionless view (by m_o1, a1, omega)."""

    def __init__(self, scene, normalized):
        self.normalized = bool(normalized)
        norm = scene.normalization
        self.mass_kg, self.length_m = norm['mass_kg'], norm['length_m']
        self.omega_rad_s = norm['omega_rad_s']

    def units(self):
        if self.normalized:
            return {'mass': 'm_o1', 'length': 'a1', 'inertia': 'm_o1 a1^2',
                    'force': 'm_o1 a1 omega^2', 'moment': 'm_o1 a1^2 omega^2',
                    'torque': 'm_o1 a1^2 omega^2', 'angle': 'deg'}
        return {'mass': 'kg', 'length': 'm', 'inertia': 'kg m^2', 'force': 'N',
                'moment': 'N m', 'torque': 'N m', 'angle': 'deg'}

    def mass(self, x):
        return float(x) / self.mass_kg if self.normalized else float(x)

    def length(self, x):
        x = np.asarray(x, dtype=float)
        out = x / self.length_m if self.normalized else x
        return out.tolist() if out.ndim else float(out)

    def inertia(self, x):
        return float(x) / (self.mass_kg * self.length_m ** 2) if self.normalized else float(x)

    def force(self, x):
        if not self.normalized:
            return np.asarray(x, dtype=float)
        return normalize_force(x, self.mass_kg, self.length_m, self.omega_rad_s)

    def moment(self, x):
        if not self.normalized:
            return np.asarray(x, dtype=float)
        return normalize_moment(x, self.mass_kg, self.length_m, self.omega_rad_s)


METRIC_KEYS = ('shaking_force_rms', 'shaking_force_max', 'shaking_moment_rms',
               'shaking_moment_max', 'driving_torque_rms', 'driving_torque_max')
"""Keys of one row of metrics in the report dicts (units in the report's ``units``)."""


def _metrics(dyn, view):
    force = view.force(dyn.shaking_force_N)
    moment = view.moment(dyn.shaking_moment_Nm)
    torque = view.moment(dyn.driving_torque_Nm)
    return {'shaking_force_rms': float(rms(force)),
            'shaking_force_max': float(np.max(np.linalg.norm(force, axis=1))),
            'shaking_moment_rms': float(rms(moment)),
            'shaking_moment_max': float(np.max(np.linalg.norm(moment, axis=1))),
            'driving_torque_rms': float(rms(torque)),
            'driving_torque_max': float(np.max(np.abs(torque)))}


def _header(scene, command, samples, view):
    return {'kind': KIND, 'command': command, 'scene': scene.name, 'source': scene.source,
            'samples': int(samples), 'normalized': view.normalized, 'units': view.units(),
            'normalization': dict(scene.normalization.items()), 'assembly_branch': scene.branch,
            'crank_speed_rad_s': scene.crank_speed_rad_s}


def analyze_report(scene, samples=DEFAULT_SAMPLES, normalized=False):
    """
    Return the analysis of ``scene`` as a plain dict of floats and lists.

    RMS and max of |shaking force|, |shaking moment| about O and |driving torque| over
    ``samples`` crank angles, per-axis RMS of the force and moment (x, y, z), the output
    angle range and the worst loop residual |BC| - a2.
    """
    view = _View(scene, normalized)
    check_full_rotation(scene)
    dyn = dynamics(scene, cycle_angles(samples))
    force = view.force(dyn.shaking_force_N)
    moment = view.moment(dyn.shaking_moment_Nm)
    phi3_deg = np.degrees(np.unwrap(dyn.kinematics.output_angle_rad))
    report = _header(scene, 'analyze', samples, view)
    report.update({
        'balancing_weights': {'crank': scene.crank_weight is not None,
                              'output': scene.output_weight is not None},
        'metrics': _metrics(dyn, view),
        'shaking_force_rms_xyz': [float(rms(force[:, i])) for i in range(3)],
        'shaking_moment_rms_xyz': [float(rms(moment[:, i])) for i in range(3)],
        'output_angle_range_deg': [float(phi3_deg.min()), float(phi3_deg.max())],
        'loop_residual_max_m': float(np.max(np.abs(dyn.kinematics.loop_residual_m))),
    })
    return report


def balance_report(scene, samples=DEFAULT_SAMPLES, normalized=False, result=None):
    """
    Return the force balancing and shaking-moment optimization of ``scene`` as a plain dict.

    The balancing weights (masses, centres, products, output weight radius, I_b3w, alpha,
    gamma), the optimal J1..J4, a before/after table (unbalanced = links without weights,
    force-balanced = weights with zero products, optimized), the least-squares optimum, the
    worst loop residual and the solve time.
    """
    view = _View(scene, normalized)
    if result is None:
        result = rggr_balancing.balance_scene(scene, samples)
    angles = cycle_angles(samples)
    bare = dataclasses.replace(scene, crank_weight=None, output_weight=None)
    rows = []
    residual = 0.0
    for label, rig in (('unbalanced', bare), ('force-balanced', result.force_balance.scene),
                       ('optimized', result.design.scene)):
        dyn = dynamics(rig, angles)
        residual = max(residual, float(np.max(np.abs(dyn.kinematics.loop_residual_m))))
        rows.append({'rig': label, **_metrics(dyn, view)})
    cw, ow, des = result.design.crank_weight, result.design.output_weight, result.design
    opt = result.optimum
    report = _header(scene, 'balance', samples, view)
    report.update({
        'coupler_mass_fraction': result.force_balance.coupler_mass_fraction,
        'crank_weight': {'mass': view.mass(cw.mass_kg),
                         'centre_uvw': view.length(cw.centre_uvw_m),
                         'product_wu': view.inertia(cw.product_wu_kg_m2),
                         'product_vw': view.inertia(cw.product_vw_kg_m2)},
        'output_weight': {'mass': view.mass(ow.mass_kg),
                          'centre_uvw': view.length(ow.centre_uvw_m),
                          'radius': view.length(des.output_weight_radius_m),
                          'inertia_ww': view.inertia(ow.inertia_ww_kg_m2),
                          'product_wu': view.inertia(ow.product_wu_kg_m2),
                          'product_vw': view.inertia(ow.product_vw_kg_m2),
                          'alpha_deg': math.degrees(des.alpha_rad),
                          'gamma_deg': math.degrees(des.gamma_rad)},
        'inertia_parameters': dict(zip(('I_1wu', 'I_1vw', 'I_3wu', 'I_3vw'),
                                       (view.inertia(x) for x in opt.inertia_parameters_kg_m2))),
        'table': rows,
        'optimum': {'shaking_moment_rms': float(view.moment(opt.moment_rms_optimal_Nm)),
                    'normal_equation_residual': opt.normal_equation_residual,
                    'rank': opt.rank},
        'loop_residual_max_m': residual,
        'solve_time_s': result.solve_time_s,
    })
    return report


def format_report(report):
    """Return an analyze or balance report as a readable fixed-width text table."""
    u = report['units']
    lines = [f"RGGR spatial four-bar '{report['scene']}' ({report['source']}): "
             f"{report['command']}, branch {report['assembly_branch']:+d}, "
             f"crank {report['crank_speed_rad_s']:g} rad/s, {report['samples']} angles"]
    if report['normalized']:
        n = report['normalization']
        lines.append(f"normalized by m_o1 = {n['mass_kg']:g} kg, a1 = {n['length_m']:g} m, "
                     f"omega = {n['omega_rad_s']:g} rad/s")
    lines.append(f"units: force {u['force']}; moment, torque {u['moment']}; "
                 f"mass {u['mass']}; length {u['length']}; inertia {u['inertia']}")
    head = (f"{'rig':<16}{'|f| rms':>12}{'|f| max':>12}{'|n| rms':>12}{'|n| max':>12}"
            f"{'tau rms':>12}{'|tau| max':>12}")
    rows = report['table'] if report['command'] == 'balance' else [
        {'rig': 'as given', **report['metrics']}]
    lines += ['', head, '-' * len(head)]
    for row in rows:
        lines.append(f"{row['rig']:<16}" + ''.join(f'{row[k]:>12.5g}' for k in METRIC_KEYS))
    lines.append('')
    if report['command'] == 'analyze':
        fx, fy, fz = report['shaking_force_rms_xyz']
        nx, ny, nz = report['shaking_moment_rms_xyz']
        lo, hi = report['output_angle_range_deg']
        lines += [f'shaking force RMS (x, y, z):  {fx:12.5g}{fy:12.5g}{fz:12.5g}',
                  f'shaking moment RMS (x, y, z): {nx:12.5g}{ny:12.5g}{nz:12.5g}',
                  f'output angle phi3: {lo:.3f} .. {hi:.3f} deg']
    else:
        cw, ow, j = report['crank_weight'], report['output_weight'], report['inertia_parameters']
        lines += [
            f"coupler mass fraction mu = c2/a2: {report['coupler_mass_fraction']:.6g}",
            f"crank weight:  m_b1 {cw['mass']:10.5g}   (u, v, w)_b1 "
            + ' '.join(f'{x:10.5g}' for x in cw['centre_uvw'])
            + f"   I_b1wu {cw['product_wu']:10.5g}   I_b1vw {cw['product_vw']:10.5g}",
            f"output weight: m_b3 {ow['mass']:10.5g}   (u, v, w)_b3 "
            + ' '.join(f'{x:10.5g}' for x in ow['centre_uvw'])
            + f"   r {ow['radius']:10.5g}   I_b3w {ow['inertia_ww']:10.5g}",
            f"               I_b3wu {ow['product_wu']:10.5g}   I_b3vw {ow['product_vw']:10.5g}"
            f"   alpha {ow['alpha_deg']:8.3f} deg   gamma {ow['gamma_deg']:8.3f} deg",
            'optimal products (links with weights): '
            + '   '.join(f'{k} {v:10.5g}' for k, v in j.items()),
            f"least-squares optimum: |n| rms {report['optimum']['shaking_moment_rms']:.6g}, "
            f"normal-equation residual {report['optimum']['normal_equation_residual']:.2e}, "
            f"rank {report['optimum']['rank']}",
            f"solve time: {report['solve_time_s'] * 1e3:.1f} ms"]
    lines.append(f"worst loop residual |BC| - a2: {report['loop_residual_max_m']:.3e} m")
    return '\n'.join(lines)


def analyze(sc, samples=None, normalized=False, design=None):
    """Return the ``mech-balance analyze`` :class:`~mech_balance.analysis.report.Report`."""
    if design is not None:
        raise ValueError('design: a point-mass design applies to planar scenes only')
    report = analyze_report(sc, samples or DEFAULT_SAMPLES, normalized)
    return Report(format_report(report), report)
