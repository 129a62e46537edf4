"""
The recording bench section of ``mech-balance bench``.

One Hoeken recording, original against seed 001's a(2) design, written to a temporary file;
then ``mech-balance record`` of every built-in in each mode the README shows (plain,
``--balance``, and the carpet scraper and Hoeken with ``--counterweights``), each a process
of its own, :data:`RECORD_REPEATS` times: the median of its whole CPU time (start, imports,
balancing, recording) is held against :data:`RECORD_CPU_LIMIT_S`.
"""

from pathlib import Path
import resource
import statistics
import subprocess
import sys
import tempfile
import time

import mech_balance
from mech_balance import schema as scene
from mech_balance.balancing.paper_tables import TABLE5
from mech_balance.bench import core as bench
from mech_balance.core import equimomental

HOEKEN_A2_DESIGN = tuple(TABLE5[('a', 2)])
"""Seed 001 Table 5, case a(2), (w1, w2) = (0.5, 0.5): the bench's balanced Hoeken design."""
BENCH_SAMPLES = 360
DEAD_SAMPLES = 100
"""Samples logged to a dead viewer url by the bench."""
DEAD_STATUS_WAIT_S = 10.0
"""The bench waits at most this long for the recorder to call a dead viewer dead."""
BENCH_REPEAT_MAX = 20
"""The bench records at most this many times (each run writes a file)."""
RECORD_CPU_LIMIT_S = 2.0
"""``mech-balance record`` of a built-in takes at most this much CPU time, whole process."""
RECORD_EXTRA_RUNS = (('carpet_scraper', ('--counterweights', 'crank')),
                     ('hoeken', ('--counterweights', 'crank,rocker')))
"""Besides every built-in plain and with ``--balance``: these counterweight recordings."""
RECORD_REPEATS = 3
"""Processes per ``record`` run (fewer with ``bench --repeat``); the median CPU is judged."""
RECORD_TIMEOUT_S = 300.0
"""A ``record`` process is stopped after this long (a hang is a FAIL, not a wait)."""
PACKAGE_ROOT = Path(mech_balance.__file__).resolve().parents[1]
"""The directory that holds this package: a ``record`` process starts there."""


def bench_section(args, progress):
    """Return the timing of one Hoeken recording (original + seed 001 a(2), 360 samples)."""
    from mech_balance.viz import recording  # rerun: imported only when this section runs
    sc = scene.load('hoeken')
    balanced = equimomental.apply_design(sc, HOEKEN_A2_DESIGN, normalized=True)
    asked = int(getattr(args, 'repeat', BENCH_REPEAT_MAX))
    repeat = min(asked, BENCH_REPEAT_MAX)
    progress('  timing record hoeken (original + a(2)) ...')
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / 'hoeken.rrd'
        t0 = time.perf_counter()
        recording.record(path, sc, balanced, cycles=1, samples=BENCH_SAMPLES)
        cold = time.perf_counter() - t0
        warm = bench.median_seconds(
            lambda: recording.record(path, sc, balanced, cycles=1, samples=BENCH_SAMPLES),
            repeat=repeat)
        size = path.stat().st_size
    progress('  timing LiveRecorder against a url where nothing listens ...')
    dead = dead_viewer_timings(sc)
    lines = [f'record (rerun file): hoeken original + Chaudhary & Saha a(2), 1 turn at '
             f'{BENCH_SAMPLES} samples;',
             f'median of {repeat} runs after {bench.WARMUP} warm-up runs'
             + (f' (--repeat {asked} capped at {BENCH_REPEAT_MAX}: each run writes a file)'
                if asked > repeat else ''),
             f'{"scene":<16}{"first run s":>14}{"median s":>12}{"file MB":>10}',
             '-' * 52,
             f'{"hoeken":<16}{cold:>14.3f}{warm:>12.3f}{size / 1e6:>10.3f}',
             '',
             'LiveRecorder(url=...) where nothing listens (issue 23 2b.1; rerun itself waits '
             '5 s to connect and 5 s to disconnect):',
             f'  constructor {dead["init_s"] * 1e3:.2f} ms, log_sample worst of '
             f'{DEAD_SAMPLES} {dead["log_worst_s"] * 1e3:.2f} ms, close(timeout_s=1) '
             f'{dead["close_s"] * 1e3:.2f} ms; status: {dead["status"]}', '']
    lines += record_cpu_table(progress, getattr(args, 'scene', None),
                              min(asked, RECORD_REPEATS))
    return '\n'.join(lines)


