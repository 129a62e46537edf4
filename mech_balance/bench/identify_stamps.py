"""``mech-balance bench`` section: ``~/identify`` after a day-ahead stamp (issue 20)."""

import os
import time

from mech_balance.bench.node import NodeProbe, stamp_ns, START_TIMEOUT_S, status_bytes

ID_RATE_HZ = 1000.0
"""Issue 20: the node's realistic sensor rate (encoder and measured wrench alike)."""
ID_SECONDS = 120.0
"""Stream played before ``~/identify``: the identify buffer's full capacity at ID_RATE_HZ
(:data:`mech_balance.ros.sensor.IDENTIFY_CAPACITY` samples)."""
ID_CALLS = 3
"""``~/identify`` calls timed (median)."""
ID_CRANK_SPEED_RAD_S = 2.0 * 3.141592653589793
"""The synthetic rig's mean crank speed (one turn per second, as the node tests)."""
ID_TARGET_S = 1.0
"""Issue 20 acceptance: ``~/identify`` answers within this after a day-ahead stamp."""
ID_CHUNK = 100
"""Samples published per topic before waiting for the residual two chunks back."""
ID_WAIT_S = 60.0
"""A residual (or an answer) not there this long after it is due: the sensor path locked."""
ID_DAY_NS = 86_400 * 10 ** 9
"""How far ahead the one bad measured_wrench message is stamped."""
ID_CALL_TIMEOUT_S = 300.0
"""Upper bound on one ``~/identify`` call before it is reported unanswered."""


def identify_buffer_bytes():
    """Return the bytes of the bounded buffers of a :class:`mech_balance.ros.sensor.Comparison`."""
    from mech_balance.ros import sensor
    comparison = sensor.Comparison(sensor.SensorPose(), (0.0, 0.0, 0.0), 0.1)
    series = [comparison.track.series, comparison.pending, comparison.measured,
              comparison.paired]
    return sum(s.nbytes for s in series)


def rig_stream(scene, seconds, rate_hz=ID_RATE_HZ, seed=20, counts=4096, noise_rel=0.01,
               w0=ID_CRANK_SPEED_RAD_S):
    """
    Return ``(t_ns, encoder positions, force (n, 3), torque (n, 3))`` of a synthetic rig.

    ``test/synthetic_rig.py``'s rig in brief: crank at ``w0`` with a 5 % ripple, 1 % noise and a
    bias, an encoder of ``counts`` per turn, stamps from a real epoch at ``rate_hz``.
    """
    import math
    import numpy as np
    from mech_balance.analysis import cycle as analysis
    from mech_balance.bench.identify import rippled_crank
    rng = np.random.default_rng(seed)
    n = max(int(round(seconds * rate_hz)), 1)
    t = np.arange(n) / rate_hz
    psi, speed, accel = rippled_crank(t, float(w0), psi0=0.3)
    rig = analysis.Rig(scene.with_outputs(('shaking_wrench',)))
    _, w = rig.evaluate(np.mod(psi, 2.0 * math.pi), outputs=('shaking_wrench',), speed=speed,
                        accel=accel)
    f = np.column_stack([w.shaking_force.real, w.shaking_force.imag, np.zeros(n)])
    pivot = complex(rig.linkage.pivot)
    # the moment about the sensor's origin (the rig frame's): n_0 = n_pivot + pivot x f
    n_z = w.shaking_moment + pivot.real * f[:, 1] - pivot.imag * f[:, 0]
    peak = np.array([np.max(np.abs(w.shaking_force))] * 3 + [np.max(np.abs(n_z))] * 3)
    wrench = np.column_stack([f, np.zeros((n, 2)), n_z])
    wrench += peak * (np.array([0.3, -0.2, 0.0, 0.0, 0.0, 0.25]) * 0.05 +
                      noise_rel * rng.normal(size=(n, 6)) * [1, 1, 0, 0, 0, 1])
    q = 2.0 * math.pi / counts
    positions = np.mod(np.round(psi / q) * q, 2.0 * math.pi)
    t_ns = 1_700_000_000_123_456_789 + np.round(t * 1e9).astype(np.int64)
    return t_ns, positions, wrench[:, :3], wrench[:, 3:]


