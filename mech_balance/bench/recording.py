"""
The recording bench section of ``mech-balance bench``.

One Hoeken recording, original against seed 001's a(2) design, written to a temporary file;
then ``mech-balance record`` of every built-in as a user runs it (``--balance``, and the
carpet scraper and Hoeken with ``--counterweights``), each a process of its own whose whole
CPU time (imports, balancing, recording) is held against :data:`RECORD_CPU_LIMIT_S`.
"""

from pathlib import Path
import resource
import subprocess
import sys
import tempfile
import time

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
"""Besides every built-in with ``--balance``: these counterweight recordings."""
RECORD_TIMEOUT_S = 300.0
"""A ``record`` process is stopped after this long (a hang is a FAIL, not a wait)."""


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
    lines = [f'record (rerun file): hoeken original + seed 001 a(2), 1 turn at {BENCH_SAMPLES} '
             'samples;', f'median of {repeat} runs after {bench.WARMUP} warm-up runs'
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
    lines += record_cpu_table(progress, getattr(args, 'scene', None))
    return '\n'.join(lines)


def record_runs(scenes=None):
    """
    Return the ``mech-balance record`` runs timed: ``[(label, scene, extra argv)]``.

    ``scenes``: only these built-ins (``bench --scene``); None or empty: every one.
    """
    runs = [(f'{name} --balance', name, ('--balance',)) for name in scene.builtin_scenes()]
    runs += [(f'{name} {" ".join(extra)}', name, extra) for name, extra in RECORD_EXTRA_RUNS]
    return [r for r in runs if not scenes or r[1] in scenes]


def record_cpu(name, extra, out):
    """
    Return ``(cpu_s, wall_s, returncode)`` of one ``mech-balance record`` process.

    The CPU time is the child's user + system time (``getrusage(RUSAGE_CHILDREN)`` before
    and after): the whole process, the interpreter's start and the imports included.
    """
    argv = [sys.executable, '-m', 'mech_balance.cli', 'record', '--scene', name, *extra,
            '--out', str(out)]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    try:
        code = subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              timeout=RECORD_TIMEOUT_S).returncode
    except subprocess.TimeoutExpired:
        code = None
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, wall, code


def record_cpu_table(progress, scenes=None):
    """Return the lines of the table of ``mech-balance record`` CPU times, one run each."""
    lines = [f'mech-balance record, one process each (CPU s = user + system of the whole '
             f'process; limit {RECORD_CPU_LIMIT_S:g} s):',
             f'{"run":<44}{"CPU s":>8}{"wall s":>9}  verdict', '-' * 70]
    with tempfile.TemporaryDirectory() as tmp:
        for label, name, extra in record_runs(scenes):
            progress(f'  timing record {label} ...')
            cpu, wall, code = record_cpu(name, extra, Path(tmp) / f'{name}.rrd')
            if code != 0:
                verdict = f'FAIL (exit {code})'
            else:
                verdict = 'PASS' if cpu <= RECORD_CPU_LIMIT_S else 'FAIL'
            lines.append(f'{label:<44}{cpu:>8.2f}{wall:>9.2f}  {verdict}')
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
