"""
The ``follow_memory`` section of ``mech-balance bench``: the node's memory over a long follow run.

What it measures: docs/benchmarks.md#how-the-node-sections-measure.
"""

import math
import os
import time

SECONDS = 90.0
"""Length of the run, s of wall time (the identify buffers hold 120 s at 1 kHz)."""
RATE_HZ = 1000.0
"""Encoder and measured-wrench rate."""
SAMPLE_EVERY_S = 5.0
"""RSS sampling period."""
SETTLED_S = 5.0
"""The growth is judged from this long after the stream starts (every buffer fed by then)."""
CHUNK_S = 0.01
"""Messages are published in chunks of this much of the rig's clock, paced by wall time."""
SPEED_RAD_S = 2.0 * math.pi
"""The fed crank's speed (one turn a second)."""


def follow_rss(scene_name='hoeken', seconds=SECONDS, rate_hz=RATE_HZ, progress=print):
    """
    Return ``(samples, counts)``: ``[(s since the stream began, RSS bytes)]`` and the stats.

    ``counts``: the node's ``follow`` statistics or ``{}``; ``(None, why)`` if it did not start.
    """
    from mech_balance.bench.identify_stamps import SensorFeed
    from mech_balance.bench.node import node_stats, NodeProbe, START_TIMEOUT_S, status_bytes

    probe = NodeProbe(scene_name, 100.0, f'/followmem{os.getpid()}', ('mode:=follow',),
                      label='followmem')
    log = ''
    try:
        feed = SensorFeed(probe)
        probe.spin_for(START_TIMEOUT_S, lambda: feed.matched() or probe.proc.poll() is not None)
        if not feed.matched():
            return None, 'the node did not start or its endpoints did not match'
        pid = probe.proc.pid
        samples = [(0.0, status_bytes(pid))]
        period_ns = int(round(1e9 / rate_hz))
        per_chunk = max(1, int(round(CHUNK_S * rate_hz)))
        t0_ns = probe.node.get_clock().now().nanoseconds
        start = time.monotonic()
        k = 0
        next_sample = SAMPLE_EVERY_S
        progress(f'    streaming {seconds:g} s of encoder and wrench at {rate_hz:g} Hz ...')
        while True:
            elapsed = time.monotonic() - start
            if elapsed >= seconds:
                break
            due = int(elapsed * rate_hz) + per_chunk
            while k < due:
                angle = math.fmod(SPEED_RAD_S * k / rate_hz, 2.0 * math.pi)
                feed.publish(t0_ns + k * period_ns, angle, (math.cos(angle), math.sin(angle), 0.0),
                             (0.0, 0.0, 0.0))
                k += 1
            if elapsed >= next_sample:
                samples.append((elapsed, status_bytes(pid)))
                next_sample += SAMPLE_EVERY_S
            probe.spin_for(CHUNK_S)
        samples.append((time.monotonic() - start, status_bytes(pid)))
    finally:
        log = probe.close(timeout=60)
    return samples, node_stats(log).get('follow', {})


def follow_memory_section(args, progress):
    """Return the ``follow_memory`` table (a ``mech-balance bench`` section)."""
    name = (getattr(args, 'scene', None) or ['hoeken'])[0]
    head = (f'rig node memory in follow mode: {name}, encoder and measured wrench at '
            f'{RATE_HZ:g} Hz for {SECONDS:g} s (RSS, /proc/PID/status VmRSS), the identify '
            'buffers allocated at their first sample (issue 32 item 3)')
    progress('  rig node memory in follow mode ...')
    samples, counts = follow_rss(name, seconds=SECONDS, progress=progress)
    if samples is None:
        return '\n'.join([head, f'not measured: {counts}'])
    lines = [head, f'{"t (s)":>8}{"RSS (MB)":>12}']
    lines += [f'{t:>8.1f}{rss / 2 ** 20:>12.2f}' for t, rss in samples]
    settled = [rss for t, rss in samples if t >= SETTLED_S]
    if len(settled) >= 2:
        lines.append(f'growth from {SETTLED_S:g} s to the end: '
                     f'{(settled[-1] - settled[0]) / 2 ** 20:+.2f} MB (largest step '
                     f'{max(b - a for a, b in zip(settled, settled[1:])) / 2 ** 20:+.2f} MB, '
                     f'range {(max(settled) - min(settled)) / 2 ** 20:.2f} MB); from the '
                     f'start: {(samples[-1][1] - samples[0][1]) / 2 ** 20:+.2f} MB')
    if counts:
        lines.append(f'encoder samples received {counts.get("received")}, not answered '
                     f'{counts.get("unanswered")}')
    return '\n'.join(lines)


if __name__ == '__main__':
    import sys
    SECONDS = float(sys.argv[1]) if len(sys.argv) > 1 else SECONDS
    print(follow_memory_section(None, print))
