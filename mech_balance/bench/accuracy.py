"""
Error against run time: the numbers behind ``mech-balance accuracy``.

RMS against samples, integrators, position analysis and the balancing certificate
(docs/simulation.md#the-accuracy-studies).
"""

from dataclasses import dataclass
import math
import statistics

from mech_balance import schema as scene_mod
from mech_balance.analysis import cycle as analysis
from mech_balance.analysis import timing
from mech_balance.analysis.studies import ACCURACY_TURNS, SECTIONS
from mech_balance.conventions import cycle_angles
from mech_balance.core import forward as simulate
from mech_balance.core.planar import kinematics
from mech_balance.core.rig import rig_for
import numpy as np

P_LADDER = (8, 12, 16, 24, 36, 48, 60, 72, 96, 120, 180, 360)
"""Crank samples per revolution of the RMS study."""
P_REFERENCE = 2880
"""Samples of the reference RMS (eight per degree)."""
RMS_TIMING_REPEAT = 5
"""Timed repeats per p (median reported)."""
RTOL_LADDER = (1e-4, 1e-6, 1e-8, 1e-10)
"""Tolerances of the integrator study."""
MAX_RTOL = {'RK45': 1e-8}
"""Tightest tolerance run per method (RK45's fifth order makes 1e-10 needlessly slow)."""
STUDY_METHODS = ('RK45', 'DOP853', 'Radau', 'BDF', 'LSODA')
POSITION_ROWS_DEG = 30.0
"""Spacing of the per-angle rows of the position table."""
BALANCE_TOLERANCES = (1e-3, 1e-5, 1e-7, 1e-9)
"""Conic-solver tolerances of the balancing study (gap and feasibility)."""
BALANCE_WEIGHTS = (0.5, 0.5)
"""Objective weights (shaking force, shaking moment) of the balancing study: one stage."""


def rms_convergence(rig, p_values=P_LADDER, p_ref=P_REFERENCE, normalized=None,
                    repeat=RMS_TIMING_REPEAT):
    """
    Return the RMS study: per p, the worst relative RMS error over the table and the time.

    Rows: ``p``, ``max_rel_error``, ``worst``, ``seconds`` (median per cycle).
    """
    normalized = rig.scene.normalization is not None if normalized is None else normalized
    ref = analysis.summarize(analysis.run_cycle(rig, p_ref), normalized)
    ref_rms = np.array([r.rms for r in ref])
    scale = np.where(ref_rms > 0.0, ref_rms, max(float(np.max(ref_rms)), 1e-300))
    rows = []
    for p in p_values:
        rows_p = analysis.summarize(analysis.run_cycle(rig, p), normalized)
        err = np.abs(np.array([r.rms for r in rows_p]) - ref_rms) / scale
        k = int(np.argmax(err))
        psi = cycle_angles(p, rig.scene.assembly_crank_angle_rad)
        evaluate = getattr(rig, 'evaluate', rig.at)   # a planar rig's own, else the protocol
        seconds = timing.median_seconds(lambda: evaluate(psi), repeat=repeat, warmup=1)
        rows.append({'p': int(p), 'max_rel_error': float(err[k]), 'worst': ref[k].quantity,
                     'seconds': seconds})
    return {'p_reference': p_ref, 'normalized': bool(normalized), 'rows': rows,
            'reference': [{'quantity': r.quantity, 'unit': r.unit, 'rms': r.rms}
                          for r in ref]}


def first_p_below(study, tol):
    """Return the smallest p of the study from which on every error is below ``tol``."""
    rows = study['rows']
    for i, row in enumerate(rows):
        if all(r['max_rel_error'] < tol for r in rows[i:]):
            return row['p']
    return None


@dataclass
class Run:
    """One integration of the study."""

    method: str
    rtol: float
    error: float          # scaled final-state error vs the reference
    energy_rel: float     # relative energy-balance residual
    nfev: int
    njev: int
    nlu: int
    steps: int
    seconds: float

    @property
    def implicit(self):
        """Return whether the method solves implicit equations (LSODA: when stiff)."""
        return self.method not in simulate.EXPLICIT_METHODS

    @property
    def kind(self):
        """Return 'explicit', 'implicit' or 'switching' (LSODA: Adams or BDF)."""
        if not self.implicit:
            return 'explicit'
        return 'switching' if self.method == 'LSODA' else 'implicit'


