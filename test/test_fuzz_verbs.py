"""
A seeded spatial fuzzer over every verb of the command line, in this process (issue 32).

Each case mutates a spatial built-in (``config/``; the former RGGR's spatial form too) where
a user or a tool gets it wrong: a number pushed to an extreme or made NaN or inf, a field of
the wrong type, deleted or added, every length scaled by 1e-15..1e12, a link's mass made 0,
tiny, huge or negative, the assembly angle or a pose's angles huge, the crank's speed or
acceleration zero, negative or huge, a joint axis degenerate (zero, subnormal, NaN, of two
components, on a spherical joint), a prismatic input's stroke reversed or empty, ``samples``
out of range.  The scene is written to a file and run through ``mech-balance`` as a user
would (:func:`mech_balance.cli.main.main` with argv, as ``test/cli_snapshot.py`` does):
``analyze``, ``balance`` (the default method, ``force-balance``, ``counterweights``),
``record``, ``urdf`` and ``simulate``.  A scene the loader refuses is run through every verb
(each must refuse it the same way); a scene that loads through :data:`VERBS_PER_VALID` of
them in turn, so that every verb meets every kind of mutation over the seed's cases.

Every run must end in exit 0 with finite figures (the ``--json`` output's numbers; the file
written for ``record`` and ``urdf``) or exit 2 or 3 with exactly one error line that starts
with the field, option or file it is about, or, for ``balance``, exit 2 with a design whose
objective is not certified (docs/cli.md: its figures finite, its message saying so); any
exception is a failure.  Each run must stay
within the stated per-run limits of docs/scenes.md (*Limits*, the verbs' time and memory):
:data:`RUN_TIME_LIMIT_S` of CPU time of this process (not wall time: a loaded machine
stretches that, not the work) and :data:`RUN_MEMORY_LIMIT_BYTES` of growth of this
process's resident peak, bounds of the work (a hang or an unbounded allocation), not of
speed (the runs here take 0.01-2 s).  Cases use the scene's ``samples: 24`` (the fuzzer tests
the handling, not the accuracy).  ``pytest -s`` prints the counts per verb and outcome.
"""

import collections
import contextlib
import copy
import io
import json
import math
import random
import re
import resource
import time

from mech_balance.cli import main as cli
from mech_balance.conventions import MAX_SAMPLES
from mech_balance.schema import load_data
import scene_paths
from test_fuzz_scenes import FIELD_FIRST
from test_spatial_bounds import _scaled
import yaml

SEED = 20261206
SCENES = 200
"""Mutated scenes per run of the test."""
VERBS_PER_VALID = 2
"""Verbs a scene that loads is run through (in turn over the cases); a refused one: all."""
BASE_SAMPLES = 24
"""Crank angles per revolution of every fuzzed scene (before its mutation)."""
RUN_TIME_LIMIT_S = 60.0
"""docs/scenes.md: a verb's run on a scene within the limits, at most this much CPU time."""
RUN_MEMORY_LIMIT_BYTES = 2 * 2 ** 30
"""docs/scenes.md: a verb's run on a scene within the limits, at most this much memory."""
BUILTINS = ('rssr_skew', 'rssp_slider', 'spatial_two_loop', 'pssr_skew', 'rggr_spatial',
            'rggr')
DATA = {name: load_data(name)[0] for name in BUILTINS}
ERROR_LINE = re.compile(r'^(mech-balance \w+: )?error: (.*)$')
OPTION_FIRST = re.compile(r'^(--[\w-]+|argument --[\w-]+)(, --[\w-]+)*: \S')
"""An option's error (argparse's or the verb's) starts with the option."""

EXTREMES = [1e308, -1e308, 1e19, -1e19, 1e18, 2 ** 63, 10 ** 40, 1e-300, 5e-324, 0, 0.0,
            -0.0, -1, 1e17, 123456789012345678]
