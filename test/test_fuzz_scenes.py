"""
A seeded, structure-aware fuzzer over every built-in scene: loader and cycle, in-process.

Each case mutates one built-in scene (``config/``) at the level of its data (deleted keys,
wrong types, extreme and non-finite numbers, broken references and topology, plausible
perturbations that reach the core) or of its text (duplicated keys, deep nesting, aliases and
"billion laughs", bad encodings, truncation), writes it to a file and runs it through
:func:`mech_balance.schema.load` and one cycle: ``analysis.run_cycle(analysis.Rig(scene))``
for planar scenes, the kind's ``analyze`` for spatial ones (as ``mech-balance analyze``
does), both at a few samples.  A former ``kind: rggr`` file (test_rggr.LEGACY, translated
on load to its spatial scene) is fuzzed as a scene of its own.  Every outcome must be a
result with finite numbers or one of the package's own ``ValueError`` subclasses with a
one-line message that starts with the field (or the file) it is about.  Any other
exception (``KeyError``, ``TypeError``, ``RecursionError``, ``MemoryError``,
``OverflowError``, a bare ``ValueError``) or a silent NaN fails the test.  Run with
``pytest -s`` to see the counts per outcome.
"""

import collections
import copy
import math
import random
import re
import warnings

from mech_balance import schema as scene
from mech_balance.analysis import cycle as analysis
import numpy as np
import pytest
import scene_paths
from test_rggr import LEGACY
import yaml

DUMPER = getattr(yaml, 'CSafeDumper', yaml.SafeDumper)
SEED = 20240612
PLANAR_CASES = 1600
RGGR_CASES = 500
SAMPLES = 6
"""Crank angles per evaluated cycle: the fuzzer tests the handling, not the accuracy."""
FIELD_FIRST = re.compile(
    r'^(scene [^:\n]+|scene|[A-Za-z_][\w]*(\.[\w-]+|\[\d+\])*|crank angle -?[\d.]+ deg|'
    r'input slide -?[\d.]+ m): \S')
"""An error message starts with the field path, the scene file, the crank angle or a
prismatic input's slide (the position where a spatial linkage stops)."""
BUILTINS = scene.builtin_scenes()
TEXTS = {name: path.read_text(encoding='utf-8') for name, path in BUILTINS.items()}
DATA = {name: scene.load_data(path)[0] for name, path in BUILTINS.items()}
PLANAR = sorted(n for n, d in DATA.items() if d.get('kind', 'planar') == 'planar')
SPATIAL = sorted(n for n, d in DATA.items() if d.get('kind') == 'spatial')
RGGR = ['rggr_legacy']
"""The former kind: rggr file (not a built-in any more)."""
DATA['rggr_legacy'] = copy.deepcopy(LEGACY)
TEXTS['rggr_legacy'] = yaml.safe_dump(LEGACY, sort_keys=False)
SPATIAL_CASES = 240

WRONG_TYPES = [None, 'text', '', True, False, [], {}, [1.0], [1.0, 2.0, 3.0], {'x': 1.0},
               [[0.0, 1.0], [2.0]], 'frame.O1', 7, -3, 0.5]
EXTREMES = [1e308, -1e308, 1.7e308, 1e19, -1e19, 1e18, 2 ** 63, -2 ** 63, 10 ** 40, 1e-300,
            -1e-300, 5e-324, 0, 0.0, -0.0, -1, 1e17, 123456789012345678]
NON_FINITE = [float('nan'), float('inf'), float('-inf')]
BAD_REFS = ['nolink.P', 'crank.nopoint', 'frame', '', 'crank.', '.A', 'frame.nope', 'a.b.c',
            'coupler', 'frame.O1.x']
SAMPLE_VALUES = [0, 3, 4, 5, 10 ** 6, 5_000_000, 2 ** 31, -5, 4.5, '360', 100_000, 100_001]


# ------------------------------------------------------------------------------ data level