def state_error(model, y, y_ref):
    """Return max(|d psi| / 1 rad, |d psi'| / omega_ref) between two final states."""
    return float(max(abs(y[0] - y_ref[0]), abs(y[1] - y_ref[1]) / model.omega_ref))


def integrator_study(model, duration_s=None, methods=STUDY_METHODS, rtols=RTOL_LADDER,
                     progress=None):
    """Return the forward-dynamics study; ``rtols``: one ladder or ``{method: ladder}``."""
    if duration_s is None:
        duration_s = ACCURACY_TURNS * 2.0 * math.pi / model.omega_ref
    stiff = model.stiffness()
    rtol_ref = simulate.REFERENCE_RTOL
    ref = model.simulate(duration_s, method=stiff.method, rtol=rtol_ref)
    other = 'LSODA'
    ref2 = model.simulate(duration_s, method=other, rtol=rtol_ref)
    spread = state_error(model, ref2.final, ref.final)
    runs = []
    for method in methods:
        ladder = rtols.get(method, ()) if isinstance(rtols, dict) else rtols
        for rtol in ladder:
            if rtol < MAX_RTOL.get(method, 0.0):
                continue
            if progress:
                progress(f'  {method} rtol {rtol:g} ...')
            sim = model.simulate(duration_s, method=method, rtol=rtol)
            seconds = sim.seconds
            if seconds < 0.2:       # fast runs: median of three
                seconds = statistics.median(
                    [seconds] + [model.simulate(duration_s, method=method,
                                                rtol=rtol).seconds for _ in range(2)])
            runs.append(Run(method, rtol, state_error(model, sim.final, ref.final),
                            sim.energy_residual()[1], sim.nfev, sim.njev, sim.nlu,
                            sim.steps, seconds))
    return {'scene': model.scene.name, 'duration_s': duration_s,
            'turns': duration_s * model.omega_ref / (2.0 * math.pi),
            'stiffness': stiff, 'rhs': model.rhs_kind,
            'reference': {'method': stiff.method, 'rtol': rtol_ref, 'seconds': ref.seconds,
                          'nfev': ref.nfev, 'energy_rel': ref.energy_residual()[1],
                          'check_method': other, 'spread': spread},
            'runs': runs, 'equal_error': equal_error(runs)}


def equal_error(runs):
    """Return, per implicit run, the fastest explicit run at least as accurate (or None)."""
    explicit = [r for r in runs if not r.implicit]
    rows = []
    for imp in (r for r in runs if r.implicit):
        ok = [r for r in explicit if r.error <= imp.error]
        best = min(ok, key=lambda r: r.seconds) if ok else None
        rows.append({'implicit': imp, 'explicit': best,
                     'time_ratio': None if best is None else best.seconds / imp.seconds,
                     'nfev_ratio': None if best is None else best.nfev / imp.nfev})
    return rows


def position_study(rig, samples=None):
    """Return the position-analysis figures of one revolution and per-angle rows."""
    samples = rig.scene.samples if samples is None else samples
    cycle = analysis.run_cycle(rig, samples, outputs=('kinematics',))
    st = cycle.state
    psi_deg = np.degrees(cycle.psi - cycle.psi[0])
    step = max(int(round(POSITION_ROWS_DEG / (360.0 / samples))), 1)
    rows = [{'angle_deg': float(np.degrees(cycle.psi[i]) % 360.0),
             'residual': float(st.residual[i]), 'iterations': int(st.iterations[i]),
             'cond': float(st.cond[i])} for i in range(0, samples, step)]
    iters = np.asarray(st.iterations)
    return {'samples': samples, 'seconds': cycle.seconds,
            'residual_max': float(np.max(st.residual)),
            'residual_mean': float(np.mean(st.residual)),
            'iterations_max': int(np.max(iters)), 'iterations_mean': float(np.mean(iters)),
            'iterations_histogram': {int(k): int(np.sum(iters == k))
                                     for k in np.unique(iters)},
            'cond_max': float(np.max(st.cond)),
            'cond_max_at_deg': float(np.degrees(cycle.psi[int(np.argmax(st.cond))]) % 360.0),
            'skeleton_nodes': int(rig.linkage.skeleton.psi.size),
            'newton_tol': kinematics.NEWTON_TOL, 'rows': rows,
            'first_angle_deg': float(psi_deg[0])}


