"""
The rig node: its parameters, the twin against the core, and real rclpy across processes.

The node runs in a second process (``python -m mech_balance.ros.node``) on a private ROS domain
and namespace; this process subscribes, publishes encoder messages and calls the services
and the parameter service.  Discovery is waited for (matched endpoints, services), never
slept on.
"""

import contextlib
import math
import os
from pathlib import Path
import signal
import subprocess
import sys
import tempfile
import time

from geometry_msgs.msg import WrenchStamped
from mech_balance import schema as scene_mod
from mech_balance.analysis import cycle as analysis
from mech_balance.balancing import defaults, redistribution, weights
from mech_balance.core.rig import rig_for
from mech_balance.ros import conversions as conv, description
from mech_balance.ros import node as rig_node
from mech_balance.ros import params, streaming as twin
import numpy as np
from numpy.testing import assert_allclose
import pytest
from rcl_interfaces.msg import ParameterType
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
import yaml

ROOT = Path(__file__).resolve().parent.parent


def _domain_id():
    """Return ROS_DOMAIN_ID if set, else a domain from the pid outside 21-28 (the helpers')."""
    if os.environ.get('ROS_DOMAIN_ID', '').isdigit():
        return int(os.environ['ROS_DOMAIN_ID'])
    d = 1 + os.getpid() % 92
    return d + 8 if d >= 21 else d


DOMAIN_ID = _domain_id()
"""The ROS domain of this test process (its namespaces carry the pid as well)."""
RTOL = 1e-9
"""Published values against the core at the stamped angle (relative to the quantity's scale)."""
DISCOVERY_TIMEOUT_S = 45.0
"""Upper bound for the node process to start and its endpoints to be discovered."""
STEP_TIMEOUT_S = 30.0
"""Upper bound for any other wait (messages, service answers)."""


def _assert_close(actual, expected, rtol=RTOL, what=''):
    """Compare with ``rtol`` relative to the largest |expected| (zero crossings included)."""
    expected = np.asarray(expected, dtype=float)
    scale = max(float(np.max(np.abs(expected))), 1e-300)
    assert_allclose(actual, expected, rtol=0.0, atol=rtol * scale, err_msg=what)


# ------------------------------------------------------------------------------ parameters


def test_every_parameter_is_declared_once_with_a_valid_default():
    names = [spec.name for spec in params.PARAMETERS]
    assert len(names) == len(set(names))
    for spec in params.PARAMETERS:
        assert spec.description, spec.name
        assert params.check(spec.name, spec.default) == spec.default
        desc = conv.parameter_descriptor(spec)
        assert desc.name == spec.name and desc.description == spec.description
        # the node checks type and range itself (its own reasons): described, not enforced
        assert desc.dynamic_typing and not desc.floating_point_range
        if spec.bounds is not None:
            assert f'{spec.bounds[0]:g} <= value <= {spec.bounds[1]:g}' in \
                desc.additional_constraints
    for required in ('scene', 'mode', 'crank_speed', 'publish_rate', 'frame_id',
                     'crank_joint', 'balance.weights', 'balance.case', 'balance.realizable',
                     'use_balanced', 'recording_path'):
        assert required in names
    assert params.BY_NAME['frame_id'].default == 'rig_frame'
    assert conv.parameter_descriptor(params.BY_NAME['balance.weights']).type == \
        ParameterType.PARAMETER_DOUBLE_ARRAY


def test_params_file_documents_a_working_set():
    data = yaml.safe_load((ROOT / 'config' / 'rig_params.yaml').read_text())
    flat = {}

    def walk(prefix, node):
        for key, value in node.items():
            if isinstance(value, dict):
                walk(f'{prefix}{key}.', value)
            else:
                flat[f'{prefix}{key}'] = value
    walk('', data['/**']['ros__parameters'])
    assert set(flat) == set(params.BY_NAME)
    for name, value in flat.items():
        params.check(name, value)
    assert 'rig_params' not in scene_mod.builtin_scenes()
    # one default objective: the file, the node's declaration and redistribution.optimize agree
    assert flat['balance.weights'] == params.defaults()['balance.weights'] == \
        list(defaults.DEFAULT_WEIGHTS)


@pytest.mark.parametrize('name, value, reason', [
    ('mode', 'dance', 'mode: got .dance., expected one of clock, follow'),
    ('publish_rate', -5.0, r'publish_rate: got -5.0, expected 0.1 <= value'),
    ('publish_rate', '100', "publish_rate: got '100', expected a floating-point number"),
    ('crank_speed', math.nan, 'crank_speed: got nan, expected a finite number'),
    ('frame_id', '/rig', 'frame_id: got ./rig., expected a frame name'),
    ('balance.weights', [0.0, 0.0], r'balance.weights: got \[0, 0\], expected at least one'),
    ('balance.weights', [1.0], r'balance.weights: got \[1.0\], expected \[w1, w2\]'),
    ('balance.case', 'c', 'balance.case: got .c., expected one of a, b'),
    ('balance.mass_factors', [5.0, 1.0], r'balance.mass_factors: got \[5.0, 1.0\]'),
    ('balance.mass_bounds', '{crank: [2, 1]}', r'balance.mass_bounds.crank: got \[2, 1\]'),
    ('balance.mass_bounds', '[1, 2]', 'balance.mass_bounds: got .* expected a mapping'),
    ('balance.mass_bounds', '{crank: [0, 2]}', r'balance.mass_bounds.crank: .* 0 < min'),
    ('balance.distance_factors', [0.0, 0.0], r'balance.distance_factors: got \[0.0, 0.0\]'),
    ('balance.samples', 3, 'balance.samples: got 3, expected 0'),
    ('recording_path', '/tmp/x.txt', 'recording_path: got .* expected a file name ending in '
     '.rrd'),
    ('recording_path', '/no/such/dir/x.rrd', "recording_path: got .*directory '/no/such/dir' "
     'does not exist'),
    ('recording_path', '/tmp', 'recording_path: got .* expected a file name ending in .rrd'),
    ('no_such', 1, 'no_such: unknown parameter'),
])
def test_bad_parameter_values_are_rejected_with_a_reason(name, value, reason):
    with pytest.raises(ValueError, match=reason):
        params.check(name, value)


