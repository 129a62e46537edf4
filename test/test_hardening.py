"""
Regression tests of issue 12, one or more per class of failure (loaders, files, CLI).

class 1: input that killed the node or gave a traceback (deep nesting, aliases, sizes) is
refused by the one YAML reader (mech_balance.schema.safe_yaml) with an error naming the limit;
class 2: work is bounded (samples, links x samples, cycles, rows) before it starts;
class 3: every write is atomic (mech_balance.atomic): a write error or SIGKILL leaves an
existing target byte-identical; class 7: silently accepted input is refused (duplicate
keys, --design magnitudes, fixed_links, frame_id); class 8: errors name the file or option.
The node's own callbacks (classes 1 node side, 4, 5, 6, 9) are tested in test_node.py.
"""

import os
from pathlib import Path
import resource
import signal
import subprocess
import sys
import textwrap
import time

from mech_balance import atomic, conventions
from mech_balance import schema as scene
from mech_balance.balancing import checks, redistribution
from mech_balance.cli import main as cli
from mech_balance.core import equimomental
from mech_balance.ros import params
from mech_balance.schema import safe_yaml
from mech_balance.viz import recording
import pytest
import yaml

ROOT = Path(__file__).resolve().parent.parent
HOEKEN_TEXT = (ROOT / 'config' / 'hoeken.yaml').read_text(encoding='utf-8')
ORIGINAL_BYTES = b'# a good file that must survive\n' + b'x' * 5000 + b'\n'
KILL_POLL_S = 0.001
"""How often the SIGKILL test looks for the recording's temporary file."""
KILL_DEADLINE_S = 120.0
"""The SIGKILL test kills the recording by then if it never saw the temporary file."""


def _env():
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join([str(ROOT)] + env.get('PYTHONPATH', '').split(
        os.pathsep))
    return env


def _cli(*argv, limit_bytes=None, **kwargs):
    """Run ``mech-balance ARGV`` in a fresh process (optionally under RLIMIT_FSIZE)."""
    def limit():
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))
    return subprocess.run([sys.executable, '-m', 'mech_balance.cli.main', *map(str, argv)],
                          env=_env(), capture_output=True, text=True, timeout=300,
                          preexec_fn=limit if limit_bytes else None, **kwargs)


def _partials(directory):
    return sorted(p.name for p in Path(directory).iterdir() if atomic.PARTIAL_MARK in p.name)


def _laughs(levels=9):
    lines = ['lol0: &l0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]']
    lines += [f'lol{k}: &l{k} [' + ', '.join([f'*l{k - 1}'] * 9) + ']'
              for k in range(1, levels)]
    return 'notes:\n' + '\n'.join('  ' + line for line in lines) + '\n'


# ------------------------------------------------------------------------------ class 1


def test_class1_deep_nesting_refused_by_loader(tmp_path):
    path = tmp_path / 'deep.yaml'
    path.write_text(HOEKEN_TEXT + 'notes: ' + '[' * 5000 + ']' * 5000 + '\n')
    with pytest.raises(scene.SceneError, match=r'^scene deep\.yaml: nesting deeper than 64 '
                                               r'levels \(a fixed limit\) at line'):
        scene.load(path)
    # the node's parameter text goes through the same reader: a ValueError, no recursion
    with pytest.raises(ValueError, match=r'^balance\.mass_bounds: nesting deeper than 64'):
        params.check('balance.mass_bounds', '[' * 5000 + ']' * 5000)
    # exactly the limit is read; one more level is refused
    assert safe_yaml.loads('[' * safe_yaml.MAX_DEPTH + ']' * safe_yaml.MAX_DEPTH) == \
        safe_yaml.loads('[' * safe_yaml.MAX_DEPTH + ']' * safe_yaml.MAX_DEPTH)
    with pytest.raises(safe_yaml.YamlError, match=r'levels \(a fixed limit\)'):
        safe_yaml.loads('[' * (safe_yaml.MAX_DEPTH + 1) + ']' * (safe_yaml.MAX_DEPTH + 1))


def test_class1_depth_counts_through_aliases():
    # 40 + 40 levels: each anchor is shallow, the expanded value is 80 deep
    text = 'a: &a ' + '[' * 40 + ']' * 40 + '\nb: ' + '[' * 40 + '*a' + ']' * 40 + '\n'
    with pytest.raises(safe_yaml.YamlError, match='nesting deeper than 64 levels through '
                                                  'aliases'):
        safe_yaml.loads(text)