def balancing_study(scene, tolerances=BALANCE_TOLERANCES, weights=BALANCE_WEIGHTS):
    """Return the certificate gap against solve time, or a note if balancing is unavailable."""
    try:
        from mech_balance import conic
        from mech_balance.balancing import redistribution
    except ImportError as exc:
        return {'available': False, 'note': f'balancing not available ({exc})'}
    rows = []
    for tol in tolerances:
        saved = conic.SOLVER_TOL
        try:
            conic.SOLVER_TOL = tol
            res = redistribution.optimize(scene, weights=weights)
        finally:
            conic.SOLVER_TOL = saved
        c = res.certificate
        rows.append({'tolerance': tol, 'status': c.status, 'iterations': c.iterations,
                     'primal': c.primal, 'lower_bound': c.lower_bound, 'dual': c.lower_bound,
                     'gap_abs': c.gap_abs, 'gap_rel': c.gap_rel, 'certified': c.certified,
                     'conic_seconds': res.conic_time_s, 'solve_seconds': res.solve_time_s})
    return {'available': True, 'weights': list(weights), 'rows': rows,
            'tolerance_via': 'mech_balance.conic.SOLVER_TOL'}


SECTION_CAPABILITY = {'integrators': 'accuracy_study', 'position': 'accuracy_study',
                      'balancing': 'accuracy_study'}
"""The rig capability each study needs beyond the protocol (the RMS study needs none)."""


def run(name_or_path, sections=SECTIONS, duration_s=None, progress=None):
    """Return every requested study of a scene as a dict (RMS only without ``accuracy_study``)."""
    say = progress or (lambda text: None)
    sc = scene_mod.load(name_or_path)
    kind = scene_mod.kind_of(sc)
    capable = 'accuracy_study' in kind.rig_factory().capabilities
    drive = simulate.drive_of(sc) if capable else None
    rig = analysis.Rig(sc) if capable else None
    out = {'scene': sc.name, 'source': sc.source}
    if 'rms' in sections:
        say('RMS against p ...')
        out['rms'] = rms_convergence(rig if capable else rig_for(sc))
    if not capable:
        out['notes'] = [f'{name}: needs the capability accuracy_study, which kind '
                        f'{kind.name} lacks' for name in sections if name != 'rms']
        return out
    if 'integrators' in sections:
        say('forward dynamics ...')
        model = simulate.ForwardDynamics(rig, drive)
        out['integrators'] = integrator_study(model, duration_s, progress=progress)
        out['integrators']['table'] = None if model.tables is None else {
            'harmonics': model.tables.harmonics, 'error': model.tables.error}
    if 'position' in sections:
        say('position analysis ...')
        out['position'] = position_study(rig)
    if 'balancing' in sections:
        say('balancing ...')
        out['balancing'] = balancing_study(sc)
    return out


def format_tables(result):
    """Return the studies as text tables."""
    lines = [f'scene: {result["scene"]} ({result["source"]})']
    for key, table in (('rms', _format_rms), ('integrators', _format_integrators),
                       ('position', _format_position), ('balancing', _format_balancing)):
        if key in result:
            lines += [''] + table(result[key])
    for note in result.get('notes', ()):
        lines += ['', note]
    return '\n'.join(lines)


def _format_rms(study):
    units = 'normalized' if study['normalized'] else 'SI'
    lines = [f'RMS against crank samples p (reference p = {study["p_reference"]}, {units}; '
             'error = max over the table of |RMS_p - RMS_ref| / RMS_ref)',
             f'{"p":>6}{"max rel. error":>16}{"us/cycle":>12}  worst quantity', '-' * 64]
    for r in study['rows']:
        lines.append(f'{r["p"]:>6}{r["max_rel_error"]:>16.3e}{r["seconds"] * 1e6:>12.1f}  '
                     f'{r["worst"]}')
    for tol in (1e-6, 1e-10):
        p = first_p_below(study, tol)
        lines.append(f'error < {tol:g} from p = {p}' if p else
                     f'error < {tol:g}: not reached by p = {study["rows"][-1]["p"]}')
    return lines