def test_balance_options_are_those_of_the_balance_command():
    values = params.defaults()
    values.update({'balance.weights': [0.5, 0.5], 'balance.case': 'b',
                   'balance.mass_bounds': '{crank: [0.3, null]}', 'balance.samples': 90,
                   'balance.max_added_mass': 2.0, 'balance.fixed_links': 'rocker'})
    opts = params.balance_options(values)
    assert opts['weights'] == (0.5, 0.5) and opts['case'] == 'b'
    # YAML 1.2 floats, as in scenes: 1e-1 is a number, not text
    assert params.check('balance.distance_bounds', '{crank: [1e-2, 2E-1]}')
    assert params.parse_link_bounds('balance.mass_bounds', '{crank: [1e-1, 2]}', 'kg') == \
        {'crank': (0.1, 2.0)}
    assert opts['mass_bounds'] == {'crank': (0.3, None)} and opts['samples'] == 90
    assert opts['max_added_mass_kg'] == 2.0 and opts['fixed_links'] == ('rocker',)
    params.check_links(values, ['crank', 'coupler', 'rocker'])
    with pytest.raises(ValueError, match='balance.fixed_links: got link .rocker.'):
        params.check_links(values, ['crank', 'rod', 'slider'])


# ------------------------------------------------------------------------------ the twin


def test_planar_twin_equals_the_core_and_joint_rates_are_derivatives():
    sc = scene_mod.load('hoeken')
    model = twin.model_for(sc)
    rng = np.random.default_rng(7)
    psi = rng.uniform(0.0, 2.0 * math.pi, 50)
    speed, accel = 2.5, -0.7
    s = model.evaluate(psi, speed, accel)
    state, w = analysis.Rig(sc).evaluate(psi, outputs=('bearing_reactions',), speed=speed,
                                         accel=accel)
    _assert_close(s.force_N[:, 0], w.shaking_force.real)
    _assert_close(s.force_N[:, 1], w.shaking_force.imag)
    _assert_close(s.moment_Nm[:, 2], w.shaking_moment)
    assert not np.any(s.force_N[:, 2]) and not np.any(s.moment_Nm[:, :2])
    assert model.joint_names == ('O1', 'A', 'B', 'O3')
    assert np.array_equal(s.joint_position[:, 0], twin.wrap_angle(psi))  # (-pi, pi]
    assert np.all(s.joint_velocity[:, 0] == speed)
    _assert_close(s.joint_effort[:, 0], w.driving_torque)
    assert not np.any(s.joint_effort[:, 1:])
    # joint velocities are the time derivatives of the joint positions (central differences)
    h = 1e-6
    ahead = model.evaluate(psi + speed * h, speed, 0.0).joint_position
    behind = model.evaluate(psi - speed * h, speed, 0.0).joint_position
    rates = model.evaluate(psi, speed, 0.0).joint_velocity
    _assert_close(twin.wrap_angle(ahead - behind) / (2.0 * h), rates, rtol=1e-7)


def test_prismatic_joint_is_the_slide_and_its_effort_the_reaction_moment():
    sc = scene_mod.load('slider_crank')
    model = twin.model_for(sc)
    psi = np.linspace(0.0, 2.0 * math.pi, 37)
    omega = sc.crank_speed_rad_s
    s = model.evaluate(psi, omega)
    a, l_rod = 0.04, 0.16  # crank and rod of config/slider_crank.yaml, in-line guide on x
    x_b = a * np.cos(psi) + np.sqrt(l_rod ** 2 - (a * np.sin(psi)) ** 2)
    slide = model.joint_names.index('S')
    _assert_close(s.joint_position[:, slide], x_b)
    rod_x = np.sqrt(l_rod ** 2 - (a * np.sin(psi)) ** 2)
    dx_dpsi = -a * np.sin(psi) * (1.0 + a * np.cos(psi) / rod_x)
    _assert_close(s.joint_velocity[:, slide], dx_dpsi * omega, rtol=1e-8)
    _, w = analysis.Rig(sc).evaluate(psi, outputs=('bearing_reactions',))
    _assert_close(s.joint_effort[:, slide], w.reaction_moment['S'])