def test_class1_billion_laughs_refused_for_every_verb(tmp_path, capsys):
    path = tmp_path / 'laughs.yaml'
    path.write_text(HOEKEN_TEXT + _laughs())
    with pytest.raises(scene.SceneError, match=r'more than 100000 nodes with its aliases '
                                               r'expanded \(a fixed limit'):
        scene.load(path)
    out = tmp_path / 'out.yaml'
    for argv in (['analyze'], ['balance', '--output', str(out)], ['simulate', '--duration',
                                                                  '0.1']):
        assert cli.main([*argv, '--scene', str(path)]) == 2
        assert '(a fixed limit; a "billion laughs" document?)' in capsys.readouterr().err
    assert not out.exists()
    # a few legal aliases are read, and expand as YAML says
    assert safe_yaml.loads('a: &p [1.0, 2.0]\nb: *p\n') == {'a': [1.0, 2.0], 'b': [1.0, 2.0]}


def test_class1_alias_count_recursion_digits_and_size(tmp_path):
    many = 'a: &a 1\nb: [' + ', '.join(['*a'] * (safe_yaml.MAX_ALIASES + 1)) + ']\n'
    with pytest.raises(safe_yaml.YamlError, match=r'more than 1000 aliases'):
        safe_yaml.loads(many)
    with pytest.raises(safe_yaml.YamlError, match='recursive alias'):
        safe_yaml.loads('a: &r [1, *r]\n')
    with pytest.raises(safe_yaml.YamlError, match=r'an integer of 5000 characters, expected '
                                                  r'at most 32 \(a fixed limit\)'):
        safe_yaml.loads('samples: ' + '9' * 5000)
    assert safe_yaml.loads('n: ' + '9' * safe_yaml.MAX_INT_DIGITS)['n'] == \
        int('9' * safe_yaml.MAX_INT_DIGITS)
    big = tmp_path / 'big.yaml'
    big.write_bytes(HOEKEN_TEXT.encode() + b'#' * safe_yaml.MAX_BYTES)
    with pytest.raises(scene.SceneError, match=r"file '.*big\.yaml' has \d+ bytes, expected "
                                               r'at most 1048576 \(a fixed limit\)'):
        scene.load(big)


def test_class1_links_and_joints_counts_are_bounded():
    data = scene.load_data('hoeken')[0]
    crank = data['links']['crank']
    many = dict(data, links={f'l{k}': crank for k in range(conventions.MAX_LINKS + 1)})
    with pytest.raises(scene.SceneError, match=r'^links: got 65 moving links, expected at most '
                                               r'64 \(a fixed limit of mech_balance\)$'):
        scene.from_dict(many)
    joint = data['joints']['A']
    many = dict(data, joints={f'j{k}': joint for k in range(conventions.MAX_JOINTS + 1)})
    with pytest.raises(scene.SceneError, match=r'^joints: got 129 joints, expected at most 128'):
        scene.from_dict(many)
    points = {f'P{k}': [0.001 * k, 0.0] for k in range(conventions.MAX_POINTS + 1)}
    many = dict(data, links=dict(data['links'], crank=dict(crank, points=points)))
    with pytest.raises(scene.SceneError, match=r'^links\.crank\.points: got 65 points'):
        scene.from_dict(many)


# ------------------------------------------------------------------------------ class 2


def test_class2_scene_samples_are_bounded(tmp_path):
    path = tmp_path / 'many.yaml'
    path.write_text(HOEKEN_TEXT.replace('samples: 360', 'samples: 5000000'))
    assert 'samples: 5000000' in path.read_text()
    with pytest.raises(scene.SceneError, match=r'^samples: got 5000000, expected at most '
                                               r'100000 .*\(a fixed limit of mech_balance\)$'):
        scene.load(path)
    # the links x samples work bound, checked by every cycle grid
    with pytest.raises(ValueError, match=r'^samples: got 100000 crank angles x 20 moving '
                                         r'links = 2000000, expected at most 1000000'):
        conventions.cycle_angles(100000, links=20)
    with pytest.raises(ValueError, match=r'^samples: got inf, expected an integer$'):
        conventions.check_samples(float('inf'))
    assert conventions.cycle_angles(conventions.MAX_SAMPLES).size == conventions.MAX_SAMPLES