class SensorFeed:
    """The bench's encoder and measured_wrench publishers, residual stamps, ~/identify."""

    def __init__(self, probe):
        from geometry_msgs.msg import WrenchStamped
        from rclpy.qos import QoSProfile
        from sensor_msgs.msg import JointState
        from std_srvs.srv import Trigger
        self.probe, self.newest, self.residuals = probe, -1, 0
        self.limit_ns = None
        node, ns, qos = probe.node, probe.ns, QoSProfile(depth=1000)
        self.encoder = node.create_publisher(JointState, f'{ns}/crank_joint_state', qos)
        self.measured = node.create_publisher(WrenchStamped, f'{ns}/measured_wrench', qos)
        self.residual = node.create_subscription(WrenchStamped, f'{ns}/wrench_residual',
                                                 self._on_residual, qos, raw=True)
        self.identify = node.create_client(Trigger, f'{ns}/rig/identify')
        self._joint, self._wrench, self._trigger = JointState, WrenchStamped, Trigger

    def _on_residual(self, raw):
        stamp = stamp_ns(raw)
        self.residuals += 1
        if self.limit_ns is None or stamp <= self.limit_ns:  # never the day-ahead one
            self.newest = max(self.newest, stamp)

    def matched(self):
        """Return whether every endpoint of the run matches, the node still running."""
        return (self.probe.proc.poll() is None and self.encoder.get_subscription_count() >= 1
                and self.measured.get_subscription_count() >= 1
                and self.residual.get_publisher_count() >= 1
                and self.identify.service_is_ready())

    def encoder_msg(self, stamp_ns, angle):
        """Return a crank_joint_state message."""
        from mech_balance.ros import conversions as conv
        msg = self._joint(name=['O1'], position=[float(angle)])
        msg.header.stamp = conv.stamp_from_ns(int(stamp_ns))
        return msg

    def wrench_msg(self, stamp_ns, force, torque):
        """Return a measured_wrench message."""
        from mech_balance.ros import conversions as conv
        return conv.fill_wrench_values(self._wrench(), int(stamp_ns), 'sensor',
                                       [*force, *torque])

    def publish(self, stamp_ns, angle, force, torque):
        """Publish one encoder and one measured_wrench message of the same stamp."""
        self.encoder.publish(self.encoder_msg(stamp_ns, angle))
        self.measured.publish(self.wrench_msg(stamp_ns, force, torque))

    def play(self, t_ns, angles, force, torque):
        """
        Publish a segment in chunks, waiting for the residual two chunks back.

        Return ``None``, or what locked: the stamp whose residual never came.
        """
        n = t_ns.size
        for c0 in range(0, n, ID_CHUNK):
            for i in range(c0, min(c0 + ID_CHUNK, n)):
                self.publish(t_ns[i], angles[i], force[i], torque[i])
            back = c0 - ID_CHUNK
            if back > 0:
                target = int(t_ns[back - 1])
                self.probe.spin_for(ID_WAIT_S, lambda: self.newest >= target or
                                    self.probe.proc.poll() is not None)
                if self.newest < target:
                    return target
        return None

    def call_identify(self):
        """Return ``(seconds, success, message)`` of one ``~/identify`` call."""
        t0 = time.perf_counter()
        future = self.identify.call_async(self._trigger.Request())
        self.probe.spin_for(ID_CALL_TIMEOUT_S, lambda: future.done() or
                            self.probe.proc.poll() is not None)
        seconds = time.perf_counter() - t0
        if not future.done():
            return seconds, False, 'unanswered'
        return seconds, future.result().success, future.result().message


