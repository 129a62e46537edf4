"""
The recording bench section of ``mech-balance bench``.

One Hoeken recording, original against seed 001's a(2) design, written to a temporary file.
"""

from pathlib import Path
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
             f'{dead["close_s"] * 1e3:.2f} ms; status: {dead["status"]}']
    return '\n'.join(lines)


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
