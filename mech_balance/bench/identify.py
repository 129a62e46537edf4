"""The identification bench section of ``mech-balance bench``: identify on 60 s of 1 kHz data."""

import math

from mech_balance import schema as scene_mod
from mech_balance.analysis import cycle as analysis, identify
from mech_balance.bench.core import median_and_result
import numpy as np

BENCH_SCENE = 'hoeken'
BENCH_SECONDS = 60.0
BENCH_RATE_HZ = 1000.0
BENCH_LIMIT_S = 2.0
"""The identification of 60 s at 1 kHz must take at most this long (median)."""
BENCH_REPEAT_MAX = 5
"""Most timed runs (each takes about a second)."""


def rippled_crank(t, w0=2.0 * math.pi, psi0=0.0):
    """Return ``(psi, speed, accel)`` at times ``t``: ``w0`` with a 5 % ripple at 0.7 ``|w0|``."""
    wr = 0.7 * abs(w0)
    return (psi0 + w0 * t + w0 * 0.05 * (1.0 - np.cos(wr * t)) / wr,
            w0 * (1.0 + 0.05 * np.sin(wr * t)), w0 * 0.05 * wr * np.cos(wr * t))


def bench_data(sc, seconds=BENCH_SECONDS, rate_hz=BENCH_RATE_HZ, seed=0):
    """
    Return synthetic (t, position, wrench) of the scene itself for the bench (not a test).

    1 rev/s with 5% ripple, a 4096-count wrapping encoder, the shaking wrench plus 1% noise.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * rate_hz)) / rate_hz
    psi, speed, accel = rippled_crank(t)
    _, w = analysis.Rig(sc).evaluate(np.mod(psi, 2.0 * math.pi), outputs=('shaking_wrench',),
                                     speed=speed, accel=accel)
    wrench = np.column_stack([w.shaking_force.real, w.shaking_force.imag, w.shaking_moment])
    wrench += rng.normal(size=wrench.shape) * 0.01 * np.max(np.abs(wrench), axis=0)
    q = 2.0 * math.pi / 4096
    return t, np.mod(np.floor(psi / q) * q, 2.0 * math.pi), wrench


def bench_section(args, progress):
    """Return the bench table of :func:`identify.identify` on 60 s of 1 kHz data."""
    repeat = min(int(args.repeat), BENCH_REPEAT_MAX)
    sc = scene_mod.load(BENCH_SCENE)
    progress(f'  timing identify {BENCH_SCENE} on {BENCH_SECONDS:g} s at '
             f'{BENCH_RATE_HZ:g} Hz ...')
    t, pos, wrench = bench_data(sc)
    sec, r = median_and_result(lambda: identify.identify(sc, t, pos, t, wrench), repeat,
                               warmup=1)
    head = (f"{'identify: scene':<18}{'samples':>9}{'rank':>6}{'cond':>10}{'median s':>10}"
            f"{'limit s':>9}  verdict")
    return '\n'.join([
        f'identify (encoder step, smoothing, regressor, SVD, consistency): median of {repeat} '
        f'runs after 1 warm-up run, {BENCH_SECONDS:g} s of synthetic data at {BENCH_RATE_HZ:g} Hz',
        head, '-' * len(head),
        f'{BENCH_SCENE:<18}{r.samples:>9}{r.rank:>6}{r.condition_number:>10.4g}{sec:>10.3f}'
        f"{BENCH_LIMIT_S:>9.1f}  {'ok' if sec <= BENCH_LIMIT_S else 'TOO SLOW'}"])
