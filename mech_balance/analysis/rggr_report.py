"""
The RGGR's ``analyze`` report, and the view and table it shares with the ``balance`` report.

SI values or the paper's dimensionless view (by m_o1, a1 and omega).  The balance report
(weights, optimum, before/after table) is :mod:`mech_balance.balancing.rggr_report`'s.
"""

from mech_balance.analysis.report import Report
from mech_balance.conventions import cycle_angles, DEFAULT_SAMPLES, normalize_force, \
    normalize_moment, rms
from mech_balance.core.rggr import check_full_rotation, dynamics
from mech_balance.schema.rggr import KIND
import numpy as np


class ReportView:
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


def report_metrics(dyn, view):
    """Return the RMS and largest |shaking force|, |shaking moment| and |driving torque|."""
    force = view.force(dyn.shaking_force_N)
    moment = view.moment(dyn.shaking_moment_Nm)
    torque = view.moment(dyn.driving_torque_Nm)
    return {'shaking_force_rms': float(rms(force)),
            'shaking_force_max': float(np.max(np.linalg.norm(force, axis=1))),
            'shaking_moment_rms': float(rms(moment)),
            'shaking_moment_max': float(np.max(np.linalg.norm(moment, axis=1))),
            'driving_torque_rms': float(rms(torque)),
            'driving_torque_max': float(np.max(np.abs(torque)))}


def report_header(scene, command, samples, view):
    """Return the keys every report starts with: the scene, the command and the units."""
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
    view = ReportView(scene, normalized)
    check_full_rotation(scene)
    dyn = dynamics(scene, cycle_angles(samples))
    force = view.force(dyn.shaking_force_N)
    moment = view.moment(dyn.shaking_moment_Nm)
    phi3_deg = np.degrees(np.unwrap(dyn.kinematics.output_angle_rad))
    report = report_header(scene, 'analyze', samples, view)
    report.update({
        'balancing_weights': {'crank': scene.crank_weight is not None,
                              'output': scene.output_weight is not None},
        'metrics': report_metrics(dyn, view),
        'shaking_force_rms_xyz': [float(rms(force[:, i])) for i in range(3)],
        'shaking_moment_rms_xyz': [float(rms(moment[:, i])) for i in range(3)],
        'output_angle_range_deg': [float(phi3_deg.min()), float(phi3_deg.max())],
        'loop_residual_max_m': float(np.max(np.abs(dyn.kinematics.loop_residual_m))),
    })
    return report


def format_table(report):
    """
    Return the heading and the metrics table of an analyze or balance report as text lines.

    A balance report's ``table`` rows (one per rig), an analyze report's ``metrics`` as one row.
    """
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
    return lines


def format_report(report):
    """Return an analyze report as a readable fixed-width text table."""
    fx, fy, fz = report['shaking_force_rms_xyz']
    nx, ny, nz = report['shaking_moment_rms_xyz']
    lo, hi = report['output_angle_range_deg']
    lines = format_table(report) + [
        f'shaking force RMS (x, y, z):  {fx:12.5g}{fy:12.5g}{fz:12.5g}',
        f'shaking moment RMS (x, y, z): {nx:12.5g}{ny:12.5g}{nz:12.5g}',
        f'output angle phi3: {lo:.3f} .. {hi:.3f} deg',
        f"worst loop residual |BC| - a2: {report['loop_residual_max_m']:.3e} m"]
    return '\n'.join(lines)


def analyze(sc, samples=None, normalized=False, design=None):
    """Return the ``mech-balance analyze`` :class:`~mech_balance.analysis.report.Report`."""
    if design is not None:
        raise ValueError('design: a point-mass design applies to planar scenes only')
    report = analyze_report(sc, samples or DEFAULT_SAMPLES, normalized)
    return Report(format_report(report), report)
