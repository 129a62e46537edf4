"""Wall-clock medians: the one timing helper of ``bench`` and ``accuracy`` (tests never time)."""

import statistics
import time

WARMUP = 3
"""Runs discarded before timing (caches, branch tracing, allocator)."""
DEFAULT_REPEAT = 50
"""Timed runs per figure; the median is reported."""


def median_seconds(fn, repeat=DEFAULT_REPEAT, warmup=WARMUP):
    """Return the median wall time of ``fn()`` over ``repeat`` runs after ``warmup`` runs."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)