def _mutate_data(rng, data):
    """Apply one structural mutation to ``data`` in place; return its description."""
    paths = sorted(scene_paths.paths(data), key=repr)
    numbers = [p for p in paths if scene_paths.is_number(scene_paths.get(data, p))]
    op = rng.choice(['delete', 'type', 'extreme', 'nonfinite', 'reference', 'topology',
                     'samples', 'unknown', 'perturb', 'perturb', 'perturb', 'rename'])
    if op in ('extreme', 'nonfinite', 'perturb') and not numbers:
        op = 'type'
    if op == 'delete':
        path = rng.choice(paths)
        del scene_paths.get(data, path[:-1])[path[-1]]
    elif op == 'type':
        path = rng.choice(paths)
        scene_paths.get(data, path[:-1])[path[-1]] = copy.deepcopy(rng.choice(WRONG_TYPES))
    elif op == 'extreme':
        path = rng.choice(numbers)
        scene_paths.get(data, path[:-1])[path[-1]] = rng.choice(EXTREMES)
    elif op == 'nonfinite':
        path = rng.choice(numbers)
        scene_paths.get(data, path[:-1])[path[-1]] = rng.choice(NON_FINITE)
    elif op == 'perturb':  # plausible values: these reach the kinematics and dynamics
        path = rng.choice(numbers)
        old = scene_paths.get(data, path)
        scene_paths.get(data, path[:-1])[path[-1]] = \
            old * rng.choice([0.0, 0.5, 0.9, 1.1, 2.0, -1.0]) + rng.choice([0.0, 1e-3, -0.02])
    elif op == 'reference':
        refs = [p for p in paths if isinstance(scene_paths.get(data, p), str) and
                (p[-1] in ('a', 'b', 'joint') or '.' in scene_paths.get(data, p))]
        path = rng.choice(refs or paths)
        scene_paths.get(data, path[:-1])[path[-1]] = rng.choice(BAD_REFS)
    elif op == 'topology':
        op = _topology(rng, data)
    elif op == 'samples':
        data['samples'] = rng.choice(SAMPLE_VALUES)
    elif op == 'unknown':
        path = rng.choice([p for p in paths if isinstance(scene_paths.get(data, p), dict)] or [()])
        scene_paths.get(data, path)['extra_field'] = 1.0
    elif op == 'rename':  # a key renamed: what referred to it breaks
        dicts = [p for p in paths
                 if isinstance(scene_paths.get(data, p), dict) and scene_paths.get(data, p)]
        path = rng.choice(dicts) if dicts else ()
        node = scene_paths.get(data, path)
        key = rng.choice(sorted(node))
        node[f'{key}_x' if rng.random() < 0.5 else 'frame'] = node.pop(key)
    return op


def _topology(rng, data):
    joints, links = data.get('joints'), data.get('links')
    if not isinstance(joints, dict) or not isinstance(links, dict) or not joints:
        return 'topology-none'
    which = rng.choice(['drop_joint', 'copy_joint', 'drop_link', 'copy_link', 'self_joint',
                        'swap_ends'])
    name = rng.choice(sorted(joints))
    if which == 'drop_joint':
        del joints[name]
    elif which == 'copy_joint':
        joints[f'{name}_2'] = copy.deepcopy(joints[name])
    elif which == 'drop_link':
        del links[rng.choice(sorted(links))]
    elif which == 'copy_link':
        key = rng.choice(sorted(links))
        links[f'{key}_2'] = copy.deepcopy(links[key])
    elif which == 'self_joint' and isinstance(joints[name], dict):
        joints[name]['b'] = joints[name].get('a')
    elif which == 'swap_ends' and isinstance(joints[name], dict):
        j = joints[name]
        j['a'], j['b'] = j.get('b'), j.get('a')
    return f'topology-{which}'


# ------------------------------------------------------------------------------ text level

_SCALAR_KEY = re.compile(rb'^(\s*)([A-Za-z_]\w*):[ \t]+[^\s&*\[{#][^\n]*$', re.M)


