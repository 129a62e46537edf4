"""
``mech-balance bench`` sections of the rig node: publish rate, step time, live view, faults.

The node runs in its own process (:class:`NodeProbe`); follow mode is timed in this one
(:class:`FollowPath`); docs/benchmarks.md#how-the-node-sections-measure.
"""

import functools
import json
import os
import re
import signal
import struct
import subprocess
import sys
import time

from mech_balance.ros import node as node_mod

RATES_HZ = (250.0, 500.0, 1000.0, 2000.0, 4000.0, 8000.0, 16000.0)
"""Clock-mode publish rates tried, ascending."""
MISSED_MAX = 0.01
"""A rate is sustained when less than this fraction of its periods is missed on each topic."""
WINDOW_S = 3.0
"""Measuring window per rate."""
SETTLE_S = 0.5
"""Time after a rate change before measuring."""
IN_FLIGHT_S = 0.05
"""Samples stamped this close to the end of a window may still be on their way: not counted."""
START_TIMEOUT_S = 60.0
"""Upper bound for the node process to start and be discovered."""
STAMP = struct.Struct('<iI')
"""builtin_interfaces/Time at the start of a CDR-serialized message with a header."""
CDR_HEADER = 4
"""Bytes of the CDR encapsulation header before the first field."""
TARGET_RATE_HZ = 1000.0
"""The issue's target: sustained publish rate, and the rate of the per-callback timing."""
TARGET_STEP_S = 100e-6
"""The issue's target: compute time per callback (sample)."""
TARGET_FOLLOW_ALONE_S = 100e-6
"""Issue 22 item 3: follow mode, compute for an encoder sample that arrives alone."""
TARGET_FOLLOW_BATCHED_S = 30e-6
"""Issue 22 item 3: follow mode, compute per sample in batches (FOLLOW_BATCH)."""
TARGET_CLOCK_COMPUTE_S = 10e-6
"""Issue 22 item 3: clock mode, compute per sample at TARGET_RATE_HZ."""
TARGET_SUSTAINED_HZ = 8000.0
"""Issue 22 item 3: the rate sustained (as today)."""
FOLLOW_BATCH = 8
"""Follow mode: the batch size reported next to a single sample."""
FOLLOW_REPEAT = 50
"""Timed follow-mode evaluations (median)."""
STATS_S = 5.0
"""Run at the target rate before shutdown (the node's statistics cover it alone)."""


def bench_section(args, progress):
    """Return the rig node's bench table (rates, missed periods, step and core times)."""
    names = list(args.scene or ['hoeken'])
    lines = [f'rig node (clock mode, node in its own process, subscriber here; {WINDOW_S:g} s '
             f'per rate, sustained = < {MISSED_MAX:.0%} missed periods on both topics)']
    head = f"{'scene':<16}{'rate Hz':>9}{'joint_states':>14}{'shaking_wrench':>16}  result"
    for name in names:
        progress(f'  rig node: {name} ...')
        try:
            rows, stats = _sweep(name, progress)
        except (RuntimeError, OSError) as exc:
            lines.append(f'{name}: not measured ({exc})')
            continue
        lines += ['', head, '-' * len(head)]
        follow = _follow_costs(name)
        exact = _follow_costs(name, exact=True)
        best = None
        for rate, joint, wrench in rows:
            ok = joint < MISSED_MAX and wrench < MISSED_MAX
            best = rate if ok else best
            lines.append(f'{name:<16}{rate:>9.0f}{joint:>13.2%} {wrench:>15.2%}  '
                         f'{"sustained" if ok else "missed periods"}')
        step = stats.get('step_median_s', float('nan'))
        compute = stats.get('prepare_per_sample_s', float('nan'))
        lines += [
            f'highest sustained rate: {best:g} Hz' if best else 'no rate sustained',
            f'per callback at {TARGET_RATE_HZ:g} Hz: compute {compute * 1e6:.1f} us (core '
            'evaluation and serialization of both messages, batched ahead in a second thread); '
            f'publishing {step * 1e6:.1f} us median, p99 '
            f'{stats.get("step_p99_s", float("nan")) * 1e6:.1f} us (the tick: two rclpy '
            'publish calls of the prepared bytes, middleware delivery included)',
            f'follow mode (compute per encoder message, as the node does it: the encoder '
            f'callback, then the evaluation and both messages serialized): '
            f'{follow[0] * 1e6:.0f} us for a sample alone, {follow[1] * 1e6:.0f} us per sample '
            f'in batches of {FOLLOW_BATCH} (the node batches what arrived during the last '
            f'evaluation); {follow[2]}',
            f'follow mode with follow.exact (the core per sample): {exact[0] * 1e6:.0f} us '
            f'alone, {exact[1] * 1e6:.0f} us per sample in batches of {FOLLOW_BATCH}',
            f'target: >= {TARGET_RATE_HZ:g} Hz sustained '
            f'{"met" if best and best >= TARGET_RATE_HZ else "NOT met"}; '
            f'<= {TARGET_STEP_S * 1e6:g} us compute per callback '
            f'{"met" if compute <= TARGET_STEP_S else "NOT met"}',
            'issue 22 targets: ' + '; '.join(
                f'{what} <= {limit * 1e6:g} us {"met" if value <= limit else "NOT met"}'
                for what, value, limit in (
                    ('follow alone', follow[0], TARGET_FOLLOW_ALONE_S),
                    ('follow batched', follow[1], TARGET_FOLLOW_BATCHED_S),
                    (f'clock compute at {TARGET_RATE_HZ:g} Hz', compute,
                     TARGET_CLOCK_COMPUTE_S))) +
            f'; >= {TARGET_SUSTAINED_HZ:g} Hz sustained '
            f'{"met" if best and best >= TARGET_SUSTAINED_HZ else "NOT met"}',
        ]
    return '\n'.join(lines)