NON_FINITE = [float('nan'), float('inf'), float('-inf')]
WRONG_TYPES = [None, 'text', '', True, [], {}, [1.0], [1.0, 2.0], {'x': 1.0}, 'frame.O1']
LENGTH_SCALES = [1e-15, 1e-13, 1e-12, 1e-9, 1e-6, 1e3, 1e4, 1e6, 1e12]
MASS_FACTORS = [0.0, 1e-15, 1e-9, 1e9, 1e15, -1.0]
ANGLES_DEG = [1e18, 1e19, -1e18, 1e12, 1e16, -1e12, 720.5, 359.999999, 1e300, 2.0 ** 60]
SPEEDS = [0.0, -62.8, 1e-12, 1e-6, 1e6, 1e12, 1e16, 1e300, -1e12]
AXES = [[0.0, 0.0, 0.0], [1e-300, 0.0, 0.0], [5e-324, 0.0, 0.0], [float('nan'), 0.0, 1.0],
        [1.0, 0.0], [1.0, 0.0, 0.0, 0.0], [1e300, 1e300, 1e300], [0.0, 0.0, -1.0], 'z']
SAMPLES = [0, 3, 4, 5, MAX_SAMPLES + 1, 10 ** 9, 2.5, '24', True, -24]


def _verbs(first_link):
    """Return ``{name: argv}`` of every verb (the scene is added per run)."""
    return {
        'analyze': ['analyze', '--json'],
        'balance': ['balance', '--json'],
        'balance_force': ['balance', '--json', '--method', 'force-balance'],
        'balance_cw': ['balance', '--json', '--method', 'counterweights', '--counterweights',
                       first_link, '--no-clearance'],
        'record': ['record', '--out', None],
        'urdf': ['urdf', '--out', None],
        'simulate': ['simulate', '--json', '--duration', None],
    }


def _duration(data):
    """
    Return ``simulate --duration`` for a case: 0.05 s, or 2 crank turns if that is shorter.

    A crank of 1e6 rad/s turns 8000 times in 0.05 s, which ``simulate`` integrates (up to its
    stated limits of turns and right-hand-side evaluations) in tens of seconds: the limits are
    stated and enforced, the fuzzer's budget is for the handling of many cases.
    """
    crank = data.get('crank') if isinstance(data, dict) else None
    speed = crank.get('speed_rad_s') if isinstance(crank, dict) else None
    if scene_paths.is_number(speed) and math.isfinite(speed) and abs(speed) > 80.0 * math.pi:
        return f'{4.0 * math.pi / abs(speed):.3g}'
    return '0.05'


VERB_NAMES = tuple(_verbs('x'))


# ------------------------------------------------------------------------------ mutations

def _set(data, path, value):
    scene_paths.get(data, path[:-1])[path[-1]] = value