def test_rggr_twin_fills_all_six_components_from_the_core():
    sc = scene_mod.load('rggr')
    model = twin.model_for(sc)
    psi = np.linspace(0.1, 6.0, 25)
    s = model.evaluate(psi, 7.0)
    ref = rig_for(sc).at(psi, 7.0)
    _assert_close(s.force_N, ref.force_N)
    _assert_close(s.moment_Nm, ref.moment_Nm)
    assert np.all(np.max(np.abs(s.force_N), axis=0) > 0.0)
    assert np.all(np.max(np.abs(s.moment_Nm), axis=0) > 0.0)
    assert model.joint_names == ref.joint_names and model.joint_names[:2] == ('crank', 'output')
    _assert_close(s.joint_position[:, 1], ref.joint_position[:, 1])
    _assert_close(s.joint_effort[:, 0], ref.joint_effort[:, 0])
    still = model.evaluate(psi[:3], 0.0)
    assert not np.any(still.force_N) and not np.any(still.joint_effort)


def test_clock_schedule_stamps_and_angles_agree():
    sched = twin.ClockSchedule(epoch_ns=10_000, period_ns=1_000_000, angle0_rad=6.0,
                               speed_rad_s=-3.0)
    angles = sched.angles(5, 4)
    t = (np.array([sched.time_ns(k) for k in range(5, 9)]) - 10_000) * 1e-9
    assert_allclose(angles, np.mod(6.0 - 3.0 * t, 2.0 * math.pi), rtol=0, atol=1e-15)
    assert sched.first_index_at_or_after(10_000) == 0
    assert sched.first_index_at_or_after(10_001) == 1
    assert sched.first_index_at_or_after(9_000) == 0
    later = sched.rebased(2_500_000_000, speed_rad_s=1.0)
    assert later.angles(0, 1)[0] == pytest.approx(np.mod(6.0 - 3.0 * 2.49999, 2 * math.pi))
    assert twin.batch_size(1_000_000) == 250
    with pytest.raises(ValueError, match='period_ns: got 0'):
        twin.ClockSchedule(0, 0, 0.0, 1.0)


def test_estimator_recovers_speed_and_acceleration_from_positions_only():
    est = twin.CrankEstimator(window=7)
    t0, omega, alpha = 1_000_000_000, 30.0, -12.0
    out = []
    for k in range(20):
        t = k * 1e-3
        turned = 1.0 + omega * t + 0.5 * alpha * t * t
        # an encoder that wraps to [-pi, pi)
        out.append(est.update(t0 + k * 1_000_000, (turned + math.pi) % (2 * math.pi) - math.pi))
    assert out[0] is None  # the first sample primes the fit
    last = out[-1]
    t = 19e-3
    assert last.speed_rad_s == pytest.approx(omega + alpha * t, rel=1e-9)
    assert last.accel_rad_s2 == pytest.approx(alpha, rel=1e-6)
    assert last.turned_rad == pytest.approx(1.0 + omega * t + 0.5 * alpha * t * t, rel=1e-12)
    est = twin.CrankEstimator(window=5)
    for k in range(6):
        s = est.update(t0 + k * 2_000_000, 0.1 + 4.0 * k * 2e-3, 4.0)
    assert s.speed_rad_s == 4.0 and s.accel_rad_s2 == 0.0
    est = twin.CrankEstimator(window=5, use_encoder_velocity=False)
    for k in range(6):
        s = est.update(t0 + k * 2_000_000, 0.1 + 4.0 * k * 2e-3, 99.0)  # velocity ignored
    assert s.speed_rad_s == pytest.approx(4.0, rel=1e-9)


def test_estimator_is_the_least_squares_fit_on_noisy_uneven_samples():
    # the estimator's plain-Python fit against numpy's least squares (the definition)
    rng = np.random.default_rng(7)
    for window in (3, 7, 25):
        for with_velocity in (False, True):
            est = twin.CrankEstimator(window=window)
            stamps = 1_000_000_000 + np.cumsum(rng.integers(200_000, 3_000_000, 60))
            t = (stamps - stamps[0]) * 1e-9
            turned = 0.4 + 20.0 * t - 35.0 * t * t + rng.normal(0.0, 1e-3, t.size)
            velocity = 20.0 - 70.0 * t + rng.normal(0.0, 0.05, t.size)
            for k, stamp in enumerate(stamps):
                s = est.update(int(stamp), math.remainder(turned[k], 2 * math.pi),
                               velocity[k] if with_velocity else None)
                lo = max(0, k - window + 1)
                if k - lo < 2:
                    continue
                tau = (stamps[lo:k + 1] - stamp) * 1e-9
                if with_velocity:
                    slope = np.polyfit(tau, velocity[lo:k + 1], 1)[0]
                    assert s.speed_rad_s == velocity[k]
                    assert s.accel_rad_s2 == pytest.approx(slope, rel=1e-9, abs=1e-9)
                    continue
                span = -tau[0]
                x = tau / span
                coef, *_ = np.linalg.lstsq(np.column_stack([np.ones(x.size), x, x * x]),
                                           turned[lo:k + 1] - turned[k], rcond=None)
                assert s.speed_rad_s == pytest.approx(coef[1] / span, rel=1e-9, abs=1e-9)
                assert s.accel_rad_s2 == pytest.approx(2.0 * coef[2] / span ** 2, rel=1e-7,
                                                       abs=1e-6)