def _follow_costs(scene_name, exact=False):
    """Return the compute per encoder message in follow mode: alone, in a batch, and what it is."""
    from mech_balance.analysis.timing import median_seconds
    path = FollowPath(scene_name, exact)
    try:
        times = []
        for n in (1, FOLLOW_BATCH):
            path.run(n)
            times.append(median_seconds(lambda n=n: path.run(n), repeat=FOLLOW_REPEAT) / n)
        return times[0], times[1], path.evaluation()
    finally:
        path.close()


class FollowPath:
    """The rig node's follow-mode objects in this process, its threads stopped (for timing)."""

    def __init__(self, scene_name, exact=False, messages=None):
        import math
        import rclpy
        from sensor_msgs.msg import JointState
        from mech_balance.ros import conversions as conv, guard, live, params
        from mech_balance.ros import parameters as node_params, publisher, real_rig
        from mech_balance.ros.rig_state import RigState
        self.ctx = rclpy.Context()
        domain = os.environ.get('ROS_DOMAIN_ID', '')
        rclpy.init(context=self.ctx, domain_id=int(domain) if domain.isdigit() else
                   101 - os.getpid() % 50)   # nothing is published: discovery only
        self.node = rclpy.create_node(f'bench_follow_{os.getpid()}', context=self.ctx)
        values = dict(params.defaults(), scene=scene_name, mode='follow')
        values['follow.exact'] = bool(exact)
        model = node_params.build_model(scene_name)
        self.state = state = RigState(values, model)

        def warn(text):
            self.node.get_logger().warning(text, throttle_duration_sec=2.0)
        self.guard = guard.Guard(warn)
        self.recording = live.Recording(lambda level, text: None, make=None)

        def record(samples, turned_rad, stamps_ns):  # the node's recording hook (inactive)
            self.recording.push(samples, turned_rad, stamps_ns,
                                original=state.published is state.original)
        parts = {}
        self.publisher = publisher.Publisher(
            self.node, state, self.guard, warn, record,
            on_encoder=lambda *a: parts['rig'].on_encoder(*a))
        parts['rig'] = self.rig = real_rig.RealRig(self.node, state, self.guard, warn,
                                                   self.publisher)
        self.publisher.streamer.stop()
        self.publisher.apply_mode()
        if not exact:
            model.cycle_table()  # built (the node builds it in a thread of its own)
        self.model = model
        speed = model.scene.crank_speed_rad_s or 2.0 * math.pi
        crank = values['crank_joint'] or model.crank_joint
        from mech_balance.analysis.timing import WARMUP
        if messages is None:  # what _follow_costs delivers (stamps never go back)
            messages = (FOLLOW_REPEAT + WARMUP + 1) * (1 + FOLLOW_BATCH) + 16
        self.messages = []
        for k in range(messages):
            msg = JointState(name=[crank], position=[(0.3 + speed * k * 1e-3) % (2 * math.pi)])
            msg.header.stamp = conv.stamp_from_ns(1_000_000_000_000 + k * 1_000_000)
            self.messages.append(msg)
        self._next = 0

    def run(self, n):
        """Deliver the next ``n`` encoder messages, then evaluate and prepare the batch."""
        streamer = self.publisher.streamer
        if self._next + n > len(self.messages):
            raise RuntimeError(f'FollowPath: the {len(self.messages)} encoder messages made '
                               'ahead are used up')
        for msg in self.messages[self._next:self._next + n]:
            self.publisher.on_encoder(msg)
        self._next += n
        batch = list(streamer._pending)
        streamer._pending.clear()
        return streamer._evaluate_follow(self.model, batch) if batch else []

    def evaluation(self):
        """Return what follow mode evaluates (the model status's ``evaluation``)."""
        return self.publisher.follow_evaluation()

    def close(self):
        """Stop the parts and the node."""
        import rclpy
        self.recording.close()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)