def identify_stamps_section(args, progress, seconds=None, calls=ID_CALLS):
    """Return ``~/identify`` after a day-ahead stamp: ``seconds`` streamed, ``calls`` calls."""
    import statistics
    from mech_balance import schema as scene_mod
    from mech_balance.ros import sensor
    seconds = ID_SECONDS if seconds is None else seconds
    name = (getattr(args, 'scene', None) or ['hoeken'])[0]
    bound = identify_buffer_bytes()
    capacity_s = sensor.IDENTIFY_CAPACITY / ID_RATE_HZ
    head = (f'rig node ~/identify after a day-ahead measured_wrench stamp: {name}, follow mode, '
            f'{seconds:g} s at {ID_RATE_HZ:g} Hz streamed (identify buffer capacity '
            f'{sensor.IDENTIFY_CAPACITY} samples = {capacity_s:g} s at this rate'
            f'{"; filled" if seconds >= capacity_s else "; NOT filled"}), target: answered '
            f'within {ID_TARGET_S:g} s, RSS growth <= the buffer bound {bound / 2 ** 20:.1f} MB')
    progress(f'  rig node ~/identify after a day-ahead stamp: generating {seconds:g} s ...')
    t_ns, angles, force, torque = rig_stream(scene_mod.load(name), seconds)
    probe = NodeProbe(name, ID_RATE_HZ, f'/identify{os.getpid()}', ('mode:=follow',),
                      label='identify')
    try:
        feed = SensorFeed(probe)
        feed.limit_ns = int(t_ns[-1])
        probe.spin_for(START_TIMEOUT_S, lambda: feed.matched() or probe.proc.poll() is not None)
        if not feed.matched():
            return '\n'.join([head, 'not measured: the node did not start or its endpoints '
                              'did not match'])
        pid = probe.proc.pid
        rss0 = status_bytes(pid)
        progress('    streaming ...')
        a = int(0.3 * t_ns.size)
        t0 = time.perf_counter()
        locked = feed.play(t_ns[:a], angles[:a], force[:a], torque[:a])
        if locked is None:
            feed.measured.publish(feed.wrench_msg(t_ns[a] + ID_DAY_NS, force[a], torque[a]))
            locked = feed.play(t_ns[a:], angles[a:], force[a:], torque[a:])
        stream_s = time.perf_counter() - t0
        if locked is not None:
            return '\n'.join([head, f'FAIL: no residual for the stamp {locked * 1e-9:.3f} s '
                              f'within {ID_WAIT_S:g} s (the sensor path locked)'])
        rss1 = status_bytes(pid)
        progress('    ~/identify ...')
        answers = [feed.call_identify() for _ in range(calls)]
        rss2, hwm = status_bytes(pid), status_bytes(pid, 'VmHWM')
    finally:
        probe.close(timeout=30)
    median = statistics.median(s for s, _, _ in answers)
    ok = all(s for _, s, _ in answers)
    grown = rss2 - rss0
    fast, small = median <= ID_TARGET_S, grown <= bound
    first = answers[0][2].splitlines()[0] if answers[0][2] else ''
    mb = 2 ** 20
    return '\n'.join([
        head,
        f'streamed {t_ns.size} samples per topic in {stream_s:.1f} s wall '
        f'({feed.residuals} residuals received)',
        f'~/identify answer time: median {median:.3f} s of {len(answers)} calls '
        f'({", ".join(f"{s:.3f}" for s, _, _ in answers)}); success '
        f'{sum(s for _, s, _ in answers)}/{len(answers)}: {first[:160]}',
        f'node RSS: {rss0 / mb:.1f} MB at matched endpoints, {rss1 / mb:.1f} MB after the '
        f'stream, {rss2 / mb:.1f} MB after the calls (peak VmHWM {hwm / mb:.1f} MB): growth '
        f'{grown / mb:.1f} MB against the buffer bound {bound / mb:.1f} MB',
        f'{"PASS" if fast and ok else "FAIL"}: answered within {ID_TARGET_S:g} s '
        f'(median {median:.3f} s, {"all succeeded" if ok else "NOT all succeeded"}); '
        f'{"PASS" if small else "FAIL"}: RSS growth {grown / mb:.1f} MB <= '
        f'{bound / mb:.1f} MB'])