def test_estimator_rejects_input_the_rig_cannot_produce():
    est = twin.CrankEstimator(window=5, max_speed=100.0, max_gap_s=0.5)
    est.update(1_000_000_000, 0.0)
    est.update(1_001_000_000, 0.01)
    with pytest.raises(ValueError, match='position: got nan, expected a finite'):
        est.update(1_002_000_000, math.nan)
    with pytest.raises(ValueError, match='velocity: got inf'):
        est.update(1_002_000_000, 0.02, math.inf)
    with pytest.raises(ValueError, match='stamp: .* is not after the previous'):
        est.update(1_000_500_000, 0.02)
    with pytest.raises(ValueError, match=r'needs a crank speed of .* \(a jump the linkage'):
        est.update(1_002_000_000, 1.5)
    assert est.update(1_002_000_000, 0.02).speed_rad_s == pytest.approx(10.0)
    assert est.update(2_000_000_000, 3.0) is None  # a long gap restarts the fit


def test_messages_carry_the_samples_and_the_encoder_is_read_with_checks():
    sc = scene_mod.load('hoeken')
    model = twin.model_for(sc)
    s = model.evaluate([0.3, 0.4], 1.0)
    js = conv.joint_state_template(JointState(), model.joint_names)
    stamp = conv.stamp_from_ns(1_234_567_890_123)
    conv.fill_joint_state(js, s, 1, stamp)
    assert conv.ns_from_stamp(js.header.stamp) == 1_234_567_890_123
    assert list(js.position) == list(s.joint_position[1])
    assert list(js.effort) == list(s.joint_effort[1])
    ws = conv.fill_wrench(WrenchStamped(), s, 1, stamp, 'cell_frame')
    force, moment = conv.wrench_values(ws)
    assert ws.header.frame_id == 'cell_frame'
    assert force == tuple(s.force_N[1]) and moment == tuple(s.moment_Nm[1])
    enc = JointState(name=['x', 'O1'], position=[0.0, 0.5], velocity=[0.0, 2.0])
    enc.header.stamp = stamp
    assert conv.crank_reading(enc, 'O1') == (1_234_567_890_123, 0.5, 2.0)
    enc.velocity = []
    assert conv.crank_reading(enc, 'O1')[2] is None
    with pytest.raises(ValueError, match="name: no joint 'crank'"):
        conv.crank_reading(enc, 'crank')
    enc.position = [0.5]
    with pytest.raises(ValueError, match='position: got 1 values for 2 names'):
        conv.crank_reading(enc, 'O1')
    enc.position = [0.0, math.nan]
    with pytest.raises(ValueError, match="position of 'O1': got nan"):
        conv.crank_reading(enc, 'O1')


@pytest.mark.parametrize('name, effort, frame_id', [
    ('hoeken', True, 'rig_frame'), ('slider_crank', True, 'a/b_c'),
    ('carpet_scraper', False, 'x'), ('rggr', True, 'rig_frame')])
def test_batch_serializer_reads_back_as_the_filled_messages(name, effort, frame_id):
    model = twin.model_for(scene_mod.load(name))
    # sample by sample (follow mode's small batches) and with numpy (clock mode's)
    for n in (9, conv.SMALL_BATCH + 8):
        samples = model.evaluate(np.linspace(0.0, 6.0, n), 1.7, -0.4)
        if not effort:
            samples.joint_effort = None
        stamps = 1_700_000_000_999_999_000 + 333_333 * np.arange(n, dtype=np.int64)
        ser = conv.SampleSerializer(model.joint_names, effort, frame_id)
        reference = conv.serialized_samples(samples, stamps, frame_id)

        def same(payloads):  # read back: CDR leaves the alignment padding unspecified
            return len(payloads) == len(reference) and all(
                deserialize_message(fj, JointState) == deserialize_message(rj, JointState)
                and deserialize_message(fw, WrenchStamped) ==
                deserialize_message(rw, WrenchStamped)
                for (fj, fw), (rj, rw) in zip(payloads, reference))
        assert same(ser.serialize(samples, stamps)) and ser.fast
        # a wrong layout is caught, not sent (both forms of it: byte indices, value runs)
        ser._joint.index = ser._joint.index[::-1].copy()
        (p0, e0, k0, at0), (p1, e1, k1, at1) = ser._joint.runs[:2]  # positions, velocities
        ser._joint.runs[:2] = [(p0, e0, k0, at1), (p1, e1, k1, at0)]
        assert same(ser.serialize(samples, stamps)) and not ser.fast


# ------------------------------------------------------------------------------ processes


class RigProcess:
    """The rig node in a second process; stopped with SIGINT (killed if it hangs)."""

    def __init__(self, namespace, *ros_args):
        self.namespace = namespace
        self.log = tempfile.NamedTemporaryFile('w+', prefix='rig_node_', suffix='.log')
        env = dict(os.environ, PYTHONPATH=str(ROOT), ROS_DOMAIN_ID=str(DOMAIN_ID),
                   ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', PYTHONUNBUFFERED='1')
        cmd = [sys.executable, '-m', 'mech_balance.ros.node', '--ros-args',
               '-r', f'__ns:={namespace}', *ros_args]
        self.proc = subprocess.Popen(cmd, env=env, stdout=self.log, stderr=subprocess.STDOUT,
                                     cwd=str(ROOT))

    def alive(self):
        return self.proc.poll() is None

    def output(self):
        self.log.seek(0)
        return self.log.read()

    def stop(self, sig=signal.SIGINT):
        if self.alive():
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=15)
        text = self.output()
        self.log.close()
        return text