def _mutate_text(rng, text):
    """Return ``(bytes, description)``: one textual mutation of a scene's YAML."""
    raw = text.encode('utf-8')
    op = rng.choice(['duplicate', 'duplicate', 'deep_list', 'deep_map', 'laughs', 'alias',
                     'recursive_alias', 'latin1', 'bad_byte', 'nul', 'utf16', 'truncate',
                     'big_int', 'merge_laughs'])
    lines = list(_SCALAR_KEY.finditer(raw))
    if op == 'duplicate':  # the same key again, next line, another value
        m = rng.choice(lines)
        value = rng.choice([b'1.0', b'0.5', b'-2', b'text', m.group(0).split(b':', 1)[1].strip()])
        dup = m.group(1) + m.group(2) + b': ' + value
        return raw[:m.end()] + b'\n' + dup.lstrip(b'\n') + raw[m.end():], op
    if op in ('deep_list', 'deep_map'):
        depth = rng.choice([10, 40, 63, 64, 65, 100, 1000, 5000])
        deep = (b'[' * depth + b'1' + b']' * depth if op == 'deep_list' else
                b'{a: ' * depth + b'1' + b'}' * depth)
        m = rng.choice(lines)
        return raw[:m.start()] + m.group(1) + m.group(2) + b': ' + deep + raw[m.end():], op
    if op == 'laughs':
        levels = rng.choice([3, 6, 9])
        bomb = [b'lol0: &l0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]']
        for k in range(1, levels):
            bomb.append(f'lol{k}: &l{k} ['.encode() + b', '.join([f'*l{k - 1}'.encode()] * 9)
                        + b']')
        body = b'\n'.join(b'  ' + line for line in bomb)
        key = rng.choice([b'notes', b'description', b'drive', b'links'])
        return raw + b'\n' + key + b':\n' + body + b'\n', f'{op}{levels}'
    if op == 'merge_laughs':
        bomb = [b'  m0: &m0 {a: 1, b: 2, c: 3, d: 4, e: 5, f: 6, g: 7, h: 8}']
        for k in range(1, 8):
            refs = b', '.join([f'*m{k - 1}'.encode()] * 9)
            bomb.append(f'  m{k}: &m{k} {{<<: ['.encode() + refs + b']}'
                        + f', z{k}: 1}}'.encode())
        return raw + b'\nnotes:\n' + b'\n'.join(bomb) + b'\n', op
    if op == 'alias':  # a legal alias: one value used twice
        m = rng.choice(lines)
        anchor = raw[:m.end()].replace(m.group(0), m.group(0).replace(b': ', b': &v ', 1), 1)
        return anchor + b'\nzz_alias: *v\n' + raw[m.end():], op
    if op == 'recursive_alias':
        return raw + b'\nnotes: &r [1, *r]\n', op
    if op == 'latin1':
        return raw.replace(b'description: ', 'description: café '.encode('latin-1'), 1) \
            if b'description: ' in raw else b'name: caf\xe9\n' + raw, op
    if op == 'bad_byte':
        at = rng.randrange(len(raw))
        return raw[:at] + rng.choice([b'\xff', b'\xc3', b'\x80', b'\xe2\x82']) + raw[at:], op
    if op == 'nul':
        at = rng.randrange(len(raw))
        return raw[:at] + b'\x00' + raw[at:], op
    if op == 'utf16':
        return text.encode('utf-16'), op
    if op == 'truncate':
        return raw[:rng.randrange(len(raw))], op
    # big_int: an integer literal far past any field's range
    m = rng.choice(lines)
    digits = rng.choice([20, 33, 400, 5000])
    return (raw[:m.start()] + m.group(1) + m.group(2) + b': ' + b'9' * digits
            + raw[m.end():]), f'{op}{digits}'


# ------------------------------------------------------------------------------ running


def _finite(values):
    for v in values:
        a = np.asarray(v)
        if a.dtype.kind in 'fciu' and not np.all(np.isfinite(a)):  # complex: both parts
            return False
    return True


def _evaluate(path):
    """Load and evaluate one scene file; return the result's numbers."""
    sc = scene.load(path)
    if sc.kind == 'spatial':  # the registry's analyze (through the Rig protocol)
        result = scene.kind_of(sc).implementation('analyze')(sc, SAMPLES)
        return list(scene_paths.numbers(result.data))
    cycle = analysis.run_cycle(analysis.Rig(sc), SAMPLES)
    st = cycle.state
    out = [st.residual, st.cond, st.omega]
    w = cycle.wrenches
    if w is not None:
        out += [w.shaking_force, w.shaking_moment]
        out += list((w.reaction_force or {}).values())
    out += [[r.rms for r in analysis.summarize(cycle)]]
    return out


