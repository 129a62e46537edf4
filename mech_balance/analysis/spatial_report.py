"""``mech-balance analyze`` for spatial scenes: RMS and peak of every output over one cycle."""

from mech_balance.analysis.report import analysis_dict, NORMALIZED_UNITS, Report, SI_UNITS
from mech_balance.conventions import cycle_angles, rms
from mech_balance.core.rig import rig_for
from mech_balance.core.spatial.kinematics import COND_WARN
from mech_balance.schema.scene import SERIES
import numpy as np


def rows(rig, data, normalized):
    """
    Return the table rows ``{quantity, unit, rms, max_abs, kind}`` of a rig evaluated by ``at``.

    Shaking force and moment, the scalar series and the bearing loads, SI or ``normalized``.
    """
    norm = rig.scene.normalization if normalized else None
    units = NORMALIZED_UNITS if norm is not None else SI_UNITS
    out = []

    def add(quantity, values, dim):
        v = np.asarray(values, dtype=float)
        v = v if norm is None else getattr(norm, dim)(v)   # energy: in the unit of a moment
        mag = np.abs(v) if v.ndim == 1 else np.linalg.norm(v, axis=1)
        out.append({'quantity': quantity, 'unit': units[dim], 'rms': float(rms(v)),
                    'max_abs': float(np.max(mag)), 'kind': dim})

    if data.force_N is not None:
        add('shaking force |f|', data.force_N, 'force')
        add('shaking moment |n| about P', data.moment_Nm, 'moment')
    for name, (label, dim) in SERIES.items():
        if name in data.series:
            add(label, data.series[name], dim)
    types = {j.name: j.joint_type for j in rig.scene.joints}
    for joint, (force, moment) in (data.reactions or {}).items():
        add(f'bearing force |F| {joint}', force, 'force')
        if types.get(joint) != 'spherical':   # a ball joint carries no moment
            add(f'bearing moment |M| {joint}', moment, 'moment')
    return out


def analyze(sc, samples=None, normalized=False, design=None):
    """Return the ``mech-balance analyze`` :class:`~mech_balance.analysis.report.Report`."""
    if design is not None:
        raise ValueError('design: a point-mass design applies to planar scenes only')
    if normalized and sc.normalization is None:
        raise ValueError(f'--normalized: scene {sc.name!r} records no normalization, '
                         'expected a scene with normalization {mass_kg, length_m, '
                         'omega_rad_s}')
    rig = rig_for(sc)
    samples = sc.samples if samples is None else samples
    psi = cycle_angles(samples, sc.assembly_crank_angle_rad, links=len(sc.links))
    data = rig.at(psi)
    table = rows(rig, data, normalized)
    unique = rig.reactions_unique
    idle = [list(s) for s in getattr(rig.linkage, 'idle_spins', ())]
    out = analysis_dict(sc, rig, int(psi.size), normalized, table,
                        float(np.max(data.residual)), float(np.max(data.condition)),
                        bool(np.any(data.near_singular)), COND_WARN,
                        {'reactions_unique': bool(unique), 'idle_spins': idle})
    width = max([len(r['quantity']) for r in table] + [10])
    lines = [f'scene {sc.name} (spatial): {psi.size} crank angles, crank speed '
             f'{sc.crank_speed_rad_s:g} rad/s' + (' (normalized)' if normalized else '')
             + f'; shaking moment about P, {rig.moment_point}',
             f'{"quantity":<{width}}  {"unit":<12} {"rms":>12} {"max":>12}']
    for r in table:
        lines.append(f'{r["quantity"]:<{width}}  {r["unit"]:<12} {r["rms"]:12.6g} '
                     f'{r["max_abs"]:12.6g}')
    lines.append(f'worst loop residual {out["worst_residual"]:.3e} (relative), worst '
                 f'Jacobian condition {out["worst_condition"]:.4g}'
                 + (' - NEAR-SINGULAR' if out['near_singular'] else ''))
    for name, j1, j2 in idle:
        lines.append(f'idle spin of {name} about the line {j1}-{j2}: fixed by convention '
                     '(slender rod)')
    if not unique:
        lines.append(f'over-constrained ({rig.linkage.redundant} redundant closure rows): '
                     'bearing reactions are not unique; the minimum-norm ones are shown')
    return Report('\n'.join(lines), out, rig.warnings)