@contextlib.contextmanager
def matched_rig(context, namespace, *ros_args, logs=None):
    """
    Start a rig node in ``namespace`` and its probe, wait until matched, yield ``(rig, probe)``.

    Both are stopped afterwards; ``logs`` (a list), if given, receives the node's log.
    """
    rig = RigProcess(namespace, *ros_args)
    probe = Probe(context, namespace)
    try:
        probe.wait_for_rig(rig)
        yield rig, probe
    finally:
        probe.destroy()
        log = rig.stop()
        if logs is not None:
            logs.append(log)


class Probe:
    """This process's side: subscribers, an encoder publisher and clients in a namespace."""

    def __init__(self, context, namespace):
        self.ns = namespace
        self.node = rclpy.create_node(f'probe_{os.getpid()}', namespace=namespace,
                                      context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.joints, self.wrenches = [], []
        self.after_ns = 0
        qos = QoSProfile(depth=1000)
        self.node.create_subscription(JointState, 'joint_states', self._on_joints, qos)
        self.node.create_subscription(WrenchStamped, 'shaking_wrench', self._on_wrench, qos)
        self.encoder = self.node.create_publisher(JointState, 'crank_joint_state',
                                                  QoSProfile(depth=1000))
        self.balance = self.node.create_client(Trigger, 'rig/balance')
        self.reset = self.node.create_client(Trigger, 'rig/reset')
        self.params = AsyncParameterClient(self.node, f'{namespace}/rig')

    def _on_joints(self, msg):
        if conv.ns_from_stamp(msg.header.stamp) <= self.after_ns:
            return
        self.joints.append((conv.ns_from_stamp(msg.header.stamp), tuple(msg.name),
                            np.array(msg.position), np.array(msg.velocity),
                            np.array(msg.effort)))

    def _on_wrench(self, msg):
        if conv.ns_from_stamp(msg.header.stamp) <= self.after_ns:
            return
        force, moment = conv.wrench_values(msg)
        self.wrenches.append((conv.ns_from_stamp(msg.header.stamp), msg.header.frame_id,
                              np.array(force + moment)))

    def spin_until(self, done, timeout=STEP_TIMEOUT_S, what='condition'):
        deadline = time.monotonic() + timeout
        while not done():
            if time.monotonic() > deadline:
                raise AssertionError(f'timed out after {timeout:g} s waiting for {what}')
            self.executor.spin_once(timeout_sec=0.02)

    def wait_for_rig(self, rig, topics=True):
        """Wait until the node's publishers and services are matched with ours."""
        def up():
            assert rig.alive(), rig.output()
            ok = self.balance.service_is_ready() and self.params.services_are_ready()
            if topics:
                ok = ok and self.node.count_publishers(f'{self.ns}/joint_states') >= 1 and \
                    self.node.count_publishers(f'{self.ns}/shaking_wrench') >= 1
            return ok
        self.spin_until(up, DISCOVERY_TIMEOUT_S, 'the rig node to be discovered')

    def collect(self, count, what='samples'):
        """
        Wait for ``count`` samples on both topics stamped after now.

        Both processes read the same system clock; a sample stamped later was published
        after every change this process has seen answered (older ones may still be queued).
        """
        self.after_ns = self.node.get_clock().now().nanoseconds
        self.joints.clear()
        self.wrenches.clear()
        self.spin_until(lambda: len(self.joints) >= count and len(self.wrenches) >= count,
                        what=f'{count} {what} on both topics')

    def call(self, client, timeout=STEP_TIMEOUT_S):
        future = client.call_async(Trigger.Request())
        self.spin_until(future.done, timeout, f'{client.srv_name} to answer')
        return future.result()

    def set_params(self, **values):
        plist = [Parameter(k.replace('__', '.'), value=v) for k, v in values.items()]
        future = self.params.set_parameters(plist)
        self.spin_until(future.done, what='the parameter service')
        return future.result().results

    def get_param(self, name):
        future = self.params.get_parameters([name])
        self.spin_until(future.done, what='the parameter service')
        return future.result().values[0]

    def destroy(self):
        self.executor.remove_node(self.node)
        self.node.destroy_node()
        self.executor.shutdown()


def _namespace(tag):
    return f'/t{os.getpid()}_{tag}'


def _expected_planar(model, joints):
    """Return the core's samples at the published crank angle and speed of each message."""
    psi = np.array([j[2][model.crank_index] for j in joints])
    speed = np.array([j[3][model.crank_index] for j in joints])
    return model.evaluate(psi, speed, 0.0)


def _check_against_core(probe, model, frame_id, rtol=RTOL):
    """Every received JointState and WrenchStamped equals the core at its stamped angle."""
    model = description.urdf_twin(model)  # the published joints: the URDF's, then cut joints
    joints = [j for j in probe.joints if j[1] == model.joint_names]
    assert len(joints) == len(probe.joints)
    ref = _expected_planar(model, joints)
    _assert_close(np.array([j[2] for j in joints]), ref.joint_position, rtol, 'positions')
    _assert_close(np.array([j[3] for j in joints]), ref.joint_velocity, rtol, 'velocities')
    _assert_close(np.array([j[4] for j in joints]), ref.joint_effort, rtol, 'efforts')
    by_stamp = {j[0]: i for i, j in enumerate(joints)}
    matched = [(by_stamp[w[0]], w) for w in probe.wrenches if w[0] in by_stamp]
    assert len(matched) >= len(probe.wrenches) // 2
    assert all(w[1] == frame_id for _, w in matched)
    rows = [i for i, _ in matched]
    got = np.array([w[2] for _, w in matched])
    _assert_close(got[:, :3], ref.force_N[rows], rtol, 'shaking force')
    _assert_close(got[:, 3:], ref.moment_Nm[rows], rtol, 'shaking moment')


def test_clock_mode_topics_parameters_and_balancing_across_processes(context):
    ns = _namespace('clock')
    rate = 200.0
    rig = RigProcess(ns, '--params-file', str(ROOT / 'config' / 'rig_params.yaml'),
                     '-p', f'publish_rate:={rate}')
    probe = Probe(context, ns)
    try:
        probe.wait_for_rig(rig)
        sc = scene_mod.load('hoeken')
        original = twin.model_for(sc)

        # stamped on the configured rate's schedule: every step a whole number of periods,
        # the period itself among them (a tick later than MAX_LAG_S is skipped under load:
        # how many is a rate, measured by `mech-balance bench --section node`, not asserted)
        probe.collect(int(rate))
        stamps = np.array(sorted(j[0] for j in probe.joints))
        period_ns = round(1e9 / rate)
        steps = np.diff(stamps)
        assert np.all(steps > 0) and np.all(steps % period_ns == 0)
        assert np.min(steps) == period_ns
        _check_against_core(probe, original, 'rig_frame')

        # invalid updates are rejected with a reason, the node keeps publishing
        for name, value, reason in (
                ('publish_rate', -5.0, 'publish_rate'),
                ('scene', 'no_such_scene', "scene: got 'no_such_scene'"),
                ('balance.weights', [0.0, 0.0], 'balance.weights'),
                ('balance.fixed_links', 'wheel', "balance.fixed_links: got link 'wheel'"),
                ('frame_id', '/bad', 'frame_id'),
                ('recording_path', '/no/such/dir/x.rrd', 'recording_path: got'),
                ('mode', 'dance', 'mode')):
            result = probe.set_params(**{name.replace('.', '__'): value})[0]
            assert not result.successful, name
            assert reason in result.reason, result.reason
        assert probe.set_params(crank_speed=2)[0].successful  # an integer for a double
        assert probe.get_param('crank_speed').type == ParameterType.PARAMETER_DOUBLE
        assert probe.set_params(crank_speed=0.0)[0].successful
        assert probe.set_params(frame_id='cell_frame')[0].successful
        probe.collect(20)
        _check_against_core(probe, original, 'cell_frame')

        # ~/balance: a long run (many samples) so that a second call finds it running
        assert probe.set_params(balance__samples=20000)[0].successful
        first = probe.balance.call_async(Trigger.Request())
        second = probe.balance.call_async(Trigger.Request())
        probe.spin_until(lambda: first.done() and second.done(), 120.0, '~/balance')
        # the second caller of the same request shares the running run's answer (issue 32.4)
        assert first.result().success, first.result().message
        assert second.result().success and second.result().message == first.result().message

        # the answer equals `mech-balance balance` for the same options
        assert probe.set_params(balance__samples=0)[0].successful
        answer = probe.call(probe.balance)
        assert answer.success, answer.message
        got = yaml.safe_load(answer.message)
        cli = subprocess.run([sys.executable, '-m', 'mech_balance.cli', 'balance', '--scene',
                              'hoeken', '--weights', '0.5', '0.5', '--json'],
                             capture_output=True, text=True, timeout=120,
                             env=dict(os.environ, PYTHONPATH=str(ROOT)))
        assert cli.returncode == 0, cli.stderr
        _same_report(got, yaml.safe_load(cli.stdout))
        assert got['success'] and got['report']['realizable'] is True
        assert got['report']['certificate']['status']
        assert probe.get_param('use_balanced').bool_value

        # the balanced design is published
        result = redistribution.optimize(sc, weights=(0.5, 0.5))
        balanced = original.with_design(result.balanced_scene)
        probe.collect(40)
        _check_against_core(probe, balanced, 'cell_frame')

        # ~/reset: back to the original
        answer = probe.call(probe.reset)
        assert answer.success, answer.message
        assert not probe.get_param('use_balanced').bool_value
        probe.collect(40)
        _check_against_core(probe, original, 'cell_frame')
        assert rig.alive()
    finally:
        probe.destroy()
        log = rig.stop()
    assert 'publishing' in log and '/rig/balance std_srvs/srv/Trigger' in log


@pytest.mark.parametrize('args, reason', [
    (('-p', 'publish_rate:=-1.0'), 'publish_rate'),
    (('-p', 'scene:=no_such_scene'), "scene: got 'no_such_scene'"),
    (('-p', 'balance.weights:=[0.0, 0.0]'), 'balance.weights'),
    (('-p', 'recording_path:=/no/such/dir/rig.rrd'),
     "recording_path: got '/no/such/dir/rig.rrd', its directory '/no/such/dir' does not"),
])
def test_an_invalid_parameter_at_start_up_is_a_clear_error(args, reason):
    rig = RigProcess(_namespace('bad'), *args)
    try:
        assert rig.proc.wait(timeout=STEP_TIMEOUT_S) == 2
    finally:
        log = rig.stop()
    assert 'rig_node: error:' in log and reason in log, log


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_shutdown_by_signal_is_quiet_and_logs_the_stats(context, sig):
    """Ctrl-C and SIGTERM stop the node without 'Failed to publish log message to rosout'."""
    ns = _namespace(f'signal{int(sig)}')
    rig = RigProcess(ns, '-p', 'publish_rate:=1000.0')
    probe = Probe(context, ns)
    try:
        probe.wait_for_rig(rig)
        probe.collect(50)  # publishing when the signal arrives
    finally:
        probe.destroy()
        log = rig.stop(sig)
    assert rig.proc.returncode == 0, log
    assert 'rosout' not in log and 'context is invalid' not in log, log
    assert 'publishing failed' not in log, log
    assert sum(rig_node.STATS_TAG in line for line in log.splitlines()) == 1, log


def _same_report(got, expected, path=''):
    """Compare two balance reports, numbers to 1e-9 relative; solve times are not compared."""
    if isinstance(expected, dict):
        keys = {k for k in expected if not k.endswith('time_s')}
        assert keys == {k for k in got if not k.endswith('time_s')}, path
        for k in keys:
            _same_report(got[k], expected[k], f'{path}.{k}')
    elif isinstance(expected, list):
        assert len(got) == len(expected), path
        for i, (g, e) in enumerate(zip(got, expected)):
            _same_report(g, e, f'{path}[{i}]')
    elif isinstance(expected, float) and not isinstance(expected, bool):
        assert got == pytest.approx(expected, rel=1e-9, abs=1e-12), path
    else:
        assert got == expected, path


def _encoder(name, stamp_ns, position, velocity=None):
    msg = JointState(name=list(name), position=list(position))
    if velocity is not None:
        msg.velocity = list(velocity)
    msg.header.stamp = conv.stamp_from_ns(stamp_ns)
    return msg


def test_follow_mode_reproduces_the_core_for_an_encoder_stream(context):
    ns = _namespace('follow')
    rig = RigProcess(ns, '-p', 'scene:=slider_crank')
    probe = Probe(context, ns)
    try:
        probe.wait_for_rig(rig)
        probe.collect(5, 'clock-mode samples')
        assert probe.set_params(mode='follow')[0].successful  # switched at run time
        probe.spin_until(lambda: probe.encoder.get_subscription_count() >= 1,
                         DISCOVERY_TIMEOUT_S, 'the node to subscribe to the encoder')
        sc = scene_mod.load('slider_crank')
        model = description.twin_for(sc)  # the published joints (description.JointLayout)
        omega, dt = sc.crank_speed_rad_s, 1_000_000
        t0 = 1_000 * 1_000_000_000
        angle = lambda t: 0.3 + omega * (t - t0) * 1e-9  # noqa: E731

        def send(msgs):
            for m in msgs:
                probe.encoder.publish(m)
                probe.executor.spin_once(timeout_sec=0.002)

        # 1) positions and velocities; 2) after a gap, positions only (wrapped angles)
        with_velocity = [t0 + k * dt for k in range(40)]
        t1 = t0 + 2_000_000_000
        position_only = [t1 + k * dt for k in range(40)]
        bad_stamps = []
        msgs = [_encoder(['O'], t, [angle(t)], [omega]) for t in with_velocity]
        for k, t in enumerate(position_only):
            msgs.append(_encoder(['O'], t, [(angle(t) + math.pi) % (2 * math.pi) - math.pi]))
            if k in (10, 20, 30):  # 3) malformed messages in between
                tb = t + 1
                bad_stamps += [tb + i for i in range(6)]
                msgs += [_encoder(['X'], tb, [angle(t)]),                  # no crank joint
                         _encoder(['O'], tb + 1, [math.nan]),              # NaN
                         _encoder(['O'], tb + 2 - 5 * dt, [angle(t)]),     # stamp backwards
                         _encoder(['O'], tb + 3, [angle(t) + 2.0]),        # impossible jump
                         _encoder(['O', 'S'], tb + 4, [angle(t)]),         # short position
                         _encoder(['O'], tb + 5, [angle(t)], [math.inf])]  # bad velocity
        probe.after_ns = -1
        probe.joints.clear()
        probe.wrenches.clear()
        send(msgs)
        t_end = position_only[-1] + 1  # later stamps: clock-mode samples still in flight
        expected = len(with_velocity) + len(position_only) - 1  # the first position primes
        probe.spin_until(lambda: sum(w[0] < t_end for w in probe.wrenches) >= expected and
                         sum(j[0] < t_end for j in probe.joints) >= expected,
                         what='a sample per encoder message')
        assert rig.alive()
        joints = {j[0]: j for j in probe.joints if j[0] < t_end}
        wrenches = {w[0]: w for w in probe.wrenches if w[0] < t_end}
        assert set(joints) == set(wrenches) == set(with_velocity) | set(position_only[1:])
        assert not set(bad_stamps) & set(joints)
        for stamps, rtol in ((with_velocity, RTOL), (position_only[1:], 1e-7)):
            psi = np.array([joints[t][2][0] for t in stamps])
            speed = np.array([joints[t][3][0] for t in stamps])
            _assert_close(speed, np.full(len(stamps), omega), rtol, 'estimated speed')
            ref = model.evaluate(psi, omega, 0.0)
            _assert_close(np.array([joints[t][2] for t in stamps]), ref.joint_position, rtol)
            _assert_close(np.array([wrenches[t][2] for t in stamps]),
                          np.hstack([ref.force_N, ref.moment_Nm]), rtol, 'shaking wrench')
        assert probe.set_params(mode='clock')[0].successful  # and back
        probe.collect(5, 'clock-mode samples')
    finally:
        probe.destroy()
        log = rig.stop()
    assert 'crank_joint_state: skipped a message' in log


def test_rggr_scene_publishes_all_six_components_and_balances(context, tmp_path):
    ns = _namespace('cell3')
    rrd = tmp_path / 'rig.rrd'
    rig = RigProcess(ns, '-p', 'scene:=rggr', '-p', 'publish_rate:=100.0',
                     '-p', 'crank_speed:=-4.0', '-p', f'recording_path:={rrd}',
                     '-p', 'use_balanced:=true')
    probe = Probe(context, ns)
    sc = scene_mod.load('rggr')
    original = description.twin_for(sc)  # the published joints (description.JointLayout)
    balanced = original.with_design(weights.balance_weights(rig_for(sc)).balanced_scene)

    def received(model):
        joints = {j[0]: j for j in probe.joints}
        rows = [(joints[w[0]], w) for w in probe.wrenches if w[0] in joints]
        assert len(rows) >= len(probe.wrenches) // 2
        assert all(j[1] == original.joint_names and j[3][0] == -4.0
                   for j, _ in rows)
        ref = model.evaluate(np.array([j[2][0] for j, _ in rows]), -4.0)
        got = np.array([w[2] for _, w in rows])
        _assert_close(got, np.hstack([ref.force_N, ref.moment_Nm]), RTOL, 'RGGR wrench')
        _assert_close(np.array([j[4] for j, _ in rows]), ref.joint_effort, RTOL, 'RGGR efforts')
        return got

    try:
        probe.wait_for_rig(rig)
        # use_balanced at start-up: balanced in the background, then published
        probe.spin_until(lambda: probe.get_param('use_balanced').bool_value and
                         'use_balanced: publishing the balanced design' in rig.output(),
                         what='the start-up balancing')
        probe.collect(20)
        got = received(balanced)
        assert np.max(np.abs(got[:, :3])) < 1e-9 * np.max(np.abs(received_scale(original)))
        # ~/reset: the original rig, all six components
        assert probe.call(probe.reset).success
        probe.collect(20)
        got = received(original)
        assert np.all(np.max(np.abs(got), axis=0) > 0.0)
        # ~/balance answers what `mech-balance balance --si --json` prints
        answer = probe.call(probe.balance)
        assert answer.success, answer.message
        cli = subprocess.run([sys.executable, '-m', 'mech_balance.cli', 'balance', '--scene',
                              'rggr', '--si', '--json'], capture_output=True, text=True,
                             timeout=120, env=dict(os.environ, PYTHONPATH=str(ROOT)))
        assert cli.returncode == 0, cli.stderr
        _same_report(yaml.safe_load(answer.message), yaml.safe_load(cli.stdout))
        probe.collect(20)
        received(balanced)
    finally:
        probe.destroy()
        log = rig.stop()
    assert f'recording to {rrd}' in log
    assert rrd.stat().st_size > 0  # written and closed on shutdown


def received_scale(model):
    """Return the shaking force of ``model`` over a turn (its scale)."""
    return model.evaluate(np.linspace(0.0, 2.0 * math.pi, 36, endpoint=False), -4.0).force_N


def test_clock_mode_follows_simulated_time(context):
    from rosgraph_msgs.msg import Clock
    ns = _namespace('sim')
    rig = RigProcess(ns, '-p', 'use_sim_time:=true', '-p', 'publish_rate:=100.0')
    probe = Probe(context, ns)
    clock = probe.node.create_publisher(Clock, '/clock', QoSProfile(depth=10))
    probe.after_ns = -1  # keep samples stamped 0 too: there must be none
    try:
        probe.wait_for_rig(rig)
        probe.spin_until(lambda: clock.get_subscription_count() >= 1, DISCOVERY_TIMEOUT_S,
                         'the node to subscribe to /clock')
        start = 5_000 * 1_000_000_000
        assert not probe.joints  # no sample before simulated time starts
        sim = start
        while len(probe.joints) < 30:
            clock.publish(Clock(clock=conv.stamp_from_ns(sim)))
            probe.executor.spin_once(timeout_sec=0.005)
            sim += 2_000_000
            assert sim < start + 60 * 1_000_000_000, 'no samples on simulated time'
        stamps = np.array([j[0] for j in probe.joints])
        assert np.all((stamps >= start) & (stamps <= sim))
        steps = np.diff(stamps)
        assert np.all(steps > 0) and np.all(steps % 10_000_000 == 0)
        psi = np.unwrap([j[2][0] for j in probe.joints])
        _assert_close(np.diff(psi),
                      steps * 1e-9 * scene_mod.load('hoeken').crank_speed_rad_s, 1e-9)
    finally:
        probe.destroy()
        rig.stop()
