"""The ``mech-balance`` command line: help texts, tables, JSON, exit codes."""

import argparse
import json
import os
import subprocess
import sys

from mech_balance import schema as scene
from mech_balance.analysis import cycle as analysis
from mech_balance.balancing import defaults, redistribution
from mech_balance.bench import balancing as bench_balancing
from mech_balance.cli import balance as cli_balance, jsonout, main as cli
import numpy as np
from numpy.testing import assert_allclose
import pytest
import yaml


def _run(*argv):
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join(
        [os.path.dirname(os.path.dirname(os.path.abspath(__file__)))]
        + env.get('PYTHONPATH', '').split(os.pathsep))
    return subprocess.run([sys.executable, '-m', 'mech_balance.cli', *argv], env=env,
                          capture_output=True, text=True, timeout=120)


def test_every_verb_has_help(capsys):
    parser = cli.build_parser()
    verbs = parser._subparsers._group_actions[0].choices
    assert {'analyze', 'scenes', 'bench'} <= set(verbs)
    for verb in verbs:
        with pytest.raises(SystemExit) as exc:
            cli.main([verb, '--help'])
        assert exc.value.code == 0
        out = capsys.readouterr().out
        assert out.startswith(f'usage: mech-balance {verb}'), verb


def test_help_texts_say_what_the_code_does(capsys):
    """record: --case is refused with --counterweights, the timeline the viewer opens."""
    from mech_balance.viz.drawing import DEGREE_TIMELINE
    with pytest.raises(SystemExit):
        cli.main(['record', '--help'])
    text = ' '.join(capsys.readouterr().out.split())
    case_help = text.split('--case {a,b}', 2)[2].split('--cycles')[0].strip()
    assert case_help.startswith('with --balance (planar) only:') and \
        '--counterweights' not in case_help
    assert f'timelines {DEGREE_TIMELINE} ' in text
    assert 'seed 00' not in text and 'conventions.' not in text
    assert cli.main(['record', '--scene', 'hoeken', '--counterweights', 'crank', '--case', 'b',
                     '--out', 'x.rrd']) == cli.EXIT_USAGE
    assert '--case applies with --balance only' in capsys.readouterr().err


