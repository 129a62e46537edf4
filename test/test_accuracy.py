"""
Error against run time (``mech-balance accuracy``): convergence, integrators, Newton, SOCP.

Errors and evaluation counts are deterministic and asserted; run times are only printed
(the rule: timings in bench and accuracy output, never in tests), so the implicit-vs-explicit
comparison is asserted on right-hand-side evaluations at equal error.
"""

import json

from mech_balance.analysis import cycle as analysis
from mech_balance.bench import accuracy
from mech_balance.cli import main as cli
from mech_balance.core import forward as simulate
from mech_balance.core.planar import kinematics
import pytest

STIFF = 'slider_crank_stiff'


@pytest.mark.parametrize('name', ['hoeken', 'slider_crank', 'carpet_scraper'])
def test_rms_error_falls_below_1e_10_by_p_72(name):
    sc, _ = simulate.load(name)
    study = accuracy.rms_convergence(analysis.Rig(sc), repeat=1)
    p = accuracy.first_p_below(study, 1e-10)
    assert p is not None and p <= 72, study['rows']
    errors = [r['max_rel_error'] for r in study['rows']]
    assert errors[0] > 1e-4          # p = 8 is visibly wrong: the study measures something
    assert max(errors[-4:]) < 1e-13  # converged to round-off


def test_stiff_scene_implicit_beats_explicit_at_equal_error():
    sc, drive = simulate.load(STIFF)
    model = simulate.ForwardDynamics(sc, drive)
    study = accuracy.integrator_study(model, duration_s=0.1,
                                      methods=('RK45', 'DOP853', 'Radau'),
                                      rtols={'RK45': (1e-8,), 'DOP853': (1e-8,),
                                             'Radau': (1e-4, 1e-6)})
    assert study['stiffness'].method == 'Radau'
    assert study['reference']['spread'] < 1e-9
    rows = [r for r in study['equal_error'] if r['implicit'].method == 'Radau']
    matched = [r for r in rows if r['explicit'] is not None]
    assert len(matched) == 2
    for r in matched:
        assert r['explicit'].error <= r['implicit'].error
        # stability, not accuracy, limits the explicit step: >= 10x the evaluations
        assert r['nfev_ratio'] >= 10.0, (r['implicit'], r['explicit'])
    for run in study['runs']:
        assert run.error < 1e-4 and run.energy_rel < 1e-2


def test_nonstiff_scene_errors_follow_the_tolerance():
    sc, drive = simulate.load('slider_crank')
    model = simulate.ForwardDynamics(sc, drive)
    study = accuracy.integrator_study(model, methods=('DOP853', 'Radau', 'LSODA'),
                                      rtols=(1e-6, 1e-8, 1e-10))
    assert study['stiffness'].method == 'DOP853'
    assert study['reference']['spread'] < 1e-8
    by_method = {}
    for run in study['runs']:
        by_method.setdefault(run.method, []).append(run)
    for method, runs in by_method.items():
        errors = [r.error for r in runs]
        assert errors[-1] < errors[0], method
        assert errors[-1] < 1e-6, method
        assert all(r.energy_rel < 1e3 * r.rtol for r in runs), method
    # not stiff: the explicit method needs fewer evaluations than Radau at equal error
    dop = by_method['DOP853'][-1]
    radau = [r for r in by_method['Radau'] if r.error <= dop.error]
    assert all(r.nfev > dop.nfev for r in radau)


def test_position_study_reports_residual_iterations_condition():
    sc, _ = simulate.load('hoeken')
    rig = analysis.Rig(sc)
    study = accuracy.position_study(rig)
    assert study['residual_max'] <= kinematics.NEWTON_TOL
    assert study['iterations_max'] <= 2
    assert sum(study['iterations_histogram'].values()) == study['samples']
    cycle = analysis.run_cycle(rig, study['samples'])
    assert study['cond_max'] == pytest.approx(float(cycle.state.cond.max()), rel=1e-12)
    assert len(study['rows']) == 12


def test_balancing_gap_tightens_with_the_solver_tolerance():
    from mech_balance import conic
    saved = conic.SOLVER_TOL
    sc, _ = simulate.load('hoeken')
    study = accuracy.balancing_study(sc, tolerances=(1e-3, 1e-6, 1e-9))
    assert conic.SOLVER_TOL == saved
    assert study['available']
    gaps = [r['gap_rel'] for r in study['rows']]
    assert gaps[0] > gaps[1] > gaps[2]
    assert all(r['status'] == 'Solved' for r in study['rows'])
    # issue 19: each lower bound is a bound, and each gap covers the true suboptimality,
    # against the optimum at the tightest tolerance (itself within its own certified gap)
    tight = study['rows'][-1]
    assert tight['certified']
    for r in study['rows']:
        assert r['lower_bound'] <= r['primal']
        assert r['lower_bound'] <= tight['primal']
        assert r['gap_abs'] >= r['primal'] - tight['primal']
        assert r['lower_bound'] <= tight['lower_bound'] + tight['gap_abs']
    objectives = [r['primal'] for r in study['rows']]
    assert abs(objectives[2] - objectives[1]) <= study['rows'][1]['gap_abs']


@pytest.mark.parametrize('name, duration', [('hoeken', '3.0'), ('slider_crank', '0.1')])
def test_cli_accuracy_prints_every_table(name, duration, capsys):
    # a shorter simulated time than the default two turns keeps the test quick
    assert cli.main(['accuracy', '--scene', name, '--duration', duration]) == 0
    out = capsys.readouterr().out
    for text in ('RMS against crank samples p', 'error < 1e-10 from p =',
                 'forward dynamics:', 'reference:', 'rhs evals', 'at equal error',
                 'position analysis:', 'Newton iterations', 'balancing (weights',
                 'rel. gap'):
        assert text in out, text
    assert 'DOP853' in out and 'Radau' in out and 'RK45' in out and 'BDF' in out


def test_cli_accuracy_json_and_sections(capsys):
    assert cli.main(['accuracy', '--scene', STIFF, '--sections', 'integrators',
                     '--duration', '0.02', '--json']) == 0
    result = json.loads(capsys.readouterr().out)
    assert set(result) == {'scene', 'source', 'integrators'}
    study = result['integrators']
    assert study['stiffness']['method'] == 'Radau'
    assert {r['method'] for r in study['runs']} == set(accuracy.STUDY_METHODS)


def test_cli_accuracy_bad_sections_exit_2(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(['accuracy', '--sections', 'rms,speed'])
    assert exc.value.code == 2
    assert 'expected a comma-separated list from' in capsys.readouterr().err


def test_rggr_scene_has_the_rms_study(capsys):
    assert cli.main(['accuracy', '--scene', 'rggr']) == 0
    out = capsys.readouterr().out
    assert 'RMS against crank samples p' in out
    assert 'integrators: needs the capability accuracy_study, which kind ' in out
    p = int(out.split('error < 1e-10 from p = ')[1].split()[0])
    assert p <= 72
