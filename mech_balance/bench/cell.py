"""
``mech-balance bench`` section of a cell: how many rig nodes at 100 Hz this machine sustains.

N nodes under ``/cell/rig_1`` .. ``/cell/rig_N``, N growing through :data:`STEPS` while
sustained (< :data:`MISSED_MAX` missed periods), within :data:`TIME_BUDGET_S`; every
process is stopped.  docs/benchmarks.md#a-cell-of-rigs.
"""

import os
import signal
import subprocess
import time

from mech_balance.bench import settle
from mech_balance.bench.node import missed_fraction, stamp_ns, start_node

RATE_HZ = 100.0
"""Clock-mode publish rate of every rig of the cell."""
STEPS = (1, 2, 4, 8, 12, 16, 24, 32)
"""Cell sizes tried, ascending; the last is the cap."""
MISSED_MAX = 0.01
"""A rig keeps up when less than this fraction of its periods is missed."""
WINDOW_S = 5.0
"""Measuring window per step (500 periods per rig at 100 Hz)."""
SETTLE_S = 2.0
"""Time after the last rig of a step delivers its first samples, before measuring."""
IN_FLIGHT_S = 0.05
"""Samples stamped this close to the end of a window may still be on their way."""
START_TIMEOUT_S = 120.0
"""Upper bound for the rigs of one step to start and deliver samples."""
TIME_BUDGET_S = 300.0
"""Upper bound of the whole search (no step is started past it)."""
STOP_TIMEOUT_S = 20.0
"""Time the rigs get to stop after SIGINT before they are killed."""
FIRST_SAMPLES = 5
"""Samples a new rig must deliver before the step is measured."""
NAMESPACE = '/cell/rig_{}'
DOMAIN_BASE, DOMAIN_SPAN = 55, 6
"""The cell runs on ROS domain DOMAIN_BASE + pid % DOMAIN_SPAN (away from the tests')."""
_CLOCK_TICK_S = 1.0 / os.sysconf('SC_CLK_TCK')


def process_cpu_s(pid):
    """Return the user + system CPU time of process ``pid`` so far, s (``/proc/pid/stat``)."""
    fields = settle.stat_fields(pid)   # state is field 3, utime and stime 14 and 15
    return (int(fields[11]) + int(fields[12])) * _CLOCK_TICK_S


def bench_section(args, progress):
    """Return the cell table: the largest N of rigs at 100 Hz, and the per-rig CPU."""
    name = (args.scene or ['hoeken'])[0]
    head = (f"{'rigs':>5}{'worst missed':>14}{'mean missed':>13}{'CPU/rig mean':>14}"
            f"{'CPU/rig max':>13}{'CPU all rigs':>14}{'subscriber':>12}  result")
    lines = [f'cell of rig nodes (scene {name}, {RATE_HZ:g} Hz each, namespaces '
             f'{NAMESPACE.format("k")}, each in its own process; subscriber here; '
             f'{WINDOW_S:g} s window per step; sustained = every rig < {MISSED_MAX:.0%} '
             'missed periods; CPU in % of one core)', '', head, '-' * len(head)]
    t0 = time.monotonic()
    try:
        rows, end = _search(name, progress)
    except (RuntimeError, OSError) as exc:
        return '\n'.join(lines[:1] + [f'not measured ({exc})'])
    best = None
    for n, missed, cpu, own in rows:
        ok = max(missed) < MISSED_MAX
        best = (n, cpu) if ok else best
        lines.append(f'{n:>5}{max(missed):>13.2%} {sum(missed) / n:>12.2%} '
                     f'{100 * sum(cpu) / n:>13.1f} {100 * max(cpu):>12.1f} '
                     f'{100 * sum(cpu):>13.1f} {100 * own:>11.1f}  '
                     f'{"sustained" if ok else "missed periods"}')
    load = os.getloadavg()
    if best:
        lines.append(f'largest cell sustained: {best[0]} rigs at {RATE_HZ:g} Hz, '
                     f'{100 * sum(best[1]) / best[0]:.1f}% of one core per rig ({end}, after '
                     f'{time.monotonic() - t0:.0f} s); machine: {os.cpu_count()} CPUs shared '
                     f'with whatever else runs, load average {load[0]:.2f} at the end')
    else:
        lines.append(f'no cell size sustained ({end})')
    return '\n'.join(lines)