def test_option_limits_are_said_without_internal_names(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(['record', '--cycles', '1000', '--out', 'x.rrd'])
    assert exc.value.code == cli.EXIT_USAGE
    err = capsys.readouterr().err
    assert 'expected an integer <= 100 (a fixed limit of mech_balance)' in err
    assert 'conventions' not in err


def test_analyze_normalized_prints_table4_row(capsys):
    assert cli.main(['analyze', '--scene', 'hoeken', '--normalized']) == 0
    out = capsys.readouterr().out
    for text in ('24.78', '24.70', '22.94', '23.05', '15.32', '11.53', '36.79'):
        assert text in out
    assert 'worst loop-closure residual' in out and 'condition number' in out


def test_analyze_json_and_design(capsys):
    x = '-4.8784,0.7227,5.1566,0.5886,5.2843,-1.3781,3.1938,1.7240,-5.1095,8.0046,-0.9951,0.8759'
    assert cli.main(['analyze', '--scene', 'hoeken', '--normalized', '--json',
                     f'--design={x}', '--samples', '180']) == 0
    report = json.loads(capsys.readouterr().out)
    rows = {r['quantity']: r['rms'] for r in report['rows']}
    assert report['samples'] == 180
    assert abs(rows['shaking moment n_sh'] - 3.4903) < 0.02


def _strict_json(text):
    """Parse ``text`` as strict JSON: NaN and Infinity (Python's extensions) are refused."""
    def refuse(token):
        raise ValueError(f'not strict JSON: {token}')
    return json.loads(text, parse_constant=refuse)


def test_json_output_is_strict_with_a_missing_bound(capsys):
    """
    A tie-break stage without a lower bound (paper constraints) is null, not -Infinity.

    The redistribution's tie-break under seed 001's constraints has no finite lower bound
    (free first moments): Python's json wrote ``-Infinity``, which jq and JSON.parse refuse.
    """
    assert cli.main(['balance', '--scene', 'hoeken', '--paper-constraints', '--weights', '1',
                     '0', '--json']) == 0
    report = _strict_json(capsys.readouterr().out)['report']
    stage2 = report['certificate']['stage2']
    assert stage2['lower_bound'] is None
    assert stage2['status'] == 'Solved' and stage2['objective'] > 0.0
    assert jsonout.finite({'a': [float('nan'), 1.0, (float('-inf'),)]}) == \
        {'a': [None, 1.0, [None]]}


@pytest.mark.parametrize('argv, message', [
    (['analyze', '--scene', '/no/such/scene.yaml'], 'does not exist'),
    (['analyze', '--scene', 'hoeken', '--design', '1,2,3'], 'got 3 values, expected 12'),
    (['analyze', '--scene', 'nosuchscene'], 'expected a built-in scene'),
])
def test_bad_input_exits_2_without_traceback(argv, message):
    proc = _run(*argv)
    assert proc.returncode == 2
    assert message in proc.stderr
    assert 'Traceback' not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_bad_scene_field_exits_2(tmp_path):
    path = tmp_path / 'bad.yaml'
    text = open(os.path.join(os.path.dirname(__file__), '..', 'config',
                             'hoeken.yaml')).read()
    path.write_text(text.replace('mass_kg: 0.326', 'mass_kg: -0.326'))
    proc = _run('analyze', '--scene', str(path))
    assert proc.returncode == 2
    assert 'links.crank.mass_kg: got -0.326, expected a number > 0' in proc.stderr
    assert 'Traceback' not in proc.stderr


def test_bad_option_value_exits_2():
    proc = _run('analyze', '--samples', 'many')
    assert proc.returncode == 2
    assert "--samples: got 'many', expected an integer >= 4" in proc.stderr


def test_scenes_lists_builtins(capsys):
    assert cli.main(['scenes']) == 0
    out = capsys.readouterr().out
    for name in ('hoeken', 'slider_crank', 'carpet_scraper', 'rggr'):
        assert name in out


# ----------------------------------------------------------------------------- one error line

USAGE_CASES = ('samples', 'case', 'cycles', 'repeat', 'unknown', 'no verb', 'record out',
               'record suffix', 'balance dir', 'balance suffix', 'rggr design', 'rggr weights',
               'rggr case', 'rggr balance weights', 'yaml')
IN_A_FRESH_PROCESS = ('samples', 'record out', 'balance dir', 'rggr weights', 'yaml')
"""The cases also run as ``python -m mech_balance.cli`` (about 1 s of imports each)."""


def _usage_cases(tmp):
    """Return ``{case: (argv, verb, message)}`` with files under ``tmp``."""
    blocker = tmp / 'a_file'
    blocker.write_text('not a directory')
    bad_yaml = tmp / 'bad.yaml'
    bad_yaml.write_text('name: x\nlinks: [1, 2\nkind: planar\n')
    return {
        'samples': (['analyze', '--samples', '3'], 'analyze',
                    'argument --samples: got 3, expected an integer >= 4'),
        'case': (['balance', '--case', 'c'], 'balance', "argument --case: invalid choice: 'c'"),
        'cycles': (['record', '--cycles', '0', '--out', str(tmp / 'c.rrd')], 'record',
                   'argument --cycles: got 0, expected an integer >= 1'),
        'repeat': (['bench', '--repeat', '0'], 'bench',
                   'argument --repeat: got 0, expected an integer >= 1'),
        'unknown': (['analyze', '--bogus'], 'analyze', 'unrecognized arguments: --bogus'),
        'no verb': ([], None, 'the following arguments are required: COMMAND'),
        'record out': (['record', '--out', str(blocker / 'x.rrd')], 'record',
                       f"--out: got '{blocker / 'x.rrd'}', its directory '{blocker}' cannot "
                       'be created'),
        'record suffix': (['record', '--out', str(tmp / 'x.mp4')], 'record',
                          'expected a file name ending in .rrd'),
        'balance dir': (['balance', '--output', str(tmp / 'none' / 'x.yaml')], 'balance',
                        'expected a file in an existing directory'),
        'balance suffix': (['balance', '--output', str(tmp / 'x.txt')], 'balance',
                           'expected a file name ending in .yaml or .yml'),
        'rggr design': (['analyze', '--scene', 'rggr', '--design=1,2'], 'analyze',
                        '--design applies to planar scenes only'),
        'rggr weights': (['record', '--scene', 'rggr', '--balance', '--weights', '0', '1',
                          '--out', str(tmp / 'r.rrd')], 'record',
                         '--weights applies to planar scenes only'),
        'rggr case': (['record', '--scene', 'rggr', '--balance', '--case', 'b',
                       '--out', str(tmp / 'r.rrd')], 'record',
                      '--case applies to planar scenes only'),
        'rggr balance weights': (['balance', '--scene', 'rggr', '--weights', '1', '0'],
                                 'balance', '--weights: not an option of the method weights'),
        'yaml': (['analyze', '--scene', str(bad_yaml)], 'analyze',
                 "scene bad.yaml: not valid YAML at line 3, column 5: expected ',' or ']', "
                 "but got ':'"),
    }


def _check_one_error_line(case, verb, message, code, out, err):
    prog = 'mech-balance' if verb is None else f'mech-balance {verb}'
    assert code == cli.EXIT_USAGE, (case, err)
    assert out == '', case                          # nothing computed or printed first
    assert len(err.splitlines()) == 1 and err.endswith('\n'), err
    assert err.startswith(f'{prog}: error: ') and message in err, err
    assert 'Traceback' not in err and 'usage:' not in err
    if message.startswith(('argument', 'unrecognized', 'the following')):
        assert err.rstrip().endswith(f'(see {prog} --help)'), err


@pytest.mark.parametrize('case', USAGE_CASES)
def test_usage_error_is_one_line_and_exit_2(case, tmp_path, capsys):
    argv, verb, message = _usage_cases(tmp_path)[case]
    try:
        code = cli.main(argv)
    except SystemExit as exc:                        # argparse: the parser's one line
        code = exc.code
    out, err = capsys.readouterr()
    _check_one_error_line(case, verb, message, code, out, err)


def test_usage_errors_in_fresh_processes(tmp_path):
    """The installed entry point's view: exit status 2, one line, no traceback."""
    cases = _usage_cases(tmp_path)
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join(
        [os.path.dirname(os.path.dirname(os.path.abspath(__file__)))]
        + env.get('PYTHONPATH', '').split(os.pathsep))
    procs = {k: subprocess.Popen([sys.executable, '-m', 'mech_balance.cli', *cases[k][0]],
                                 env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                 text=True)
             for k in IN_A_FRESH_PROCESS}
    for k, proc in procs.items():
        out, err = proc.communicate(timeout=120)
        _check_one_error_line(k, cases[k][1], cases[k][2], proc.returncode, out, err)


def test_os_error_is_one_line_naming_the_path(monkeypatch, capsys):
    def fail(args):
        raise FileNotFoundError(2, 'No such file or directory', '/no/such/dir/x.yaml')
    monkeypatch.setattr(cli, 'cmd_scenes', fail)
    assert cli.main(['scenes']) == cli.EXIT_USAGE
    assert capsys.readouterr().err == \
        'mech-balance scenes: error: /no/such/dir/x.yaml: No such file or directory\n'


def test_key_error_is_a_bug_not_a_usage_error(monkeypatch):
    def fail(args):
        raise KeyError('x')
    monkeypatch.setattr(cli, 'cmd_scenes', fail)
    with pytest.raises(KeyError):
        cli.main(['scenes'])


def test_output_paths_are_checked_before_the_solve(monkeypatch, tmp_path, capsys):
    def solve(*args, **kwargs):
        pytest.fail('solved before the output path was checked')
    monkeypatch.setattr(redistribution, 'optimize', solve)
    blocker = tmp_path / 'a_file'
    blocker.write_text('')
    (tmp_path / 'dir.rrd').mkdir()
    assert cli.main(['balance', '--output', str(tmp_path / 'no' / 'x.yaml')]) == 2
    assert cli.main(['record', '--balance', '--out', str(blocker / 'x.rrd')]) == 2
    assert cli.main(['record', '--balance', '--out', str(tmp_path / 'dir.rrd')]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 3 and all(line.startswith('mech-balance ') for line in err)
    assert '--output' in err[0] and '--out' in err[1] and '--out' in err[2]


def test_writable_path(tmp_path):
    made = cli.writable_path('--out', str(tmp_path / 'a' / 'b' / 'x.rrd'), ('.rrd',),
                             create_parent=True)
    assert made.parent.is_dir() and not made.exists()
    (tmp_path / 'd.rrd').mkdir()
    with pytest.raises(ValueError, match=r"--out: got '.*d\.rrd', a directory"):
        cli.writable_path('--out', str(tmp_path / 'd.rrd'), ('.rrd',))
    with pytest.raises(ValueError, match='--output: .* in an existing directory'):
        cli.writable_path('--output', str(tmp_path / 'none' / 'x.yaml'), ('.yaml',))
    with pytest.raises(ValueError, match=r'expected a file name ending in \.yaml or \.yml'):
        cli.writable_path('--output', str(tmp_path / 'x.yam'), ('.yaml', '.yml'))
    assert not list(tmp_path.glob('.mech-balance-probe-*'))


@pytest.mark.parametrize('argv, message', [
    (['balance', '--analytic', '--weights', '1', '0'],
     '--weights applies to the optimization, not to --analytic'),
    (['balance', '--analytic', '--case', 'b'], '--case applies to the optimization'),
    (['balance', '--mass-factor', '2'], '--mass-factor applies with --analytic only'),
    (['balance', '--scene', 'rggr', '--analytic'], '--analytic applies to planar scenes only'),
    (['record', '--case', 'b', '--out', 'OUT'], '--case applies with --balance only'),
])
def test_ignored_options_are_rejected(argv, message, tmp_path, capsys):
    argv = [str(tmp_path / 'x.rrd') if a == 'OUT' else a for a in argv]
    assert cli.main(argv) == cli.EXIT_USAGE
    err = capsys.readouterr().err
    assert message in err and len(err.splitlines()) == 1


# ----------------------------------------------------------------------------- weights


def test_balance_and_record_share_the_default_weights(monkeypatch, tmp_path, capsys):
    calls = []

    def solve(scene, weights, case, **kwargs):
        calls.append((tuple(weights), case))
        raise ValueError('stop here')
    monkeypatch.setattr(redistribution, 'optimize', solve)
    assert cli.main(['balance']) == 2
    assert cli.main(['record', '--balance', '--out', str(tmp_path / 'x.rrd')]) == 2
    assert cli.main(['balance', '--weights', '1', '0', '--case', 'b']) == 2
    assert cli.main(['record', '--balance', '--weights', '1', '0', '--case', 'b',
                     '--out', str(tmp_path / 'x.rrd')]) == 2
    default = (tuple(defaults.DEFAULT_WEIGHTS), cli_balance.DEFAULT_CASE)
    assert calls == [default, default, ((1.0, 0.0), 'b'), ((1.0, 0.0), 'b')]
    capsys.readouterr()
    w1, w2 = defaults.DEFAULT_WEIGHTS
    for verb in ('balance', 'record'):
        with pytest.raises(SystemExit):
            cli.main([verb, '--help'])
        text = ' '.join(capsys.readouterr().out.split())
        assert '--weights W1 W2' in text and f'(default: {w1:g} {w2:g}' in text, verb
        assert f'(default: {cli_balance.DEFAULT_CASE})' in text, verb
        assert '(default: None)' not in text, verb


# ----------------------------------------------------------------------------- bench


@pytest.mark.parametrize('tables, status', [
    (('a -> PASS', 'b: 1.0 us'), 0), (('a -> PASS', 'b -> FAIL (1.1 s > 1 s)'), 3)])
def test_bench_exits_non_zero_on_a_fail_and_settles_between_sections(tables, status,
                                                                     monkeypatch, capsys):
    """Every section after the first is measured once the machine settled; a FAIL exits 3."""
    from mech_balance.bench import core as bench_core, recording, settle, spatial
    monkeypatch.setattr(bench_core, 'SECTIONS', ('mech_balance.bench.recording:bench_section',
                                                 'mech_balance.bench.spatial:bench_section'))
    monkeypatch.setattr(recording, 'bench_section', lambda args, progress: tables[0])
    monkeypatch.setattr(spatial, 'bench_section', lambda args, progress: tables[1])
    monkeypatch.setattr(settle, 'settle', lambda: '[settled: test]')
    assert cli.main(['bench', '--section', 'recording', '--section', 'spatial']) == status
    out, err = capsys.readouterr()
    assert out.split('\n\n')[-1].startswith('spatial: [settled: test]\n' + tables[1])
    assert 'recording: [settled' not in out    # the first section follows nothing
    assert ('1 target(s) FAILED:\n  b -> FAIL (1.1 s > 1 s)' in err) == bool(status)


def test_settle_waits_for_children_and_says_what_it_found():
    import subprocess
    from mech_balance.bench import settle
    child = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(30)'])
    try:
        assert child.pid in settle.children()
        line = settle.settle(timeout_s=1.5)
        assert line.startswith('[not settled after 1.5 s (1 child processes left')
    finally:
        child.kill()
        child.wait()
    assert child.pid not in settle.children()
    share = settle.busy_share(0.2)
    assert share is None or 0.0 <= share <= 1.0
    assert settle.failures('x -> PASS\ny FAIL: z\nFAILED stage\n') == ['y FAIL: z']


def test_bench_balance_section_honours_repeat():
    def header(repeat):
        args = argparse.Namespace(scene=['slider_crank'], repeat=repeat, samples=90)
        return bench_balancing.bench_section(args, lambda s: None).splitlines()[0]
    assert 'median of 1 optimizations' in header(1)
    capped = header(bench_balancing.BENCH_REPEAT_MAX + 5)
    assert f'median of {bench_balancing.BENCH_REPEAT_MAX} optimizations' in capped
    assert f'--repeat {bench_balancing.BENCH_REPEAT_MAX + 5} capped at' in capped


# ----------------------------------------------------------------------------- analyze, scenes


def _slider_crank(**changes):
    data, _ = scene.load_data('slider_crank')
    for key, value in changes.items():
        data[key] = value
    return data


def test_round_off_bearing_moment_gets_no_row():
    """Gravity on the in-line slider: its guide's moment is ~4e-16 N*m, round-off."""
    sc = scene.from_dict(_slider_crank(gravity_m_s2=[0.0, -9.81]))
    cycle = analysis.run_cycle(analysis.Rig(sc))
    moment = np.max(np.abs(cycle.wrenches.reaction_moment['S']))
    assert 0.0 < moment < analysis.MOMENT_ROUNDOFF_REL * analysis.moment_scale(cycle)
    assert 'bearing S moment' not in [r.quantity for r in analysis.summarize(cycle)]
    data = _slider_crank()
    data['links']['slider']['com_m'] = [0.0, 0.01]   # off the guide: a real moment
    cycle = analysis.run_cycle(analysis.Rig(scene.from_dict(data)))
    rows = {r.quantity: r for r in analysis.summarize(cycle)}
    assert_allclose(rows['bearing S moment'].max_abs,
                    np.max(np.abs(cycle.wrenches.reaction_moment['S'])), rtol=1e-15)
    assert rows['bearing S moment'].max_abs > 0.1


def test_analyze_kinematics_only_says_why_the_table_is_empty(tmp_path, capsys):
    path = tmp_path / 'kin.yaml'
    path.write_text(yaml.safe_dump(_slider_crank(outputs=['kinematics'])))
    assert cli.main(['analyze', '--scene', str(path)]) == 0
    out = capsys.readouterr().out
    assert 'asks for kinematics only' in out and 'outputs key' in out
    assert 'shaking_wrench' in out


def test_analyze_states_crank_speed_and_acceleration(tmp_path, capsys):
    data = _slider_crank()
    data['crank']['acceleration_rad_s2'] = 50.0
    path = tmp_path / 'acc.yaml'
    path.write_text(yaml.safe_dump(data))
    assert cli.main(['analyze', '--scene', str(path)]) == 0
    out = capsys.readouterr().out
    assert 'crank speed 31.4159 rad/s and acceleration 50 rad/s^2 at every angle' in out
    assert 'note: crank.acceleration_rad_s2 is not 0' in out
    assert cli.main(['analyze', '--scene', 'slider_crank']) == 0
    out = capsys.readouterr().out
    assert 'acceleration 0 rad/s^2' in out and 'note:' not in out
    assert max(len(line) for line in out.splitlines()) <= cli.LINE_WIDTH


def test_scenes_wraps_descriptions_at_word_boundaries(capsys):
    assert cli.main(['scenes']) == 0
    lines = capsys.readouterr().out.splitlines()
    assert max(len(line) for line in lines) <= cli.LINE_WIDTH
    text = ' '.join(' '.join(lines).split())
    for name, path in scene.builtin_scenes().items():
        data, _ = scene.load_data(path)
        assert ' '.join(str(data.get('description', '')).split()) in text, name


def test_no_flags_of_the_options_table_turn_their_option_off():
    """``--no-realizable`` / ``--no-clearance`` reach balance() (and the node's false)."""
    from mech_balance.balancing import defaults, options
    parser = cli.build_parser()
    plain = parser.parse_args(['balance'])
    given = parser.parse_args(['balance', '--no-realizable', '--counterweights', 'crank',
                               '--no-clearance', '--disc-side', 'below',
                               '--max-overhang', '0.05'])
    assert options.from_args(plain, 'redistribution')['realizable'] is True
    assert options.from_args(given, 'redistribution')['realizable'] is False
    on, off = (options.from_args(a, 'counterweights') for a in (plain, given))
    assert 'clearance' not in on and 'clearance' not in off   # not a balance() keyword
    assert on['clearance_margin_m'] == defaults.DEFAULT_CLEARANCE_MARGIN_M
    assert on['disc_side'] == 'auto' and on['max_overhang_m'] is None
    assert off['clearance_margin_m'] is None
    assert off['disc_side'] == 'below' and off['max_overhang_m'] == 0.05
    values = {opt.param: options.param_default(opt) for opt in options.OPTIONS if opt.param}
    both = {k: v for k, v in on.items() if options.BY_KEY[k].param}   # not --planes, ...
    assert options.from_params(values, 'counterweights') == both
    values.update({'balance.clearance': False, 'balance.max_overhang': 0.05,
                   'balance.disc_side': 'below'})
    got = options.from_params(values, 'counterweights')
    assert got['clearance_margin_m'] is None and got['max_overhang_m'] == 0.05
    assert got['disc_side'] == 'below'


@pytest.mark.parametrize('argv, reason', [
    (['--clearance-margin', '-0.001'], '--clearance-margin: got -0.001, expected 0 <= value'),
    (['--max-overhang', '0'], '--max-overhang: got 0.0, expected a number of metres > 0'),
    (['--clearance-margin', '0.01', '--no-clearance'], '--clearance-margin: no clearance'),
])
def test_clearance_flags_are_checked_before_the_solve(argv, reason, capsys):
    assert cli.main(['balance', '--counterweights', 'crank', *argv]) == 2
    assert reason in capsys.readouterr().err


def test_no_clear_design_json_is_the_designs_shape_without_a_design(capsys):
    from mech_balance.balancing import result
    assert cli.main(['balance', '--counterweights', 'crank,rocker', '--max-overhang', '0.001',
                     '--json']) == cli_balance.EXIT_NO_CLEAR_DESIGN
    out, err = capsys.readouterr()
    got = json.loads(out)
    assert list(got) == [k for k in result.SCHEMA_KEYS if k in got]   # its keys, its order
    assert got['success'] is False and got['method'] == 'counterweights'
    why = got['report']['clearance_design']
    assert why['status'] == 'none' and 'max overhang 0.001 m' in why['binding_bounds'][0]
    assert 'none given' in err