def start_node(scene_name, rate_hz, ns, domain, params=(), stderr=subprocess.DEVNULL):
    """Start ``python -m mech_balance.ros.node`` (clock mode) in a process of its own."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED='1',
               ROS_AUTOMATIC_DISCOVERY_RANGE=os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE',
                                                            'LOCALHOST'))
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    env['PYTHONPATH'] = os.pathsep.join(p for p in (root, env.get('PYTHONPATH')) if p)
    cmd = [sys.executable, '-m', 'mech_balance.ros.node', '--ros-args', '-r', f'__ns:={ns}',
           '-p', f'scene:={scene_name}', '-p', f'publish_rate:={rate_hz}']
    for p in params:
        cmd += ['-p', p]
    return subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=stderr, text=True)


def stamp_ns(raw):
    """Return the header stamp of a serialized message, ns (read without deserializing)."""
    sec, nsec = STAMP.unpack_from(raw, CDR_HEADER)
    return sec * 1_000_000_000 + nsec


def status_bytes(pid, key='VmRSS'):
    """Return ``key`` (``VmRSS``, ``VmHWM``) of /proc/PID/status in bytes."""
    with open(f'/proc/{pid}/status') as f:
        for line in f:
            if line.startswith(key + ':'):
                return int(line.split()[1]) * 1024
    raise RuntimeError(f'/proc/{pid}/status has no {key}')


class NodeProbe:
    """A rig node in its own process (:func:`start_node`) and a subscriber counting its stamps."""

    def __init__(self, scene_name, rate_hz, ns, params=(), domain=None, label='bench'):
        import rclpy
        from rclpy.experimental import EventsExecutor
        from rclpy.qos import QoSProfile
        from sensor_msgs.msg import JointState
        from geometry_msgs.msg import WrenchStamped

        self.ns = ns
        self.domain = (101 - os.getpid() % 50) if domain is None else domain
        self.proc = start_node(scene_name, rate_hz, ns, self.domain, params, subprocess.PIPE)
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=self.domain)
        self.node = rclpy.create_node(f'{label}_probe_{os.getpid()}', context=self.ctx)
        self.executor = EventsExecutor(context=self.ctx)
        self.executor.add_node(self.node)
        self.stamps = {'joint_states': [], 'shaking_wrench': []}

        def keep(got):
            return lambda raw: got.append(stamp_ns(raw))

        for msg_type, key in ((JointState, 'joint_states'), (WrenchStamped, 'shaking_wrench')):
            self.node.create_subscription(msg_type, f'{ns}/{key}', keep(self.stamps[key]),
                                          QoSProfile(depth=1000), raw=True)

    def spin_for(self, seconds, until=None):
        """Spin the subscriber for ``seconds`` or until ``until()`` is true."""
        end = time.monotonic() + seconds
        while time.monotonic() < end and not (until and until()):
            self.executor.spin_once(timeout_sec=0.01)

    def publishing(self):
        """Return whether both topics have arrived (and the node still runs)."""
        return self.proc.poll() is None and all(len(v) > 10 for v in self.stamps.values())

    def parameter_client(self):
        """Return a parameter client of the node once it publishes; RuntimeError if it never."""
        from rclpy.parameter_client import AsyncParameterClient
        client = AsyncParameterClient(self.node, f'{self.ns}/rig')
        self.spin_for(START_TIMEOUT_S, lambda: client.services_are_ready() and
                      self.publishing() or self.proc.poll() is not None)
        if self.proc.poll() is not None or not client.services_are_ready():
            raise RuntimeError('the node did not start or was not discovered')
        return client

    def measure(self, seconds, period_ns, spin=None):
        """
        Count afresh for ``seconds`` (``spin(seconds)`` spins instead, if given).

        Returns ``(missed fraction per topic, joint_states per s, what spin returned)``.
        """
        start = self.node.get_clock().now().nanoseconds
        for v in self.stamps.values():
            v.clear()
        result = spin(seconds) if spin else self.spin_for(seconds)
        stop = self.node.get_clock().now().nanoseconds - int(IN_FLIGHT_S * 1e9)
        missed = [missed_fraction(v, start, stop, period_ns) for v in self.stamps.values()]
        got = {s for s in self.stamps['joint_states'] if start <= s < stop}
        return missed, len(got) / ((stop - start) * 1e-9), result

    def close(self, timeout=20):
        """Stop the subscriber and the node (SIGINT, then kill); return the node's log."""
        import rclpy
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        try:
            _, err = self.proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            _, err = self.proc.communicate()
        return err or ''