@pytest.mark.parametrize('argv, option, limit', [
    (['analyze', '--samples', '1000000000'], '--samples', conventions.MAX_SAMPLES),
    (['balance', '--samples', '1000000000'], '--samples', conventions.MAX_SAMPLES),
    (['record', '--cycles', '1000000000', '--out', 'x.rrd'], '--cycles',
     conventions.MAX_CYCLES),
    (['simulate', '--duration', '0.1', '--rows', '1000000000'], '--rows',
     conventions.MAX_TABLE_ROWS),
    (['bench', '--repeat', '1000000000'], '--repeat', conventions.MAX_REPEAT),
])
def test_class2_cli_work_options_are_bounded(argv, option, limit, capsys, tmp_path):
    argv = [str(tmp_path / a) if a == 'x.rrd' else a for a in argv]
    with pytest.raises(SystemExit) as exc:
        cli.main(argv)
    assert exc.value.code == cli.EXIT_USAGE
    err = capsys.readouterr().err
    assert f'argument {option}: got 1000000000, expected an integer <= {limit} (a fixed ' \
        'limit of mech_balance)' in err
    assert 'conventions' not in err   # the limit is said, not its internal name
    assert len(err.splitlines()) == 1


def test_class2_record_and_simulate_bounds_in_the_core(tmp_path, capsys):
    sc = scene.load('hoeken')
    with pytest.raises(ValueError, match=r'^cycles: got 101, expected at most 100 crank turns '
                                         r'\(a fixed limit of mech_balance\)$'):
        recording.record(tmp_path / 'x.rrd', sc, cycles=conventions.MAX_CYCLES + 1)
    assert not (tmp_path / 'x.rrd').exists() and not _partials(tmp_path)
    assert cli.main(['simulate', '--duration', '1e9']) == cli.EXIT_USAGE
    assert 'expected at most 100000 turns' in capsys.readouterr().err  # MAX_SIMULATED_TURNS


# ------------------------------------------------------------------------------ class 3


def test_class3_atomic_helpers_replace_or_keep(tmp_path):
    target = tmp_path / 'good.yaml'
    target.write_bytes(ORIGINAL_BYTES)
    os.chmod(target, 0o640)
    with pytest.raises(RuntimeError):
        with atomic.atomic_path(target) as tmp:
            assert tmp.parent == tmp_path and tmp.name.startswith('.good.yaml.partial-')
            tmp.write_bytes(b'half')
            raise RuntimeError('failed midway')
    assert target.read_bytes() == ORIGINAL_BYTES and not _partials(tmp_path)
    atomic.write_text_atomic(target, 'complete: true\n')
    assert target.read_text() == 'complete: true\n' and not _partials(tmp_path)
    assert os.stat(target).st_mode & 0o777 == 0o640          # the target's permissions kept
    fresh = tmp_path / 'new.bin'
    atomic.write_bytes_atomic(fresh, b'\x00\x01')
    assert fresh.read_bytes() == b'\x00\x01'


def test_class3_atomic_balance_output_write_error(tmp_path):
    target = tmp_path / 'good.yaml'
    target.write_bytes(ORIGINAL_BYTES)
    # the balanced scene is ~3 kB: RLIMIT_FSIZE of 1 kB fails its write (EFBIG)
    proc = _cli('balance', '--output', target, limit_bytes=1024)
    assert proc.returncode == cli.EXIT_USAGE, proc.stderr
    assert proc.stderr.strip() == f'mech-balance balance: error: {target}: File too large'
    assert target.read_bytes() == ORIGINAL_BYTES
    assert _partials(tmp_path) == []                  # a clean failure leaves no temp file
    proc = _cli('balance', '--output', target)        # without the limit: replaced, loadable
    assert proc.returncode == 0, proc.stderr
    assert scene.load(target).name == 'hoeken_balanced' and not _partials(tmp_path)


def test_class3_atomic_record_write_error(tmp_path):
    target = tmp_path / 'good.rrd'
    target.write_bytes(ORIGINAL_BYTES)
    proc = _cli('record', '--out', target, '--cycles', '2', limit_bytes=64 * 1024)
    assert proc.returncode == cli.EXIT_USAGE, proc.stderr
    assert 'good.rrd: File too large' in proc.stderr
    assert target.read_bytes() == ORIGINAL_BYTES and _partials(tmp_path) == []