def _mutate(rng, data):
    """Apply one mutation to ``data`` (a spatial scene mapping) in place; return its name."""
    paths = sorted(scene_paths.paths(data), key=repr)
    numbers = [p for p in paths if scene_paths.is_number(scene_paths.get(data, p))]
    links = sorted(data['links'])
    joints = sorted(data['joints'])
    op = rng.choice(['extreme', 'nonfinite', 'type', 'delete', 'extra', 'scale', 'scale',
                     'mass', 'mass', 'angle', 'pose_angle', 'speed', 'speed', 'axis', 'axis',
                     'stroke', 'samples', 'moment_point'])
    if op == 'extreme':
        _set(data, rng.choice(numbers), rng.choice(EXTREMES))
    elif op == 'nonfinite':
        _set(data, rng.choice(numbers), rng.choice(NON_FINITE))
    elif op == 'type':
        _set(data, rng.choice(paths), copy.deepcopy(rng.choice(WRONG_TYPES)))
    elif op == 'delete':
        path = rng.choice(paths)
        del scene_paths.get(data, path[:-1])[path[-1]]
    elif op == 'extra':
        dicts = [p for p in paths if isinstance(scene_paths.get(data, p), dict)] + [()]
        scene_paths.get(data, rng.choice(dicts))['extra_field'] = 1.0
    elif op == 'scale':
        s = rng.choice(LENGTH_SCALES)
        data.update(_scaled(data, s))
        op = f'scale{s:g}'
    elif op == 'mass':
        link = data['links'][rng.choice(links)]
        f = rng.choice(MASS_FACTORS)
        link['mass_kg'] = link['mass_kg'] * f
        if f == 0.0 and rng.random() < 0.5:     # a consistent massless link
            link['inertia_com_kg_m2'] = [0.0] * 6
        op = f'mass{f:g}'
    elif op == 'angle':
        data['assembly']['crank_angle_deg'] = rng.choice(ANGLES_DEG)
    elif op == 'pose_angle':
        pose = data['assembly']['poses'][rng.choice(sorted(data['assembly']['poses']))]
        pose['rpy_deg'][rng.randrange(3)] = rng.choice(ANGLES_DEG)
    elif op == 'speed':
        key = rng.choice(['speed_rad_s', 'speed_rad_s', 'acceleration_rad_s2'])
        data['crank'][key] = rng.choice(SPEEDS)
    elif op == 'axis':
        joint = data['joints'][rng.choice(joints)]
        joint[rng.choice(['axis', 'axis_b'])] = copy.deepcopy(rng.choice(AXES))
    elif op == 'stroke':
        stroke = data['crank'].get('stroke_m')
        if stroke is None:
            data['crank']['stroke_m'] = [0.0, 0.05]    # on a revolute input: refused
        else:
            data['crank']['stroke_m'] = rng.choice([stroke[::-1], [stroke[0]] * 2,
                                                    [stroke[0], stroke[1] * 1e6],
                                                    [stroke[0], float('inf')]])
    elif op == 'samples':
        data['samples'] = rng.choice(SAMPLES)
    else:
        data['moment_point_m'] = [rng.choice(EXTREMES + [0.5])] * 3
    return op


def _cases():
    """Yield ``(k, builtin, mutation, data)`` for every case, seeded."""
    rng = random.Random(SEED)
    for k in range(SCENES):
        name = BUILTINS[k % len(BUILTINS)]
        data = copy.deepcopy(DATA[name])
        data['samples'] = BASE_SAMPLES
        ops = [_mutate(rng, data) for _ in range(rng.choice([1, 1, 1, 2]))]
        yield k, name, '+'.join(ops), data


# ------------------------------------------------------------------------------ running

def _run(argv):
    """Run one command in this process; return ``(exit, stdout, stderr, seconds, grown)``."""
    out, err = io.StringIO(), io.StringIO()
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    t0 = time.process_time()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = cli.main(argv)
        except SystemExit as exc:
            code = exc.code
    seconds = time.process_time() - t0
    grown = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 - peak
    return code or 0, out.getvalue(), err.getvalue(), seconds, grown


def _judge(verb, code, out, err, path):
    """Return ``(outcome, problem)``; ``problem`` is None when the run is acceptable."""
    errors = [m.group(2) for m in map(ERROR_LINE.match, err.splitlines()) if m]
    if code == 0:
        if errors:
            return 'exit 0', f'exit 0 with an error line: {errors[0][:200]!r}'
        if '--json' in VERBS[verb]:
            try:
                doc = json.loads(out)
            except ValueError:
                return 'exit 0', f'not JSON: {out[-200:]!r}'
            bad = [v for v in scene_paths.numbers(doc) if not math.isfinite(v)]
            if bad:
                return 'exit 0', f'{len(bad)} non-finite figures, e.g. {bad[0]!r}'
        elif path is not None and not path.exists():
            return 'exit 0', f'{path.name} not written'
        return 'result', None
    if code == 2 and '--json' in VERBS[verb] and not errors:   # docs/cli.md: not certified
        try:
            doc = json.loads(out)
        except ValueError:
            return 'exit 2', f'exit 2, no error line and no JSON: {err[-300:]!r}'
        bad = [v for v in scene_paths.numbers(doc) if not math.isfinite(v)]
        if doc.get('certified') is not False or bad or 'NOT certified' not in doc['message']:
            return 'exit 2', f'exit 2 without an error line: {out[-300:]!r}'
        return 'not certified', None
    if code not in (2, 3):
        return f'exit {code}', f'exit {code}: {err[-300:]!r}'
    if len(errors) != 1:
        return f'exit {code}', f'{len(errors)} error lines: {err[-400:]!r}'
    text = errors[0]
    if not (FIELD_FIRST.match(text) or OPTION_FIRST.match(text)):
        return f'exit {code}', f'the error names no field: {text[:300]!r}'
    return f'refused ({code})', None


