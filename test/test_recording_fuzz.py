"""
Bad recordings: every one gets ONE clear line and exit 2, never a traceback or a silent fix.

A seeded fuzz over rosbag2 (MCAP, sqlite3) and CSV recordings made here: truncations at every
MCAP record boundary and inside records, at sqlite3 page boundaries and inside pages, at CSV
line boundaries and inside lines; bit flips; wrong message types; and one case per value
class (non-finite, implausible, time not increasing, duplicated, missing or unknown columns,
binary or mis-encoded text, ragged rows, NaN in t_s, the CSV limits).  Every case runs the
verb in-process with ``--output`` pointing at an existing file, which must be untouched unless
the verb succeeds.  At most :data:`MAX_CASES_PER_KIND` random cases per kind (bounded time).
"""

import math
import os
from pathlib import Path
import shutil
import sqlite3
import struct
import sys

from mech_balance.cli import main as cli
from mech_balance.ros import bags
import numpy as np
import pytest

SEED = 20
MAX_CASES_PER_KIND = 12
"""Random truncations and bit flips per recording kind (the boundary cases come on top)."""
N = 2000
RATE_HZ = 1000.0
SENTINEL = 'an existing file: never touched on failure\n'


def _samples():
    """
    Return (t_ns, position, wrench (n, 3)) of a 2 s recording (2 turns) from an epoch.

    The synthetic Hoeken rig (test/synthetic_rig.py): the intact recordings must calibrate,
    and identify refuses a wrench its model does not explain (docs/identification.md).
    """
    from mech_balance import schema
    sys.path.insert(0, os.path.dirname(__file__))
    import synthetic_rig as sr
    true = sr.perturbed(schema.load('hoeken'), SEED)
    t_ns, pos, wrench, _ = sr.record_real(true, N / RATE_HZ, 4096, SEED, w0=2.0 * math.pi,
                                          t0_ns=1_700_000_000_000_000_000)
    return t_ns, pos, wrench


@pytest.fixture(scope='module')
def made(tmp_path_factory):
    """Return {kind: path} of the intact recordings."""
    root = tmp_path_factory.mktemp('fuzz')
    t_ns, pos, wrench = _samples()
    out = {s: bags.write_bag(root / s, s, t_ns, pos, wrench) for s in bags.STORAGES}
    out['csv'] = bags.write_csv(root / 'rec.csv', t_ns * 1e-9, pos, wrench)
    return out


class Runner:
    """Run the verb on a recording; check the exit code, the one line and the output file."""

    def __init__(self, tmp_path, capsys):
        self.out = tmp_path / 'calibrated.yaml'
        self.capsys = capsys
        self.codes = {}

    def __call__(self, bag, what, expect=None):
        self.out.write_text(SENTINEL)
        rc = cli.main(['identify', '--scene', 'hoeken', '--bag', str(bag), '--output',
                       str(self.out)])
        err = self.capsys.readouterr().err
        errors = [ln for ln in err.splitlines() if 'error:' in ln]
        assert 'Traceback' not in err, (what, err)
        assert rc in (0, cli.EXIT_USAGE), (what, rc, err)
        self.codes[rc] = self.codes.get(rc, 0) + 1
        if rc == 0:
            assert self.out.read_text() != SENTINEL, what
        else:
            assert len(errors) == 1, (what, err)
            assert self.out.read_text() == SENTINEL, what
            if expect is not None:
                assert expect in errors[0], (what, errors[0])
        return rc, (errors[0] if errors else '')


def _copy(src, dst):
    if Path(src).is_dir():
        shutil.copytree(src, dst)
    else:
        shutil.copy(src, dst)
    return Path(dst)


def _storage_file(bag):
    return next(p for p in Path(bag).iterdir() if p.suffix in ('.mcap', '.db3'))


def _mcap_boundaries(data):
    """Return the offsets of every MCAP record (after the 8-byte magic)."""
    out, i = [], 8
    while i + 9 <= len(data) - 8:
        out.append(i)
        i += 9 + struct.unpack('<Q', data[i + 1:i + 9])[0]
    return out + [len(data) - 8, len(data)]


def _mutate(bag, tmp_path, name, data):
    dst = _copy(bag, tmp_path / name)
    _storage_file(dst).write_bytes(data)
    return dst


def test_intact_recordings_succeed(made, tmp_path, capsys):
    run = Runner(tmp_path, capsys)
    for kind, path in made.items():
        assert run(path, kind)[0] == 0