def record_runs(scenes=None):
    """
    Return the ``mech-balance record`` runs timed: ``[(label, scene, extra argv)]``.

    ``scenes``: only these built-ins (``bench --scene``); None or empty: every one.
    """
    runs = [(name, extra) for name in scene.builtin_scenes() for extra in ((), ('--balance',))]
    runs += list(RECORD_EXTRA_RUNS)
    runs = [(' '.join((name,) + extra), name, extra) for name, extra in runs]
    return [r for r in runs if not scenes or r[1] in scenes]


def record_cpu(name, extra, out):
    """
    Return ``(cpu_s, wall_s, returncode)`` of one ``mech-balance record`` process.

    The CPU time is the child's user + system time (``getrusage(RUSAGE_CHILDREN)`` before
    and after): the whole process, the interpreter's start and the imports included.  The
    child starts in the directory that holds this package, so it runs the code timed here.
    """
    argv = [sys.executable, '-m', 'mech_balance.cli', 'record', '--scene', name, *extra,
            '--out', str(out)]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    try:
        code = subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              timeout=RECORD_TIMEOUT_S, cwd=PACKAGE_ROOT).returncode
    except subprocess.TimeoutExpired:
        code = None
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, wall, code


def record_cpu_table(progress, scenes=None, repeats=RECORD_REPEATS):
    """Return the lines of the table of ``mech-balance record`` CPU times (median of runs)."""
    repeats = max(1, int(repeats))
    lines = [f'mech-balance record, a process each, median of {repeats} (CPU s = user + '
             f'system of the whole process; limit {RECORD_CPU_LIMIT_S:g} s):',
             f'{"run":<40}{"CPU s":>7}{"min":>7}{"max":>7}{"wall s":>8}  verdict', '-' * 78]
    worst, met = (0.0, ''), True
    with tempfile.TemporaryDirectory() as tmp:
        for label, name, extra in record_runs(scenes):
            progress(f'  timing record {label} ...')
            runs = [record_cpu(name, extra, Path(tmp) / f'{name}.rrd') for _ in range(repeats)]
            cpu = sorted(r[0] for r in runs)
            median = statistics.median(cpu)
            wall = statistics.median(r[1] for r in runs)
            failed = [r[2] for r in runs if r[2] != 0]
            if failed:
                verdict = f'FAIL (exit {failed[0]})'
            else:
                verdict = 'PASS' if median <= RECORD_CPU_LIMIT_S else 'FAIL'
            lines.append(f'{label:<40}{median:>7.2f}{cpu[0]:>7.2f}'
                         f'{cpu[-1]:>7.2f}{wall:>8.2f}  {verdict}')
            met &= verdict == 'PASS'
            worst = max(worst, (median, label))
    if worst[1]:
        lines.append(f'target: every run within {RECORD_CPU_LIMIT_S:g} s of CPU (median): '
                     f'{"met" if met else "FAIL"} (worst {worst[0]:.2f} s, {worst[1]})')
    return lines


def dead_viewer_timings(sc):
    """Return the seconds a caller waits on a viewer url where nothing listens, and its status."""
    import socket
    from mech_balance.viz import recording
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        port = s.getsockname()[1]
    t0 = time.perf_counter()
    rec = recording.LiveRecorder(None, sc, url=f'rerun+http://127.0.0.1:{port}/proxy')
    init = time.perf_counter() - t0
    worst = 0.0
    for k in range(DEAD_SAMPLES):
        t1 = time.perf_counter()
        rec.log_sample(0.01 * k, 0.05 * k)
        worst = max(worst, time.perf_counter() - t1)
    deadline = time.monotonic() + DEAD_STATUS_WAIT_S
    while not rec.status.startswith('dead') and time.monotonic() < deadline:
        time.sleep(0.02)
    status = rec.status
    t2 = time.perf_counter()
    rec.close(timeout_s=1.0)
    return {'init_s': init, 'log_worst_s': worst, 'close_s': time.perf_counter() - t2,
            'status': status}