def _search(scene_name, progress):
    """Return ``([(n, missed per rig, CPU per rig, CPU here)], why it ended)``, CPU in cores."""
    import rclpy
    from rclpy.experimental import EventsExecutor
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import JointState

    deadline = time.monotonic() + TIME_BUDGET_S
    domain = DOMAIN_BASE + os.getpid() % DOMAIN_SPAN
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = rclpy.create_node(f'cell_probe_{os.getpid()}', context=ctx)
    executor = EventsExecutor(context=ctx)
    executor.add_node(node)
    procs, stamps = [], []
    period_ns = round(1e9 / RATE_HZ)

    def keep(rig_stamps):
        return lambda raw: rig_stamps.append(stamp_ns(raw))

    def spin_for(seconds, until=None):
        end = time.monotonic() + seconds
        while time.monotonic() < end and not (until and until()):
            executor.spin_once(timeout_sec=0.01)

    def measure():
        start = node.get_clock().now().nanoseconds
        cpu0 = [process_cpu_s(p.pid) for p in procs]
        own0 = process_cpu_s(os.getpid())
        t0 = time.monotonic()
        for s in stamps:
            s.clear()
        spin_for(WINDOW_S)
        wall = time.monotonic() - t0
        cpu = [(process_cpu_s(p.pid) - c) / wall for p, c in zip(procs, cpu0)]
        own = (process_cpu_s(os.getpid()) - own0) / wall
        stop = node.get_clock().now().nanoseconds - int(IN_FLIGHT_S * 1e9)
        return [missed_fraction(s, start, stop, period_ns) for s in stamps], cpu, own

    rows, end = [], f'cap of {STEPS[-1]} rigs reached'
    try:
        for n in STEPS:
            if time.monotonic() + SETTLE_S + 2 * WINDOW_S > deadline:
                end = f'time bound of {TIME_BUDGET_S:g} s reached'
                break
            progress(f'  cell: {n} rigs ...')
            while len(procs) < n:
                k = len(procs) + 1
                ns = NAMESPACE.format(k)
                procs.append(start_node(scene_name, RATE_HZ, ns, domain))
                stamps.append([])
                node.create_subscription(JointState, f'{ns}/joint_states', keep(stamps[-1]),
                                         QoSProfile(depth=1000), raw=True)
            spin_for(min(START_TIMEOUT_S, max(0.0, deadline - time.monotonic())),
                     lambda: all(len(s) >= FIRST_SAMPLES for s in stamps) or
                     any(p.poll() is not None for p in procs))
            dead = [i + 1 for i, p in enumerate(procs) if p.poll() is not None]
            if dead or not all(len(s) >= FIRST_SAMPLES for s in stamps):
                end = (f'rig {dead[0]} exited' if dead else
                       f'the rigs of step {n} did not all deliver samples in time')
                break
            spin_for(SETTLE_S)
            missed, cpu, own = measure()
            if max(missed) >= MISSED_MAX and time.monotonic() + WINDOW_S < deadline:
                missed, cpu, own = measure()   # once more: a burst elsewhere is not the cell
            rows.append((n, missed, cpu, own))
            if max(missed) >= MISSED_MAX:
                end = f'{n} rigs not sustained'
                break
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
        _stop(procs)
    return rows, end


def _stop(procs):
    """Stop every process: SIGINT, wait, then kill what is left."""
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
    end = time.monotonic() + STOP_TIMEOUT_S
    for p in procs:
        try:
            p.wait(timeout=max(0.1, end - time.monotonic()))
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