def test_mcap_truncations_and_bit_flips(made, tmp_path, capsys):
    run = Runner(tmp_path, capsys)
    rng = np.random.default_rng(SEED)
    data = _storage_file(made['mcap']).read_bytes()
    cuts = set(_mcap_boundaries(data)[:-1])
    bounds = sorted(cuts)
    for a, b in zip(bounds, bounds[1:] + [len(data)]):   # inside every record
        cuts.add(int((a + b) // 2))
        cuts.add(a + 5)
    cuts |= {int(c) for c in rng.integers(0, len(data), MAX_CASES_PER_KIND)}
    cuts.add(8)
    for k, cut in enumerate(sorted(cuts)):
        run(_mutate(made['mcap'], tmp_path, f'cut{k}', data[:cut]), f'mcap cut at {cut}')
    for k, pos in enumerate(rng.integers(0, len(data), MAX_CASES_PER_KIND)):
        flipped = bytearray(data)
        flipped[pos] ^= 1 << int(rng.integers(8))
        run(_mutate(made['mcap'], tmp_path, f'flip{k}', bytes(flipped)), f'mcap flip {pos}')
    assert run(_mutate(made['mcap'], tmp_path, 'eight', data[:8]), '8 bytes')[0] == cli.EXIT_USAGE
    assert run.codes.get(cli.EXIT_USAGE, 0) >= len(cuts) // 2, run.codes


def test_sqlite_truncations_bit_flips_and_bad_payload(made, tmp_path, capsys):
    run = Runner(tmp_path, capsys)
    rng = np.random.default_rng(SEED + 1)
    data = _storage_file(made['sqlite3']).read_bytes()
    page = 4096
    cuts = set(range(0, len(data), page)) | {c + page // 2 for c in range(0, len(data), page)}
    cuts = sorted(cuts)
    if len(cuts) > 4 * MAX_CASES_PER_KIND:
        cuts = sorted(rng.choice(cuts, 4 * MAX_CASES_PER_KIND, replace=False))
    for k, cut in enumerate(cuts):
        run(_mutate(made['sqlite3'], tmp_path, f'cut{k}', data[:int(cut)]), f'db3 cut {cut}')
    for k, pos in enumerate(rng.integers(0, len(data), MAX_CASES_PER_KIND)):
        flipped = bytearray(data)
        flipped[pos] ^= 1 << int(rng.integers(8))
        run(_mutate(made['sqlite3'], tmp_path, f'flip{k}', bytes(flipped)), f'db3 flip {pos}')
    # a message whose CDR payload is garbage
    bad = _copy(made['sqlite3'], tmp_path / 'badcdr')
    with sqlite3.connect(_storage_file(bad)) as db:
        db.execute("UPDATE messages SET data = x'00010000deadbeef' WHERE id = 7")
    _, line = run(bad, 'bad CDR', expect='undecodable')
    assert 'message' in line and 'topic' in line


def test_bag_metadata_and_files(made, tmp_path, capsys):
    run = Runner(tmp_path, capsys)
    meta = (Path(made['mcap']) / 'metadata.yaml').read_text()
    cases = {
        'nested': 'a: ' + '[' * 5000 + ']' * 5000 + '\n',
        'truncated': meta[:len(meta) // 2],
        'garbage': '\x00\xff' * 10,
        'not a mapping': '- 1\n- 2\n',
        'wrong type': meta.replace('geometry_msgs/msg/WrenchStamped', 'std_msgs/msg/String'),
        'unknown type': meta.replace('sensor_msgs/msg/JointState', 'no_pkg/msg/Nothing'),
    }
    for name, text in cases.items():
        dst = _copy(made['mcap'], tmp_path / name.replace(' ', '_'))
        (dst / 'metadata.yaml').write_text(text, errors='surrogateescape')
        run(dst, f'metadata {name}', expect='--')
    eight = _mutate(made['mcap'], tmp_path, 'eight', b'\x89MCAP0\r\n')
    run(eight, '8-byte mcap', expect='--bag')
    missing = _copy(made['mcap'], tmp_path / 'missing')
    _storage_file(missing).unlink()
    run(missing, 'storage file missing', expect='--bag')


def _bag(tmp_path, name, storage='mcap', **change):
    t_ns, pos, wrench = _samples()
    values = {'t_ns': t_ns, 'position_rad': pos, 'wrench': wrench, **change}
    return bags.write_bag(tmp_path / name, storage, values['t_ns'], values['position_rad'],
                          values['wrench'])


def test_bag_values(tmp_path, capsys):
    run = Runner(tmp_path, capsys)
    t_ns, pos, wrench = _samples()
    huge = wrench.copy()
    huge[100, 0] = 1e300
    nan = pos.copy()
    nan[5] = math.nan
    back = t_ns.copy()
    back[50] = back[40]
    cases = [('huge', {'wrench': huge}, 'force.x = 1e+300'),
             ('nan', {'position_rad': nan}, 'position = nan'),
             ('backwards', {'t_ns': back}, 'is not after the previous')]
    for name, change, expect in cases:
        run(_bag(tmp_path, name, **change), name, expect=expect)
    # a wrench topic recorded as another message type
    t_ns, pos, wrench = _samples()
    wrong = bags.write_bag(tmp_path / 'wrongtype', 'mcap', t_ns, pos, wrench,
                           wrench_topic='/crank_joint_state', encoder_topic='/measured_wrench')
    run(wrong, 'wrong message type', expect='carries geometry_msgs/msg/WrenchStamped')


def _csv_text(path):
    return Path(path).read_text()


def _write(tmp_path, name, text, mode='w'):
    p = tmp_path / f'{name}.csv'
    if mode == 'wb':
        p.write_bytes(text)
    else:
        p.write_text(text)
    return p


def test_csv_value_classes(made, tmp_path, capsys, monkeypatch):
    run = Runner(tmp_path, capsys)
    text = _csv_text(made['csv'])
    head, *rows = text.splitlines()
    body = '\n'.join(rows)

    def with_row(k, new):
        out = list(rows)
        out[k] = new
        return '\n'.join([head, *out]) + '\n'

    fields = rows[10].split(',')
    cases = {
        'huge field': (with_row(10, ','.join([fields[0], '1' * 200000, *fields[2:]])),
                       'characters'),
        'force 1e300': (with_row(10, ','.join([*fields[:2], '1e300', *fields[3:]])),
                        'column force_x_N: got 1e+300'),
        'nan t_s': (with_row(10, ','.join(['nan', *fields[1:]])), 'column t_s: got nan'),
        'inf position': (with_row(10, ','.join([fields[0], 'inf', *fields[2:]])),
                         'column crank_position_rad'),
        'backwards': (with_row(10, rows[5]), 'is not after'),
        'duplicated row': (with_row(10, rows[9]), 'is not after'),
        'duplicated column': (head + ',force_x_N\n' + '\n'.join(r + ',0' for r in rows),
                              'given twice'),
        'missing column': (head.replace('force_y_N', 'force_q_N') + '\n' + body,
                           'force_q_N'),
        'unknown column': (head + ',extra\n' + '\n'.join(r + ',0' for r in rows), 'unknown'),
        'ragged': (with_row(10, ','.join(fields[:-2])), 'fields, expected'),
        'not a number': (with_row(10, ','.join([fields[0], 'abc', *fields[2:]])),
                         "got 'abc'"),
        'empty': ('', 'empty'),
        'header only': (head + '\n', 'no rows'),
        'long line': (with_row(10, ' ' * 10000 + rows[10]), 'longer than'),
    }
    for name, (content, expect) in cases.items():
        run(_write(tmp_path, name.replace(' ', '_'), content), name, expect=expect)
    binary = bytes(np.random.default_rng(SEED).integers(0, 256, 5000, dtype=np.uint8))
    run(_write(tmp_path, 'binary', binary, 'wb'), 'binary', expect='line')
    latin = (head + '\n# caf\xe9\n' + body).encode('latin-1')
    run(_write(tmp_path, 'latin1', latin, 'wb'), 'latin-1', expect='not UTF-8')
    # the limits: rows (streamed, refused at the limit) and file size (refused at once)
    monkeypatch.setattr(bags, 'MAX_SAMPLES', 1024)
    run(made['csv'], 'rows', expect='more than 1024 samples')
    monkeypatch.setattr(bags, 'MAX_CSV_BYTES', 1000)
    run(made['csv'], 'size', expect='expected at most 1000')


def test_csv_truncations_and_bit_flips(made, tmp_path, capsys):
    run = Runner(tmp_path, capsys)
    rng = np.random.default_rng(SEED + 2)
    data = Path(made['csv']).read_bytes()
    lines = np.flatnonzero(np.frombuffer(data, dtype=np.uint8) == ord('\n')) + 1
    cuts = {int(c) for c in rng.choice(lines, MAX_CASES_PER_KIND, replace=False)}
    cuts |= {int(c) for c in rng.integers(0, len(data), MAX_CASES_PER_KIND)}
    cuts |= {0, 1, int(lines[0]), int(lines[0]) + 3}
    for k, cut in enumerate(sorted(cuts)):
        run(_write(tmp_path, f'cut{k}', data[:cut], 'wb'), f'csv cut {cut}')
    for k, pos in enumerate(rng.integers(0, len(data), MAX_CASES_PER_KIND)):
        flipped = bytearray(data)
        flipped[pos] ^= 1 << int(rng.integers(8))
        run(_write(tmp_path, f'flip{k}', bytes(flipped), 'wb'), f'csv flip {pos}')
    assert run(_write(tmp_path, 'empty', b'', 'wb'), 'empty csv')[0] == cli.EXIT_USAGE
    assert run.codes.get(cli.EXIT_USAGE, 0) > 0, run.codes


def test_output_never_touched_on_failure_without_a_recording(tmp_path, capsys):
    run = Runner(tmp_path, capsys)
    run(tmp_path / 'nothing.csv', 'missing file', expect='does not exist')
    os.mkdir(tmp_path / 'dir.csv')
    run(tmp_path / 'dir.csv', 'a directory', expect='--bag')