def node_stats(log):
    """Return the node's statistics logged at shutdown (:data:`node_mod.STATS_TAG`)."""
    match = re.search(re.escape(node_mod.STATS_TAG) + r'(\{.*\})', log)
    return json.loads(match.group(1)) if match else {}


def _sweep(scene_name, progress):
    from rclpy.parameter import Parameter
    probe = NodeProbe(scene_name, RATES_HZ[0], f'/bench{os.getpid()}')
    rows = []
    try:
        client = probe.parameter_client()
        failures = 0
        for rate in RATES_HZ:
            future = client.set_parameters([Parameter('publish_rate', value=rate)])
            probe.spin_for(10.0, future.done)
            if not (future.done() and future.result().results[0].successful):
                raise RuntimeError(f'could not set publish_rate to {rate:g}')
            progress(f'    {rate:g} Hz ...')
            probe.spin_for(SETTLE_S)
            missed, _, _ = probe.measure(WINDOW_S, round(1e9 / rate))
            rows.append((rate, *missed))
            failures = failures + 1 if max(missed) >= MISSED_MAX else 0
            if failures >= 2:
                break
        # the node's own statistics (logged at shutdown) at the target rate
        future = client.set_parameters([Parameter('publish_rate', value=TARGET_RATE_HZ)])
        probe.spin_for(10.0, future.done)
        progress(f'    per-callback time at {TARGET_RATE_HZ:g} Hz ...')
        probe.spin_for(STATS_S)
    finally:
        log = probe.close()
    return rows, node_stats(log)


def missed_fraction(stamps, start_ns, stop_ns, period_ns):
    """Return the fraction of periods in [start, stop) whose stamp was not received."""
    inside = {s for s in stamps if start_ns <= s < stop_ns}
    if not inside:
        return 1.0
    first = min(inside)
    expected = (stop_ns - 1 - first) // period_ns + 1
    return max(0.0, 1.0 - len(inside) / expected)


LIVE_RATE_HZ = 1000.0
"""The rate of the live-view comparison (the node's target rate)."""
LIVE_WINDOW_S = 4.0
"""Measuring window of each run of the live-view comparison."""


