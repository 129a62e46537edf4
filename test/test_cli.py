"""The ``mech-balance`` command line: help texts, tables, JSON, exit codes."""

import json
import os
import subprocess
import sys

from mech_balance import cli
import pytest


def _run(*argv):
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join(
        [os.path.dirname(os.path.dirname(os.path.abspath(cli.__file__)))]
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
    text = open(os.path.join(os.path.dirname(cli.__file__), '..', 'config',
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