VERBS = _verbs('x')


def test_every_verb_on_mutated_spatial_scenes(tmp_path):
    counts, spent = collections.Counter(), collections.Counter()
    problems, slowest, largest = [], (0.0, ''), (0, '')
    scene = tmp_path / 'fuzzed.yaml'
    turn = 0
    for k, name, op, data in _cases():
        scene.write_text(yaml.safe_dump(data, sort_keys=False), encoding='utf-8')
        first = _run(['analyze', '--json', '--scene', str(scene)])
        verbs = ['analyze']
        if first[0] != 0:       # refused on load (or by analyze): every verb must refuse it
            verbs += [v for v in VERB_NAMES if v != 'analyze']
        else:
            for _ in range(VERBS_PER_VALID):
                turn += 1
                verbs.append(VERB_NAMES[1 + turn % (len(VERB_NAMES) - 1)])
        first_link = sorted(data['links'])[0] if isinstance(data.get('links'), dict) and \
            data['links'] else 'crank'
        for verb in verbs:
            argv = list(_verbs(str(first_link))[verb])
            path = None
            if verb == 'simulate':
                argv[argv.index(None)] = _duration(data)
            elif None in argv:
                path = tmp_path / f'out{k}_{verb}.{"rrd" if verb == "record" else "urdf"}'
                argv[argv.index(None)] = str(path)
            result = first if verb == 'analyze' else _run(argv + ['--scene', str(scene)])
            code, out, err, seconds, grown = result
            outcome, problem = _judge(verb, code, out, err, path)
            counts[(verb, outcome)] += 1
            spent[verb] += seconds
            where = f'case {k} {name} {op} {verb}'
            slowest = max(slowest, (seconds, where))
            largest = max(largest, (grown, where))
            if problem is None and seconds > RUN_TIME_LIMIT_S:
                problem = f'{seconds:.1f} s, over the limit {RUN_TIME_LIMIT_S:g} s'
            if problem is None and grown > RUN_MEMORY_LIMIT_BYTES:
                problem = f'resident peak grew {grown / 2 ** 20:.0f} MiB, over the limit'
            if problem is not None:
                problems.append(f'{where}: {problem}')
    print(f'\nfuzz verbs: {SCENES} scenes, seed {SEED}, {sum(counts.values())} runs; slowest '
          f'{slowest[0]:.2f} s ({slowest[1]}), largest peak growth {largest[0] / 2 ** 20:.0f} '
          f'MiB ({largest[1]})')
    for (verb, outcome), n in sorted(counts.items()):
        print(f'  {verb:<15}{outcome:<14}{n:>5}')
    print('  seconds per verb: ' + ', '.join(f'{v} {t:.1f}' for v, t in spent.items()))
    assert not problems, '\n'.join(problems[:40])
    for verb in VERB_NAMES:      # every verb met both a scene it ran and one it refused
        assert counts[(verb, 'result')] > 0, (verb, counts)
        assert any(n for (v, o), n in counts.items() if v == verb and o.startswith('refused'))


def test_the_fuzzer_is_seeded_and_covers_every_spatial_builtin():
    from mech_balance import schema
    spatial = sorted(n for n, p in schema.builtin_scenes().items()
                     if load_data(p)[0].get('kind') == 'spatial')
    assert sorted(BUILTINS) == spatial
    assert [c[:3] for c in _cases()] == [c[:3] for c in _cases()]
    assert len({op for _, _, op, _ in _cases()}) > 30