def _format_integrators(study):
    st = study['stiffness']
    ref = study['reference']
    lines = [
        f'forward dynamics: {study["duration_s"]:.4g} s ({study["turns"]:.3g} crank turns), '
        f'right-hand side: {study["rhs"]}'
        + (f' ({study["table"]["harmonics"]} harmonics, {study["table"]["error"]:.1e} '
           'from the core)' if study.get('table') else ''),
        f'stiffness: {st.reason}',
        f'reference: {ref["method"]} rtol {ref["rtol"]:g} ({ref["nfev"]} evaluations, '
        f'{ref["seconds"]:.3g} s); {ref["check_method"]} at the same tolerance differs by '
        f'{ref["spread"]:.1e}',
        "error = max(|psi - psi_ref| / rad, |psi' - psi'_ref| / omega_ref) at the end; "
        'energy = |motor work - dissipation - energy change| / energy scale',
        f'{"method":<8}{"kind":<10}{"rtol":>8}{"error":>11}{"energy":>10}{"rhs evals":>11}'
        f'{"jac":>6}{"LU":>7}{"steps":>8}{"seconds":>10}',
        '-' * 89,
    ]
    for r in study['runs']:
        lines.append(f'{r.method:<8}{r.kind:<10}'
                     f'{r.rtol:>8.0e}{r.error:>11.2e}{r.energy_rel:>10.1e}{r.nfev:>11}'
                     f'{r.njev:>6}{r.nlu:>7}{r.steps:>8}{r.seconds:>10.4f}')
    lines += ['', 'at equal error: each implicit (and LSODA) run against the fastest explicit '
              'run that is at least as accurate',
              f'{"implicit":<18}{"error":>10}{"seconds":>10}   {"explicit":<18}{"error":>10}'
              f'{"seconds":>10}{"time x":>9}{"evals x":>9}', '-' * 94]
    for row in study['equal_error']:
        i, e = row['implicit'], row['explicit']
        left = f'{i.method + " " + format(i.rtol, ".0e"):<18}{i.error:>10.2e}{i.seconds:>10.4f}'
        if e is None:
            lines.append(left + '   no explicit run is as accurate')
        else:
            lines.append(left + f'   {e.method + " " + format(e.rtol, ".0e"):<18}'
                         f'{e.error:>10.2e}{e.seconds:>10.4f}{row["time_ratio"]:>9.1f}'
                         f'{row["nfev_ratio"]:>9.1f}')
    return lines


def _format_position(study):
    hist = ', '.join(f'{k}: {v}' for k, v in study['iterations_histogram'].items())
    lines = [f'position analysis: {study["samples"]} angles in {study["seconds"] * 1e3:.2f} ms '
             f'({study["skeleton_nodes"]} branch nodes; Newton tolerance '
             f'{study["newton_tol"]:g} relative)',
             f'residual max {study["residual_max"]:.2e}, mean {study["residual_mean"]:.2e}; '
             f'Newton iterations max {study["iterations_max"]}, mean '
             f'{study["iterations_mean"]:.2f} (histogram {hist}); condition max '
             f'{study["cond_max"]:.4g} at {study["cond_max_at_deg"]:.1f} deg',
             f'{"angle deg":>10}{"residual":>12}{"iterations":>12}{"condition":>12}',
             '-' * 46]
    for r in study['rows']:
        lines.append(f'{r["angle_deg"]:>10.1f}{r["residual"]:>12.2e}{r["iterations"]:>12}'
                     f'{r["cond"]:>12.4g}')
    return lines


def _format_balancing(study):
    if not study.get('available'):
        return [f'balancing: {study["note"]}']
    lines = [f'balancing (weights {study["weights"]}): primal z of the design, safe lower '
             'bound and gap against solve time '
             f'(tolerance set through {study["tolerance_via"]})',
             f'{"tolerance":>10}{"status":>10}{"iter":>6}{"primal":>14}{"lower bound":>14}'
             f'{"gap":>11}{"rel. gap":>11}{"conic ms":>10}{"total ms":>10}', '-' * 96]
    for r in study['rows']:
        lines.append(f'{r["tolerance"]:>10.0e}{r["status"]:>10}{r["iterations"]:>6}'
                     f'{r["primal"]:>14.8g}{r["lower_bound"]:>14.8g}{r["gap_abs"]:>11.2e}'
                     f'{r["gap_rel"]:>11.2e}'
                     f'{r["conic_seconds"] * 1e3:>10.2f}{r["solve_seconds"] * 1e3:>10.2f}')
    return lines


def to_jsonable(result):
    """Return the study with dataclasses turned into dicts (for ``--json``)."""
    def conv(obj):
        if isinstance(obj, (Run, simulate.Stiffness)):
            return {k: conv(v) for k, v in obj.__dict__.items()}
        if isinstance(obj, dict):
            return {str(k): conv(v) for k, v in obj.items()}
        if isinstance(obj, (list, tuple)):
            return [conv(v) for v in obj]
        if isinstance(obj, (np.floating, np.integer)):
            return obj.item()
        return obj
    return conv(result)