def viewer_endpoint(path, port):
    """Start ``rerun --port PORT --save PATH``; return the process once its port accepts."""
    import pathlib
    import socket
    import rerun_cli
    exe = pathlib.Path(rerun_cli.__file__).parent / 'rerun'
    proc = subprocess.Popen([str(exe), '--port', str(port), '--save', str(path)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + START_TIMEOUT_S
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            with socket.create_connection(('127.0.0.1', port), timeout=0.2):
                return proc
        except OSError:
            time.sleep(0.05)
    proc.kill()
    raise RuntimeError(f'rerun --port {port} --save {path} did not start listening')


def free_port():
    """Return a TCP port free on this machine now."""
    import socket
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def run_node(scene_name, rate_hz, seconds, params=(), domain=None):
    """
    Run the node in its own process at ``rate_hz`` and measure ``seconds`` of publishing.

    Returns ``{'rate_hz', 'missed', 'stats', 'log'}`` (joint_states per s, worst missed share).
    """
    probe = NodeProbe(scene_name, rate_hz,
                      f'/live{os.getpid()}_{int(time.monotonic() * 1000) % 100000}', params,
                      domain, label='live')
    try:
        probe.spin_for(START_TIMEOUT_S,
                       lambda: probe.publishing() or probe.proc.poll() is not None)
        if not probe.publishing():
            raise RuntimeError('the node did not start or was not discovered')
        probe.spin_for(SETTLE_S)
        missed, rate, _ = probe.measure(seconds, round(1e9 / rate_hz))
    finally:
        log = probe.close(timeout=30)
    return {'rate_hz': rate, 'missed': max(missed), 'stats': node_stats(log), 'log': log}


def live_view_section(args, progress):
    """Return the node's publishing with and without the live view (``rerun_url``)."""
    import tempfile
    name = (getattr(args, 'scene', None) or ['hoeken'])[0]
    lines = [f'rig node with the live view (rerun_url to a `rerun --save` endpoint) against '
             f'without: {name}, clock mode at {LIVE_RATE_HZ:g} Hz, {LIVE_WINDOW_S:g} s each',
             f"{'run':<22}{'rate Hz':>10}{'missed':>9}{'compute us':>12}{'tick us':>9}"
             f"{'tick p99 us':>13}", '-' * 75]
    with tempfile.TemporaryDirectory() as tmp:
        port = free_port()
        viewer = viewer_endpoint(os.path.join(tmp, 'live.rrd'), port)
        try:
            runs = []
            for label, extra in (('without live view', ()),
                                 ('with live view', (f'rerun_url:=rerun+http://127.0.0.1:'
                                                     f'{port}/proxy',))):
                progress(f'  rig node {label} ...')
                runs.append((label, run_node(name, LIVE_RATE_HZ, LIVE_WINDOW_S, extra)))
        finally:
            viewer.send_signal(signal.SIGINT)
            try:
                viewer.wait(timeout=10)
            except subprocess.TimeoutExpired:
                viewer.kill()
    for label, r in runs:
        st = r['stats']
        lines.append(f"{label:<22}{r['rate_hz']:>10.1f}{r['missed']:>9.2%}"
                     f"{st.get('prepare_per_sample_s', float('nan')) * 1e6:>12.1f}"
                     f"{st.get('step_median_s', float('nan')) * 1e6:>9.1f}"
                     f"{st.get('step_p99_s', float('nan')) * 1e6:>13.1f}")
    ratio = runs[1][1]['rate_hz'] / runs[0][1]['rate_hz'] if runs[0][1]['rate_hz'] else 0.0
    lines.append(f'publishing rate with / without the live view: {ratio:.3f} (the view logs '
                 'at most 30 samples/s on a thread of its own)')
    return '\n'.join(lines)


FAULT_RATE_HZ = 1000.0
"""The rate of the under-attack runs (the node's target rate)."""
FAULT_WINDOW_S = 3.0
"""Measuring window of each under-attack run."""
FAULT_RATE_TOL = 0.05
"""Issue 23: under attack the rate stays within this fraction of nominal."""
STORM = 320
"""Invalid parameter updates sent at once in the storm run."""
SIMULTANEOUS = 50
"""Calls sent at once to each service in the service run."""
SERVICES = ('tare', 'identify', 'balance', 'reset')


def _storm(probe, params, clients, seconds):
    """Send STORM refused parameter updates at once; spin; return their futures."""
    from rclpy.parameter import Parameter
    bad = [('publish_rate', -1.0), ('frame_id', 'x' * 100_000), ('mode', 'dance'),
           ('balance.weights', [0.0, 0.0]), ('balance.fixed_links', 'crank,crank')]
    futures = [params.set_parameters([Parameter(bad[i % len(bad)][0], value=bad[i % len(bad)][1])])
               for i in range(STORM)]
    probe.spin_for(seconds)
    return futures


def _dead_viewer(probe, params, clients, seconds):
    """Set rerun_url to a port where nothing listens, clear it half-way; return the futures."""
    from rclpy.parameter import Parameter
    url = f'rerun+http://127.0.0.1:{free_port()}/proxy'
    futures = [params.set_parameters([Parameter('rerun_url', value=url)])]
    probe.spin_for(seconds / 2)
    futures.append(params.set_parameters([Parameter('rerun_url', value='')]))
    probe.spin_for(seconds / 2)
    return futures


def _service_calls(probe, params, clients, seconds):
    """Send SIMULTANEOUS calls to each service at once; spin; return their futures."""
    from std_srvs.srv import Trigger
    futures = [c.call_async(Trigger.Request()) for c in clients.values()
               for _ in range(SIMULTANEOUS)]
    probe.spin_for(seconds)
    return futures


def faults_section(args, progress):
    """Return the node's publishing rate under attack (issue 23.2b): within 5 % of nominal."""
    from rclpy.parameter_client import AsyncParameterClient
    from rclpy.qos import QoSProfile
    from std_srvs.srv import Trigger
    name = (getattr(args, 'scene', None) or ['hoeken'])[0]
    ns = f'/faults{os.getpid()}'
    lines = [f'rig node under attack: {name}, clock mode at {FAULT_RATE_HZ:g} Hz, '
             f'{FAULT_WINDOW_S:g} s per run (target: rate within {FAULT_RATE_TOL:.0%} of '
             'nominal, every request answered)',
             f"{'run':<44}{'rate Hz':>9}{'of nominal':>12}{'missed':>8}{'answered':>11}",
             '-' * 84]
    probe = NodeProbe(name, FAULT_RATE_HZ, ns, label='faults')
    try:
        params = AsyncParameterClient(probe.node, f'{ns}/rig',  # a deep request queue
                                      qos_profile=QoSProfile(depth=2 * STORM))
        clients = {s: probe.node.create_client(Trigger, f'{ns}/rig/{s}',
                                               qos_profile=QoSProfile(depth=4 * SIMULTANEOUS))
                   for s in SERVICES}
        probe.spin_for(START_TIMEOUT_S, lambda: probe.publishing() and params.
                       services_are_ready() and all(c.service_is_ready()
                                                    for c in clients.values()))
        if not probe.publishing():
            return '\n'.join(lines + ['not measured: the node did not start'])
        probe.spin_for(SETTLE_S)
        period = round(1e9 / FAULT_RATE_HZ)
        for label, attack in (('quiet', None),
                              (f'parameter storm ({STORM} refused updates)', _storm),
                              ('dead rerun_url set, cleared half-way', _dead_viewer),
                              (f'{SIMULTANEOUS} simultaneous calls on each of 4 services',
                               _service_calls)):
            progress(f'  rig node: {label} ...')
            spin = None if attack is None else functools.partial(attack, probe, params, clients)
            missed, rate, futures = probe.measure(FAULT_WINDOW_S, period, spin)
            missed, futures = max(missed), futures or []
            probe.spin_for(START_TIMEOUT_S, lambda: all(f.done() for f in futures))
            answered = f'{sum(f.done() for f in futures)}/{len(futures)}' if futures else '-'
            lines.append(f'{label:<44}{rate:>9.1f}{rate / FAULT_RATE_HZ:>12.3f}{missed:>8.2%}'
                         f'{answered:>11}')
            probe.spin_for(SETTLE_S)
    finally:
        probe.close(timeout=30)
    return '\n'.join(lines)
