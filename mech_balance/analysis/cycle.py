"""
Cycle analysis of a rig of any kind: the table of RMS and extreme values, SI or normalized.

:func:`run_cycle` evaluates one revolution, :func:`summarize` makes the table's rows.
"""

from dataclasses import dataclass
import time

from mech_balance.analysis.report import analysis_dict, ANALYSIS_KEYS, Report  # noqa: F401
from mech_balance.analysis.report import NORMALIZED_UNITS, SI_UNITS
from mech_balance.conventions import cycle_angles, rms
from mech_balance.core import equimomental
from mech_balance.core.planar import dynamics, kinematics
from mech_balance.core.planar.rig import linkage_for, PlanarRig as Rig  # noqa: F401
from mech_balance.schema.scene import OUTPUTS, SERIES
import numpy as np

MOMENT_ROUNDOFF_REL = 1e-12
"""A bearing moment below this fraction of :func:`moment_scale` is round-off: no row."""


@dataclass
class Cycle:
    """One revolution: the angles, kinematic state and wrenches, and the time it took."""

    rig: Rig
    psi: np.ndarray
    state: kinematics.KinematicState
    wrenches: dynamics.Wrenches
    seconds: float
    series: dict = None   # the scalar series from the kinematics alone (kinetic energy, ...)
    data: object = None   # the RigData of a rig evaluated through the protocol (else None)


def run_cycle(rig, samples=None, outputs=None):
    """Evaluate one revolution of a rig (or a scene) at ``samples`` equally spaced angles."""
    from mech_balance.core.rig import as_rig
    rig = as_rig(rig)
    samples = rig.scene.samples if samples is None else samples
    psi = cycle_angles(samples, rig.scene.assembly_crank_angle_rad,
                       links=len(rig.scene.links))
    outputs = rig.scene.outputs if outputs is None else outputs
    if not isinstance(rig, Rig):   # every other rig: through the protocol
        t0 = time.perf_counter()
        data = rig.at(psi, outputs=outputs)
        return Cycle(rig, psi, None, None, time.perf_counter() - t0, dict(data.series), data)
    rig.linkage.skeleton  # noqa: B018 - trace the branch outside the timed section
    t0 = time.perf_counter()
    state, wrenches = rig.evaluate(psi, outputs)
    series = rig.series(state, outputs)
    return Cycle(rig, psi, state, wrenches, time.perf_counter() - t0, series)


@dataclass
class Row:
    """One line of the analysis table."""

    quantity: str
    unit: str
    rms: float
    max_abs: float
    kind: str  # 'force' | 'moment' | 'energy' (the row's dimension)


def summarize(cycle, normalized=False):
    """Return the table rows (RMS and max |.|) of a cycle, SI or normalized."""
    rows = []
    w = cycle.wrenches
    norm = cycle.rig.scene.normalization
    if normalized and norm is None:
        raise ValueError(f'--normalized: scene {cycle.rig.scene.name!r} records no '
                         'normalization (mass_kg, length_m, omega_rad_s)')
    if cycle.data is not None:
        from mech_balance.analysis import spatial_report
        return [Row(r['quantity'], r['unit'], r['rms'], r['max_abs'], r['kind'])
                for r in spatial_report.rows(cycle.rig, cycle.data, normalized)]

    def add(name, values, dimension):
        values = np.abs(values)
        if normalized:
            values = getattr(norm, dimension)(values)
        unit = (NORMALIZED_UNITS if normalized else SI_UNITS)[dimension]
        rows.append(Row(name, unit, float(rms(values)), float(np.max(values)), dimension))

    if w is not None:
        if w.reaction_force is not None:
            floor = MOMENT_ROUNDOFF_REL * moment_scale(cycle)
            for name, f in w.reaction_force.items():
                add(f'bearing {name} |f|', f, 'force')
                moment = w.reaction_moment[name]
                if name != cycle.rig.scene.crank_joint and np.max(np.abs(moment)) > floor:
                    add(f'bearing {name} moment', moment, 'moment')
        if w.driving_torque is not None:
            add('driving torque', w.driving_torque, 'moment')
        add('shaking force |f_sh|', w.shaking_force, 'force')
        add('shaking moment n_sh', w.shaking_moment, 'moment')
    for name, values in (cycle.series or {}).items():
        label, dimension = SERIES[name]
        add(label, values, dimension)
    return rows