def _outcome(path):
    """Return ``(outcome, problem)``: problem is None when the outcome is acceptable."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter('ignore', RuntimeWarning)  # near-singular: reported, fine
            values = _evaluate(path)
    except ValueError as exc:
        kind = type(exc)
        text = str(exc)
        name = kind.__name__
        if not kind.__module__.startswith('mech_balance'):
            return f'bare {name}', f'{name} is not a package error: {text[:300]}'
        if '\n' in text or len(text) > 1000 or not FIELD_FIRST.match(text):
            return name, f'message does not name the field: {text[:300]!r}'
        return name, None
    except Exception as exc:  # noqa: BLE001 - every other exception is a finding
        return type(exc).__name__, f'{type(exc).__name__}: {str(exc)[:300]}'
    if not _finite(values):
        return 'non-finite result', 'a result with NaN or inf and no error'
    return 'valid result', None


def _cases(names, count, seed):
    rng = random.Random(seed)
    for k in range(count):
        name = names[k % len(names)]
        if rng.random() < 0.45:
            raw, op = _mutate_text(rng, TEXTS[name])
        else:
            data = copy.deepcopy(DATA[name])
            ops = [_mutate_data(rng, data) for _ in range(rng.choice([1, 1, 1, 2, 3]))]
            raw = yaml.dump(data, Dumper=DUMPER, sort_keys=False,
                            allow_unicode=True).encode('utf-8')
            op = '+'.join(ops)
        yield name, op, raw


def _run(names, count, seed, tmp_path):
    counts = collections.Counter()
    problems = []
    path = tmp_path / 'fuzzed.yaml'
    for k, (name, op, raw) in enumerate(_cases(names, count, seed)):
        path.write_bytes(raw)
        outcome, problem = _outcome(path)
        counts[outcome] += 1
        if problem is not None:
            problems.append(f'case {k} {name} {op}: {problem}')
    print(f'\nfuzz {"/".join(names)}: {count} cases, seed {seed}')
    for outcome, n in counts.most_common():
        print(f'  {outcome:<24}{n:>6}')
    return counts, problems


def test_fuzz_planar_scenes(tmp_path):
    counts, problems = _run(PLANAR, PLANAR_CASES, SEED, tmp_path)
    assert sum(counts.values()) == PLANAR_CASES
    assert counts['valid result'] > 0 and counts['SceneError'] > 0  # both paths exercised
    assert not problems, '\n'.join(problems[:40])


def test_fuzz_rggr_scenes(tmp_path):
    counts, problems = _run(RGGR, RGGR_CASES, SEED + 1, tmp_path)
    assert sum(counts.values()) == RGGR_CASES
    assert counts['valid result'] > 0
    assert not problems, '\n'.join(problems[:40])


def test_fuzz_spatial_scenes(tmp_path):
    counts, problems = _run(SPATIAL, SPATIAL_CASES, SEED + 2, tmp_path)
    assert sum(counts.values()) == SPATIAL_CASES
    assert counts['valid result'] > 0 and counts['SceneError'] > 0
    assert not problems, '\n'.join(problems[:40])


def test_fuzzer_covers_every_builtin_and_is_seeded():
    assert sorted(PLANAR + SPATIAL) == sorted(BUILTINS) and PLANAR and SPATIAL and RGGR
    first = [(n, op, raw) for n, op, raw in _cases(PLANAR, 50, SEED)]
    again = [(n, op, raw) for n, op, raw in _cases(PLANAR, 50, SEED)]
    assert first == again
    assert math.isclose(PLANAR_CASES + RGGR_CASES, 2000) or PLANAR_CASES + RGGR_CASES > 2000


@pytest.mark.parametrize('name', sorted(BUILTINS))
def test_unmutated_builtins_evaluate(name, tmp_path):
    path = tmp_path / f'{name}.yaml'
    path.write_text(TEXTS[name], encoding='utf-8')
    assert _outcome(path) == ('valid result', None)