def test_class3_atomic_record_sigkill(tmp_path):
    target = tmp_path / 'good.rrd'
    target.write_bytes(ORIGINAL_BYTES)
    proc = subprocess.Popen([sys.executable, '-m', 'mech_balance.cli.main', 'record', '--scene',
                             'carpet_scraper', '--balance', '--cycles',
                             str(conventions.MAX_CYCLES), '--out', str(target)], env=_env(),
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    seen = False
    try:
        end = time.monotonic() + KILL_DEADLINE_S
        while proc.poll() is None and time.monotonic() < end:
            if _partials(tmp_path):          # the ~33 MB recording is being written: kill it
                seen = True
                break
            time.sleep(KILL_POLL_S)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == -signal.SIGKILL, 'the recording ended before it was killed'
    assert target.read_bytes() == ORIGINAL_BYTES
    print(f'\nSIGKILL while the temporary file existed: {seen}; left: {_partials(tmp_path)}')
    assert all(p.startswith('.good.rrd.partial-') for p in _partials(tmp_path))


LIVE_SCRIPT = textwrap.dedent("""
    import sys, time
    from mech_balance import schema as scene
    from mech_balance.viz import recording
    rec = recording.LiveRecorder(sys.argv[1], scene.load('hoeken'))
    k = 0
    while True:
        rec.log_sample(0.01 * k, 0.01 * k)
        k += 1
        if k == 50:
            print('ready', flush=True)
        time.sleep(0.001)
""")


def test_class3_live_recording_is_partial_until_closed(tmp_path):
    target = tmp_path / 'live.rrd'
    target.write_bytes(ORIGINAL_BYTES)
    # SIGKILL during a live recording (the node's recording_path): the target is untouched
    proc = subprocess.Popen([sys.executable, '-c', LIVE_SCRIPT, str(target)], env=_env(),
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        assert proc.stdout.readline().strip() == 'ready'
        assert len(_partials(tmp_path)) == 1          # visibly partial while recording
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert target.read_bytes() == ORIGINAL_BYTES
    for name in _partials(tmp_path):
        (tmp_path / name).unlink()
    # a clean close renames the complete recording over the target
    rec = recording.LiveRecorder(target, scene.load('hoeken'))
    assert rec.log_sample([0.0, 0.01, 0.02], [0.0, 0.1, 0.2]) == 3
    assert target.read_bytes() == ORIGINAL_BYTES and len(_partials(tmp_path)) == 1
    rec.close()
    assert _partials(tmp_path) == []
    assert recording.read_recording(target)['/plots/shaking_force/original'].rows == 3


# ------------------------------------------------------------------------------ class 7


def test_class7_duplicate_key_names_line(tmp_path):
    lines = HOEKEN_TEXT.splitlines()
    at = next(i for i, line in enumerate(lines) if line.strip().startswith('mass_kg:'))
    indent = lines[at][:len(lines[at]) - len(lines[at].lstrip())]
    lines.insert(at + 1, f'{indent}mass_kg: 1.0')
    path = tmp_path / 'twice.yaml'
    path.write_text('\n'.join(lines) + '\n')
    link = scene.load('hoeken').links[0].name
    with pytest.raises(scene.SceneError, match=(
            rf'^links\.{link}\.mass_kg: duplicate key in scene twice\.yaml at line {at + 2} '
            rf'\(first at line {at + 1}\); expected each key once')):
        scene.load(path)
    # in flow style too, and at the top level; merge keys may still be overridden
    with pytest.raises(safe_yaml.YamlError, match=r'^a\.b: duplicate key .* at line 1'):
        safe_yaml.loads('a: {b: 1, b: 2}')
    with pytest.raises(safe_yaml.YamlError, match=r'^name: duplicate key in YAML at line 2'):
        safe_yaml.loads('name: x\nname: y\n')
    assert safe_yaml.loads('base: &b {m: 1, n: 2}\nd: {<<: *b, m: 3}\n')['d'] == {'m': 3, 'n': 2}


def test_class7_design_values_have_the_scene_magnitude_limit(capsys):
    for value in ('1e308', '1e200', '-1e19'):
        with pytest.raises(SystemExit) as exc:
            cli.main(['analyze', f'--design={value},' + ','.join(['1'] * 11)])
        assert exc.value.code == cli.EXIT_USAGE
        err = capsys.readouterr().err
        assert 'argument --design:' in err and \
            'magnitude <= 1e+18 (the limit of numbers in scene files)' in err
    sc = scene.load('hoeken')
    with pytest.raises(ValueError, match=r'^design: got 1e\+200, expected magnitudes <= 1e\+18'):
        equimomental.apply_design(sc, [1e200] + [1.0] * 11, normalized=True)


def test_class7_fixed_links_duplicates_blanks_and_all_are_refused():
    sc = scene.load('hoeken')
    names = [lk.name for lk in sc.links]
    with pytest.raises(checks.BalanceError, match=r"^fixed_links: got 'crank' twice"):
        redistribution.optimize(sc, fixed_links=('crank', 'crank'))
    with pytest.raises(checks.BalanceError, match=r"^fixed_links: got ''"):
        redistribution.optimize(sc, fixed_links=('',))
    with pytest.raises(checks.BalanceError, match=r'^fixed_links: got every link'):
        redistribution.optimize(sc, fixed_links=tuple(names))
    with pytest.raises(ValueError, match=r"^balance\.fixed_links: got 'crank' twice"):
        params.check('balance.fixed_links', 'crank,crank')
    with pytest.raises(ValueError, match=r'^balance\.fixed_links: got .*expected comma'):
        params.check('balance.fixed_links', 'crank,,rocker')
    values = dict(params.defaults(), **{'balance.fixed_links': ','.join(names)})
    with pytest.raises(ValueError, match=r'^balance\.fixed_links: got every link'):
        params.check_links(values, names)


def test_class7_frame_id_length_is_bounded():
    with pytest.raises(ValueError, match=r'^frame_id: got a name of 100000 characters, '
                                         r'expected at most 256'):
        params.check('frame_id', 'a' * 100_000)
    assert params.check('frame_id', 'a' * conventions.MAX_NAME_LENGTH)


# ------------------------------------------------------------------------------ class 8


def test_class8_latin1_scene_names_file_byte_and_fix(tmp_path):
    path = tmp_path / 'latin.yaml'
    path.write_bytes(HOEKEN_TEXT.replace('description:', 'description: café', 1)
                     .encode('latin-1'))
    raw = path.read_bytes()
    at = raw.index(b'\xe9')
    line = raw.count(b'\n', 0, at) + 1
    with pytest.raises(scene.SceneError, match=(
            rf'^scene latin\.yaml: byte 0xe9 at offset {at} \(line {line}, column \d+\) is not '
            r'UTF-8; expected a UTF-8 text file \(re-save it as UTF-8\)$')):
        scene.load(path)


@pytest.mark.parametrize('make, match', [
    (lambda d: Path(os.devnull), r"^scene: '/dev/null' is not a regular file"),
    (lambda d: d, r"^scene: '.*' is a directory, expected a YAML file$"),
    (lambda d: (d / 'empty.yaml', (d / 'empty.yaml').write_text(''))[0],
     r"^scene: file '.*empty\.yaml' is empty, expected a YAML mapping$"),
    (lambda d: d / 'missing.yaml', r"^scene: file '.*missing\.yaml' does not exist$"),
])
def test_class8_file_kinds_are_said(make, match, tmp_path, capsys):
    path = make(tmp_path)
    with pytest.raises(scene.SceneError, match=match):
        scene.load(f'{path}{os.sep}' if path == tmp_path else path)
    assert cli.main(['analyze', '--scene', str(path)]) == cli.EXIT_USAGE
    assert capsys.readouterr().err.startswith('mech-balance analyze: error: scene')


def test_class8_weights_1e308_names_the_option(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(['balance', '--weights', '1e308', '1e308'])
    assert exc.value.code == cli.EXIT_USAGE
    err = capsys.readouterr().err
    assert err.startswith("mech-balance balance: error: argument --weights: got '1e308', "
                          'expected a number 0 <= x <= 1e+06 (a fixed limit of mech_balance)')
    with pytest.raises(checks.BalanceError, match=r'^weights: w1 = 1e\+308, expected at '
                       r'most 1e\+06'):
        redistribution.optimize(scene.load('hoeken'), (1e308, 1e308))
    with pytest.raises(ValueError, match=r'^balance\.weights: got \[1e\+308, 1\.0\]'):
        params.check('balance.weights', [1e308, 1.0])


def test_class8_syntax_and_control_characters_name_line_and_column():
    with pytest.raises(safe_yaml.YamlError, match=r'^f: not valid YAML at line 2, column 1: '
                                                  r"expected ',' or ']'"):
        safe_yaml.loads('a: [1, 2\n', 'f')
    with pytest.raises(safe_yaml.YamlError, match=r'^f: not valid YAML at line 2, column 5: '
                                                  r'character #x0000'):
        safe_yaml.loads('a: 1\nb: x\x00y\n', 'f')
    with pytest.raises(safe_yaml.YamlError, match=r'^f: a value cannot be read'):
        safe_yaml.loads('d: 2001-02-30\n', 'f')
    assert yaml.safe_load('x: 1e-3')['x'] == '1e-3' and safe_yaml.loads('x: 1e-3')['x'] == 1e-3