def moment_scale(cycle):
    """Return the rig's moment scale over a cycle (N*m; 0: kinematics only) for round-off."""
    w = cycle.wrenches
    if w is None:
        return 0.0
    scales = [np.max(np.abs(w.shaking_moment))]
    if w.driving_torque is not None:
        scales.append(np.max(np.abs(w.driving_torque)))
    if w.reaction_force is not None:
        force = max(np.max(np.abs(f)) for f in w.reaction_force.values())
        scales.append(force * cycle.rig.linkage.length_scale)
    return float(max(scales))


def format_table(cycle, rows, normalized=False):
    """Return the analysis table as text."""
    sc = cycle.rig.scene
    st = cycle.state
    lines = [
        f'scene: {sc.name} ({sc.source})',
        f'crank: joint {sc.crank_joint}, {cycle.psi.size} angles per revolution',
        f'crank speed {sc.crank_speed_rad_s:g} rad/s and acceleration '
        f'{sc.crank_acceleration_rad_s2:g} rad/s^2 at every angle',
        'RMS = sqrt(mean(x^2)) over the cycle; units: '
        + ('normalized by m1, a1, omega (Chaudhary & Saha sec. 3.4)' if normalized else 'SI'),
    ]
    if sc.crank_acceleration_rad_s2:
        lines += ['note: crank.acceleration_rad_s2 is not 0: every angle is evaluated at this '
                  'speed with this', 'acceleration (a snapshot, not a run-up; '
                  '`mech-balance simulate` integrates one)']
    lines += [
        '',
        f'{"quantity":<28}{"unit":>14}{"RMS":>14}{"max |.|":>14}',
        '-' * 70,
    ]
    for r in rows:
        lines.append(f'{r.quantity:<28}{r.unit:>14}{r.rms:>14.6g}{r.max_abs:>14.6g}')
    if cycle.wrenches is None:
        more = ', '.join(o for o in OUTPUTS if o != 'kinematics')
        lines += ["(no rows: the scene's outputs key asks for kinematics only; add one of",
                  f'{more} to it for the wrench rows)']
    lines += [
        '-' * 70,
        f'worst loop-closure residual: {np.max(st.residual):.3e} (relative to '
        f'{cycle.rig.linkage.length_scale:g} m)',
        f'worst Jacobian condition number: {np.max(st.cond):.4g}'
        + (f'  (WARNING: near-singular, > {kinematics.COND_WARN:.4g}: the figures may be '
           f'wrong in their last printed digit, error bound 2 kappa^2 x Newton tolerance = '
           f'{2.0 * np.max(st.cond) ** 2 * kinematics.NEWTON_TOL:.1e} relative)'
           if np.max(st.cond) > kinematics.COND_WARN else ''),
        f'Newton iterations per angle: max {int(np.max(st.iterations))}, '
        f'mean {np.mean(st.iterations):.2f}'
        + ('  (positions in closed form: the loops are RRR dyads)'
           if getattr(cycle.rig.linkage, 'dyads', None) is not None else ''),
    ]
    if cycle.wrenches is not None and cycle.wrenches.consistency is not None:
        lines.append(f'reaction recursion consistency: {cycle.wrenches.consistency:.3e} N*m')
    lines.append(f'cycle computed in {cycle.seconds * 1e3:.3f} ms '
                 f'({cycle.seconds * 1e6 / cycle.psi.size:.2f} us per angle), one cold run; warm '
                 'medians: `mech-balance bench`')
    return '\n'.join(lines)


def analyze(sc, samples=None, normalized=False, design=None):
    """Return the ``analyze`` :class:`Report`; ``design``: a seed 001 design applied first."""
    if design is not None:
        sc = equimomental.apply_design(sc, design, normalized=sc.normalization is not None)
    rig = Rig(sc)
    cycle = run_cycle(rig, samples)
    rows = summarize(cycle, normalized)
    data = analysis_dict(
        sc, rig, int(cycle.psi.size), normalized, [r.__dict__ for r in rows],
        float(np.max(cycle.state.residual)), float(np.max(cycle.state.cond)),
        bool(np.max(cycle.state.cond) > kinematics.COND_WARN), kinematics.COND_WARN,
        {'newton_iterations_max': int(np.max(cycle.state.iterations)),
         'reaction_consistency_Nm': None if cycle.wrenches is None else
         cycle.wrenches.consistency})
    return Report(format_table(cycle, rows, normalized), data, list(rig.linkage.warnings))
