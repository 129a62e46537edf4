"""
The twin against the real rig: the sensor's frame and sign, pairing, tare, the node's wiring.

Pure tests of :mod:`mech_balance.ros.sensor` and :mod:`mech_balance.ros.diagnostics` against
hand computations and the synthetic rig of ``test/synthetic_rig.py`` (made by the tests: a
perturbed true scene, a quantized encoder, sensor noise and bias).  The node tests run two
rig nodes in other processes, one with an identity-mounted sensor and one with a rotated,
offset sensor reporting the reaction, and play the same synthetic recording to both as
topics (``crank_joint_state`` in follow mode, ``measured_wrench``).
"""

from dataclasses import replace
import math
import os
import sys

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from mech_balance import rotations, schema
from mech_balance.ros import conversions as conv
from mech_balance.ros import diagnostics, params, sensor, streaming
import numpy as np
from numpy.testing import assert_allclose
import pytest
from rclpy.qos import QoSProfile
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
import yaml

sys.path.insert(0, os.path.dirname(__file__))
import synthetic_rig as sr  # noqa: E402, I100
from test_node import DISCOVERY_TIMEOUT_S, Probe, RigProcess  # noqa: E402, I100

SE_BOUND = 3.0
"""A tare within this many of its standard errors of the injected bias."""
NOISE_TOL = 1.25
"""Residual minus (true - nominal) within this factor of the injected noise RMS (the crank
state estimated from the quantized encoder adds a little)."""
ROUND_OFF = 1e-9
"""Identity and rotated sensors: residuals equal to this fraction of the wrench's peak."""
SHIFT_M = (0.05, 0.02)
"""The node tests' scene: Hoeken with its frame moved, so that the crank pivot is off the
rig frame's origin."""
RATE_STEP = 4
"""The node tests play the 1 kHz synthetic recording at 250 Hz (every 4th sample)."""
NODE_SEED = 23
"""The node tests' perturbed rig (5 s at 250 Hz calibrate it to a realizable scene: with so
little data the crank's small centroidal inertia may come out negative for other seeds, and
~/identify then refuses)."""
POSE = {'x': 0.12, 'y': -0.05, 'z': 0.3, 'roll': 0.4, 'pitch': -0.3, 'yaw': 2.0}
"""The rotated and offset sensor of the node tests (it reports the reaction)."""


def _rotation(roll, pitch, yaw):
    """Return the test's own R = Rz(yaw) Ry(pitch) Rx(roll): scipy's extrinsic x-y-z angles."""
    return Rotation.from_euler('xyz', [roll, pitch, yaw]).as_matrix()


def _reading(wrench_rig, pivot, position, rotation, sign):
    """
    Return what a sensor at ``position``, ``rotation`` reports, written out by hand.

    The rig's wrench ``(n, 6)`` about ``pivot`` has, about the sensor's origin p, the moment
    n_p = n_O - (p - O) x f; the sensor reports s R^T f and s R^T n_p.
    """
    f, n_o = wrench_rig[:, :3], wrench_rig[:, 3:]
    arm = np.asarray(position, float) - np.asarray(pivot, float)
    n_p = n_o - np.cross(arm, f)
    return sign * f @ rotation, sign * n_p @ rotation


def _six(planar):
    """Return ``(n, 6)`` of a planar ``(n, 3)`` wrench [f_x, f_y, n_z]."""
    out = np.zeros((planar.shape[0], 6))
    out[:, [0, 1, 5]] = planar
    return out


# ------------------------------------------------------------------------------ frames


def test_rotation_is_ros_fixed_axis_roll_pitch_yaw():
    rng = np.random.default_rng(1)
    for roll, pitch, yaw in rng.uniform(-math.pi, math.pi, (20, 3)):
        r = rotations.rpy_matrix((roll, pitch, yaw))
        assert_allclose(r @ r.T, np.eye(3), atol=1e-14)
        assert np.linalg.det(r) == pytest.approx(1.0, abs=1e-14)
        assert_allclose(r, _rotation(roll, pitch, yaw), atol=1e-14)
    # yaw a quarter turn: the sensor's x axis is the rig's y axis
    assert_allclose(rotations.rpy_matrix((0.0, 0.0, math.pi / 2)) @ [1, 0, 0], [0, 1, 0],
                    atol=1e-15)


def test_reduction_to_the_pivot_by_hand():
    pose = sensor.SensorPose(x=0.1, y=-0.2, z=0.05)
    w = pose.to_rig([1.0, 2.0, 3.0], [0.1, 0.2, 0.3], point_m=(0.3, 0.1, 0.0))
    # p - O = (-0.2, -0.3, 0.05); (p - O) x f = (-1.0, 0.65, -0.1)
    assert_allclose(w, [[1.0, 2.0, 3.0, -0.9, 0.85, 0.2]], atol=1e-15)
    # a lever: F down at L along x from the pivot turns it about +y by L F
    lever = sensor.SensorPose(x=0.5).to_rig([0.0, 0.0, -4.0], [0.0, 0.0, 0.0], (0.0, 0.0))
    assert_allclose(lever, [[0.0, 0.0, -4.0, 0.0, 2.0, 0.0]], atol=1e-15)
    # the reaction convention reports the negative
    react = sensor.SensorPose(x=0.5, convention='reaction').to_rig([0, 0, 4.0], [0, 0, 0],
                                                                   (0.0, 0.0))
    assert_allclose(react, lever, atol=1e-15)
    # a quarter-turn yaw: the sensor's x is the rig's y
    turned = sensor.SensorPose(yaw=math.pi / 2).to_rig([1.0, 0.0, 0.0], [0, 0, 0.5],
                                                       (0.0, 0.0))
    assert_allclose(turned, [[0.0, 1.0, 0.0, 0.0, 0.0, 0.5]], atol=1e-15)


def test_round_trip_and_any_mounting_gives_the_same_rig_wrench():
    rng = np.random.default_rng(2)
    wrench = rng.normal(size=(50, 6))
    pivot = (0.05, 0.02, 0.0)
    identity = sensor.SensorPose()
    ref = identity.to_rig(*identity.to_sensor(wrench, pivot), pivot)
    assert_allclose(ref, wrench, atol=1e-13)
    for convention in sensor.CONVENTIONS:
        for k in range(10):
            x, y, z = rng.uniform(-0.5, 0.5, 3)
            roll, pitch, yaw = rng.uniform(-math.pi, math.pi, 3)
            pose = sensor.SensorPose(x, y, z, roll, pitch, yaw, convention)
            # the test's own transformation of the rig's wrench into this sensor's reading
            f_s, n_s = _reading(wrench, pivot, (x, y, z), _rotation(roll, pitch, yaw),
                                pose.sign)
            mine = pose.to_sensor(wrench, pivot)
            assert_allclose(mine[0], f_s, atol=1e-13)
            assert_allclose(mine[1], n_s, atol=1e-13)
            assert_allclose(pose.to_rig(f_s, n_s, pivot), ref, atol=1e-13)


def test_bad_pose_and_readings_name_the_field():
    with pytest.raises(ValueError, match='sensor.convention: got .up.'):
        sensor.SensorPose(convention='up')
    with pytest.raises(ValueError, match='sensor.yaw: got nan'):
        sensor.SensorPose(yaw=math.nan)
    comparison = sensor.Comparison(sensor.SensorPose(), (0, 0, 0), 0.1)
    with pytest.raises(ValueError, match='wrench: got force'):
        comparison.measurement(1, [math.inf, 0, 0], [0, 0, 0])
    comparison.measurement(5, [0, 0, 0], [0, 0, 0])
    with pytest.raises(ValueError, match='stamp: .* is not after the previous'):
        comparison.measurement(5, [0, 0, 0], [0, 0, 0])
    msg = WrenchStamped()
    msg.wrench.torque.y = math.nan
    with pytest.raises(ValueError, match=r'wrench.torque: got \[0.0, nan, 0.0\]'):
        conv.wrench_reading(msg)


# ------------------------------------------------------------------------------ weight


def test_weight_model_is_the_links_weight_at_their_mass_centres():
    nominal = replace(schema.load('hoeken'), gravity_m_s2=(3.0, -9.0))
    true = sr.perturbed(nominal, 5, gravity=nominal.gravity_m_s2)
    data = sr.record(true, 1.0, 2.0 * math.pi, 5)
    model = streaming.model_for(true)
    weight = sensor.WeightModel.of(model.rig)
    rig_data = model.evaluate(np.mod(data.psi, 2.0 * math.pi), data.speed, data.accel)
    # the synthetic rig computes shaking wrench + weight with its own (complex) code
    got = sensor.model_wrench(rig_data, weight, model.moment_point_m)
    scale = np.max(np.abs(data.true_wrench), axis=0)
    assert_allclose(got[:, sensor.PLANAR] / scale, data.true_wrench / scale, atol=1e-12)
    assert not np.any(got[:, [2, 3, 4]])
    # the total weight force is sum m g at every pose
    total = sum(lk.mass_kg for lk in true.links)
    w = weight.wrench(rig_data.bodies, model.moment_point_m)
    assert_allclose(w[:, :2], np.tile(np.multiply(total, (3.0, -9.0)), (w.shape[0], 1)),
                    rtol=1e-14)
    # no gravity: no weight model; the RGGR's model has no gravity
    assert sensor.WeightModel.of(streaming.model_for(schema.load('hoeken')).rig) is None
    assert sensor.WeightModel.of(streaming.model_for(schema.load('rggr')).rig) is None


def test_rig_at_rest_reads_its_weight_with_the_sign_of_the_convention():
    """At rest the model is the weight alone: a reaction sensor reads -sum m g, up."""
    nominal = replace(schema.load('hoeken'), gravity_m_s2=(0.0, -9.81))
    model = streaming.model_for(nominal)
    total = sum(lk.mass_kg for lk in nominal.links)
    pivot = model.moment_point_m
    for convention, sign in (('load_on_sensor', 1.0), ('reaction', -1.0)):
        comparison = sensor.Comparison(sensor.SensorPose(convention=convention), pivot, 0.1,
                                       sensor.WeightModel.of(model.rig))
        rest = model.evaluate([1.0], 0.0, 0.0)
        expected = sensor.model_wrench(rest, comparison.weight, pivot)
        assert expected[0, 1] == pytest.approx(-9.81 * total, rel=1e-14)
        assert not np.any(rest.force_N) and not np.any(rest.moment_Nm)
        stamps = 10_000_000 * np.arange(40)
        for t in stamps:
            comparison.encoder(t, 1.0)
        reading = sign * expected[0]
        # load_on_sensor: the rig pushes the sensor down; reaction: the sensor pushes up
        assert reading[1] == pytest.approx(-sign * 9.81 * total, rel=1e-14)
        for t in stamps[:30]:
            comparison.measurement(t, reading[:3], reading[3:])
        paired = comparison.process(model.evaluate)
        assert paired.stamps_ns.size == 30 - 5  # 5 in the first half window: before data
        assert_allclose(paired.residual, 0.0, atol=1e-12)
        assert comparison.rejected == {'before the encoder data': 5}


# ------------------------------------------------------------------------------ pairing


def test_encoder_track_recovers_a_quadratic_motion_between_samples():
    track = sensor.EncoderTrack(window_s=0.05)
    t = 1_000_000_000 + 4_000_000 * np.arange(200)      # 250 Hz

    def motion(stamp):
        s = (stamp - 1_000_000_000) * 1e-9
        return 0.3 + 7.0 * s + 0.5 * -3.0 * s * s, 7.0 - 3.0 * s, -3.0
    for stamp in t:
        angle = motion(stamp)[0]
        track.add(stamp, (angle + math.pi) % (2 * math.pi) - math.pi)   # a wrapping encoder
    query = np.array([t[0] + 1_000, t[20] + 1_234_567, t[100] + 3_999_999, t[-3]])
    psi, speed, accel, status = track.state_at(query)
    assert status == ['before the encoder data', 'ok', 'ok', 'wait']
    for i in (1, 2):
        angle, rate, acc = motion(query[i])
        assert psi[i] == pytest.approx(angle, abs=1e-9)   # unwrapped from 0.3 on
        assert speed[i] == pytest.approx(rate, rel=1e-9)
        assert accel[i] == pytest.approx(acc, rel=1e-7)
    # a gap in the encoder: a stamp inside it cannot be paired
    gap = sensor.EncoderTrack(window_s=0.05)
    for stamp in np.concatenate([t[:50], t[60:]]):
        gap.add(stamp, 0.0)
    assert gap.state_at([t[55]])[3] == ['encoder gap at the stamp']


@pytest.fixture(scope='module')
def hoeken_rig():
    """Return the nominal Hoeken, its perturbed true rig and 6 s of its recording."""
    nominal = schema.load('hoeken')
    true = sr.perturbed(nominal, 21)
    data = sr.record(true, 6.0, 2.0 * math.pi, 21)
    return nominal, true, data


def test_residual_is_true_minus_nominal_within_the_noise(hoeken_rig):
    nominal, true, data = hoeken_rig
    model = streaming.model_for(nominal)
    comparison = sensor.Comparison(sensor.SensorPose(), model.moment_point_m, 0.1)
    k = slice(None, None, RATE_STEP)
    t, pos, w = data.t_ns[k], data.position_rad[k], data.wrench[k]
    for stamp, angle in zip(t, pos):
        comparison.encoder(stamp, angle)
    for stamp, x in zip(t, w):
        comparison.measurement(stamp, [x[0], x[1], 0.0], [0.0, 0.0, x[2]])
    paired = comparison.process(model.evaluate)
    i = np.searchsorted(t, paired.stamps_ns)
    truth = model.evaluate(np.mod(data.psi[k][i], 2 * math.pi), data.speed[k][i],
                           data.accel[k][i])
    expected = data.true_wrench[k][i] + data.bias - sensor.model_wrench(
        truth, None, model.moment_point_m)[:, sensor.PLANAR]
    diff = paired.residual[:, sensor.PLANAR] - expected
    ratio = np.sqrt(np.mean(diff ** 2, axis=0)) / data.noise_std
    assert np.all(ratio < NOISE_TOL), ratio
    # the model error is far above the noise: the comparison sees it
    assert np.max(np.sqrt(np.mean(expected ** 2, axis=0)) / data.noise_std) > 5.0
    rms = comparison.rms(2.0)
    assert rms['samples'] == pytest.approx(2.0 * sr.RATE_HZ / RATE_STEP, abs=1)
    assert_allclose(rms['model'][[2, 3, 4]], 0.0)
    status = diagnostics.measurement_status('rig: measured wrench', 'hoeken', rms,
                                            sensor.COMPONENTS, sensor.UNITS, 0.1, 0.5,
                                            comparison.received, comparison.used, {}, 0.1,
                                            comparison.bias, 'hoeken')
    assert status.level == diagnostics.WARN, status.message
    levels = dict(status.values)
    assert levels['force_z level'] == 'not judged' and levels['torque_z level'] == 'WARN'


def test_tare_at_rest_estimates_the_bias_within_three_standard_errors(hoeken_rig):
    nominal, _, data = hoeken_rig
    model = streaming.model_for(nominal)
    rng = np.random.default_rng(3)
    comparison = sensor.Comparison(sensor.SensorPose(), model.moment_point_m, 0.1)
    t = 1_000_000_000 + 4_000_000 * np.arange(600)
    for stamp in t:
        comparison.encoder(stamp, 1.25)
    bias6, std6 = _six(data.bias[None])[0], _six(data.noise_std[None])[0]
    for stamp in t:
        reading = bias6 + std6 * rng.normal(size=6)
        comparison.measurement(stamp, reading[:3], reading[3:])
    comparison.process(model.evaluate)
    est = comparison.tare(1.0)
    assert est.at_rest and est.samples == 251
    assert np.all(np.abs(est.bias - bias6) <= SE_BOUND * est.std_error + 1e-15)
    assert_allclose(est.std_error[list(sensor.PLANAR)], data.noise_std / math.sqrt(251), rtol=0.15)
    assert_allclose(comparison.bias, est.bias)
    assert 'at rest' in est.summary()
    # from then on the residual is the noise about zero
    assert np.max(np.abs(comparison.rms(1.0)['residual'] - std6)) < 0.15 * np.max(std6)


def test_series_keeps_the_newest_samples_in_order():
    s = sensor.Series(2, capacity=10)
    for k in range(37):
        s.append([k], [[k, -k]])
        assert len(s) == min(k + 1, 10)
        assert list(s.stamps_ns) == list(range(max(0, k - 9), k + 1))
    s.append(np.arange(100, 125), np.zeros((25, 2)))
    assert list(s.stamps_ns) == list(range(115, 125))
    t, _ = s.since(120)
    assert list(t) == [120, 121, 122, 123, 124]


# ------------------------------------------------------------------------------ statuses


def test_statuses_and_reasons():
    assert diagnostics.reason_of(ValueError("name: no joint 'O' in []")) == 'name'
    assert diagnostics.reason_of(ValueError("position of 'O': got nan")) == 'position'
    assert diagnostics.reason_of(ValueError('position: 1 rad after 0 rad in 0.001 s needs '
                                            'a crank speed of 1000 rad/s')) == 'position jump'
    assert diagnostics.reason_of(KeyError('x')) == 'internal error: KeyError'
    watch = diagnostics.ModelWatch()
    model = streaming.model_for(schema.load('hoeken'))
    watch.add(model.evaluate(np.linspace(0, 6, 50), 1.0))
    samples, residual, cond, near = watch.snapshot()
    assert samples == 50 and 0.0 <= residual < diagnostics.RESIDUAL_ERROR and cond >= 1.0
    assert diagnostics.model_status('m', 'h', samples, residual, cond, near).level == \
        diagnostics.OK
    assert diagnostics.model_status('m', 'h', 5, 1e-3, 10.0, 0).level == diagnostics.ERROR
    assert diagnostics.model_status('m', 'h', 5, 0.0, 1e5, 2).level == diagnostics.WARN
    assert watch.snapshot()[0] == 0
    status = diagnostics.publisher_status('p', 'h', 'clock', 100.0, 50.0, 10, 3, 3)
    assert status.level == diagnostics.WARN and '3 ticks skipped' in status.message
    never = diagnostics.measurement_status('s', 'h', None, sensor.COMPONENTS, sensor.UNITS,
                                           0.1, 0.3, 0, 0, {}, None, np.zeros(6), 'hoeken')
    assert never.level == diagnostics.OK and 'no sensor' in never.message
    values = params.defaults()
    params.check_together(values)
    values['diagnostics.warn_fraction'] = 0.5
    with pytest.raises(ValueError, match='diagnostics.warn_fraction: got 0.5 above'):
        params.check_together(values)
    with pytest.raises(ValueError, match='sensor.convention: got .up., expected one of'):
        params.check('sensor.convention', 'up')
    with pytest.raises(ValueError, match='sensor.roll: got 7.0'):
        params.check('sensor.roll', 7.0)


# ------------------------------------------------------------------------------ the node


def _scene_file(tmp_path):
    sc = schema.load('hoeken')
    shifted = replace(sc, name='hoeken_shifted', frame_points={
        k: (v[0] + SHIFT_M[0], v[1] + SHIFT_M[1]) for k, v in sc.frame_points.items()})
    path = tmp_path / 'hoeken_shifted.yaml'
    path.write_text(schema.to_yaml(shifted))
    return schema.load(str(path)), str(path)


class SensorProbe(Probe):
    """The probe of test_node, plus the sensor's topics and services."""

    def __init__(self, context, namespace):
        super().__init__(context, namespace)
        qos = QoSProfile(depth=1000)
        self.measured = self.node.create_publisher(WrenchStamped, 'measured_wrench', qos)
        self.residuals = {}
        self.node.create_subscription(WrenchStamped, 'wrench_residual', self._on_residual,
                                      qos)
        self.statuses = []
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics,
                                      QoSProfile(depth=100))
        self.tare = self.node.create_client(Trigger, 'rig/tare')
        self.identify = self.node.create_client(Trigger, 'rig/identify')

    def _on_residual(self, msg):
        force, moment = conv.wrench_values(msg)
        self.residuals[conv.ns_from_stamp(msg.header.stamp)] = np.array(force + moment)

    def _on_diagnostics(self, msg):
        prefix = f'{self.ns}/rig: '
        mine = {s.name[len(prefix):]: s for s in msg.status if s.name.startswith(prefix)}
        if mine:
            self.statuses.append(mine)

    def ready(self):
        self.discovered = (self.measured.get_subscription_count() >= 1,
                           self.encoder.get_subscription_count() >= 1,
                           self.node.count_publishers(f'{self.ns}/wrench_residual') >= 1,
                           self.tare.service_is_ready(), self.identify.service_is_ready())
        return all(self.discovered)

    def newest(self):
        return max(self.residuals, default=-1)

    def measurement_status(self, after_ns):
        """Return the newest measured-wrench status whose RMS window starts at after_ns."""
        for s in reversed(self.statuses):
            st = s.get('measured wrench')
            values = {kv.key: kv.value for kv in st.values} if st else {}
            if 'window oldest stamp s' in values and \
                    float(values['window oldest stamp s']) >= after_ns * 1e-9 - 1e-6:
                return st, values
        return None


def _encoder_msg(stamp_ns, angle):
    msg = JointState(name=['O1'], position=[float(angle)])
    msg.header.stamp = conv.stamp_from_ns(int(stamp_ns))
    return msg


def _wrench_msg(stamp_ns, force, torque):
    return conv.fill_wrench_values(WrenchStamped(), int(stamp_ns), 'sensor', [*force, *torque])


CHUNK = 25
"""Samples published per topic before waiting for the nodes (0.1 s at 250 Hz)."""


def _play(probes, t_ns, angles, readings, spin):
    """
    Publish one segment (encoder and wrench interleaved) to every probe, paced.

    ``readings[j]`` is ``(force (n, 3), torque (n, 3))`` for probe j.  After each chunk, wait
    until every node has published the residual of a measurement two chunks back (then at
    least 0.1 s of encoder data lie beyond it: more than half the crank window).
    """
    n = t_ns.size
    for c0 in range(0, n, CHUNK):
        for i in range(c0, min(c0 + CHUNK, n)):
            for probe, (force, torque) in zip(probes, readings):
                probe.encoder.publish(_encoder_msg(t_ns[i], angles[i]))
                probe.measured.publish(_wrench_msg(t_ns[i], force[i], torque[i]))
        back = c0 - CHUNK
        if back > 0:
            target = t_ns[back - 1]
            spin(lambda: all(p.newest() >= target for p in probes),
                 f'the residual at {target * 1e-9:.3f} s')


def test_node_compares_tares_identifies_and_diagnoses(context, tmp_path):
    nominal, path = _scene_file(tmp_path)
    true = sr.perturbed(nominal, NODE_SEED)
    data = sr.record(true, 7.5, 2.0 * math.pi, NODE_SEED)
    k = slice(None, None, RATE_STEP)
    t_all, pos_all, w_all = data.t_ns[k], data.position_rad[k], data.wrench[k]
    true_all, psi_all = data.true_wrench[k], data.psi[k]
    speed_all, accel_all = data.speed[k], data.accel[k]
    pivot = (SHIFT_M[0], SHIFT_M[1], 0.0)
    rate = sr.RATE_HZ / RATE_STEP
    # segments: 1.5 s at rest, a 1 s gap, 5 s turning (A), ~identify, 2.5 s turning (B)
    n_rest, n_a = int(1.5 * rate), int(5.0 * rate)
    t_rest = t_all[0] - int(2.5e9) + (np.arange(n_rest) * (1e9 / rate)).astype(np.int64)
    rng = np.random.default_rng(5)   # (seed 4's rest noise has a 2.98-sigma mean in n_z)
    rest = _six(data.bias[None] + data.noise_std * rng.normal(size=(n_rest, 3)))
    q = 2.0 * math.pi / sr.COUNTS_PER_TURN
    rest_angle = np.full(n_rest, round(1.1 / q) * q)
    turning = _six(w_all)
    rotation = _rotation(POSE['roll'], POSE['pitch'], POSE['yaw'])
    position = (POSE['x'], POSE['y'], POSE['z'])

    def readings(w6):
        return [_reading(w6, pivot, np.zeros(3), np.eye(3), 1.0),
                _reading(w6, pivot, position, rotation, -1.0)]

    half_ns = int(0.5 * params.BY_NAME['sensor.crank_window'].default * 1e9)

    def drain(t_seg):
        """Wait for the residual of the segment's last measurement that can be paired."""
        last = t_seg[t_seg + half_ns <= t_seg[-1]][-1]
        spin(lambda: all(p.newest() >= last for p in probes), f'the residual at {last}')

    common = ('-p', f'scene:={path}', '-p', 'mode:=follow', '-p', 'publish_rate:=50.0',
              '-p', 'sensor.residual_window:=1.0', '-p', 'sensor.tare_seconds:=1.0',
              '-p', 'diagnostics.warn_fraction:=0.1', '-p', 'diagnostics.error_fraction:=0.5')
    ns = [f'/t{os.getpid()}_sensor_identity', f'/t{os.getpid()}_sensor_rotated']
    rotated_args = [a for key, v in POSE.items() for a in ('-p', f'sensor.{key}:={v!r}')]
    rigs = [RigProcess(ns[0], *common),
            RigProcess(ns[1], *common, *rotated_args, '-p', 'sensor.convention:=reaction')]
    probes = [SensorProbe(context, n) for n in ns]

    def spin(done, what, timeout=60.0):
        import time
        deadline = time.monotonic() + timeout
        while not done():
            for rig in rigs:
                assert rig.alive(), rig.output()
            assert time.monotonic() < deadline, \
                f'timed out waiting for {what}: ' + '; '.join(
                    f'{p.ns}: discovered {getattr(p, "discovered", None)}, '
                    f'{len(p.residuals)} residuals' for p in probes)
            for p in probes:
                p.executor.spin_once(timeout_sec=0.005)

    def call_all(client_name):
        futures = [getattr(p, client_name).call_async(Trigger.Request()) for p in probes]
        spin(lambda: all(f.done() for f in futures), f'~/{client_name}', 120.0)
        return [f.result() for f in futures]

    try:
        spin(lambda: all(p.ready() for p in probes), 'the nodes', DISCOVERY_TIMEOUT_S)
        # bad input: counted by reason, never fatal
        for p in probes:
            p.measured.publish(_wrench_msg(t_rest[0] - 10, [math.nan, 0, 0], [0, 0, 0]))
            p.encoder.publish(JointState(name=['X'], position=[0.0]))
        # ---- at rest: ~tare
        _play(probes, t_rest, rest_angle, readings(rest), spin)
        drain(t_rest)
        answers = call_all('tare')
        assert all(a.success for a in answers), [a.message for a in answers]
        tares = [yaml.safe_load(a.message.split('\n', 1)[1]) for a in answers]
        assert tares[0]['at_rest'] and 'at rest' in answers[0].message.splitlines()[0]
        bias_hat = np.array([tares[0]['bias'][c]['estimate'] for c in sensor.COMPONENTS])
        bias_se = np.array([tares[0]['bias'][c]['std_error'] for c in sensor.COMPONENTS])
        assert np.all(np.abs(bias_hat - _six(data.bias[None])[0]) <= SE_BOUND * bias_se)
        assert np.all(bias_se[list(sensor.PLANAR)] > 0.0)
        rotated_bias = np.array([tares[1]['bias'][c]['estimate'] for c in sensor.COMPONENTS])
        assert_allclose(rotated_bias, bias_hat, rtol=0, atol=ROUND_OFF * np.max(data.noise_std))
        # ---- turning with the nominal model (A)
        t_a = t_all[:n_a]
        _play(probes, t_a, pos_all[:n_a], readings(turning[:n_a]), spin)
        drain(t_a)
        spin(lambda: all(p.measurement_status(t_a[0]) is not None for p in probes) and
             all(float(p.measurement_status(t_a[0])[1]['window newest stamp s']) >=
                 t_a[-int(0.1 * rate)] * 1e-9 for p in probes), 'the A diagnostics')
        status_a, values_a = probes[0].measurement_status(t_a[0])
        assert status_a.level == bytes([diagnostics.WARN]), status_a.message
        model = streaming.model_for(nominal)
        stamps_a = np.array(sorted(s for s in probes[0].residuals if t_a[0] <= s <= t_a[-1]))
        assert stamps_a.size > 0.9 * n_a
        i = np.searchsorted(t_all, stamps_a)
        truth = model.evaluate(np.mod(psi_all[i], 2 * math.pi), speed_all[i], accel_all[i])
        expected = _six(true_all[i] + data.bias) - sensor.model_wrench(
            truth, None, model.moment_point_m) - bias_hat
        got = np.array([probes[0].residuals[s] for s in stamps_a])
        diff = got - expected
        ratio = np.sqrt(np.mean(diff[:, sensor.PLANAR] ** 2, axis=0)) / data.noise_std
        assert np.all(ratio < NOISE_TOL), ratio
        assert np.max(np.sqrt(np.mean(expected ** 2, axis=0))[list(sensor.PLANAR)] /
                      data.noise_std) > 5.0
        # ---- ~identify: the calibrated scene is published
        answers = call_all('identify')
        assert all(a.success for a in answers), [a.message[:500] for a in answers]
        first = answers[0].message.splitlines()[0]
        assert first.startswith("identified scene 'hoeken_shifted'") and 'rank' in first
        reports = [yaml.safe_load(a.message.split('\n', 1)[1]) for a in answers]
        assert reports[0]['rank'] == reports[1]['rank'] < reports[0]['parameter_count']
        assert_allclose(reports[1]['theta'], reports[0]['theta'], rtol=1e-6, atol=1e-12)
        calibrated = tmp_path / 'calibrated.yaml'
        calibrated.write_text(reports[0]['calibrated_scene'])
        assert schema.load(str(calibrated)).name == 'hoeken_shifted_calibrated'
        # ---- turning with the calibrated model (B)
        t_b = t_all[n_a:]
        _play(probes, t_b, pos_all[n_a:], readings(turning[n_a:]), spin)
        drain(t_b)
        spin(lambda: all(p.measurement_status(t_b[0]) is not None for p in probes) and
             all(float(p.measurement_status(t_b[0])[1]['window newest stamp s']) >=
                 t_b[-int(0.1 * rate)] * 1e-9 for p in probes), 'the B diagnostics')
        status_b, values_b = probes[0].measurement_status(t_b[0])
        assert status_b.level == bytes([diagnostics.OK]), status_b.message
        stamps_b = np.array(sorted(s for s in probes[0].residuals if t_b[0] <= s <= t_b[-1]))
        assert stamps_b.size > 0.9 * t_b.size
        got_b = np.array([probes[0].residuals[s] for s in stamps_b])
        ratio_b = np.sqrt(np.mean(got_b[:, sensor.PLANAR] ** 2, axis=0)) / data.noise_std
        assert np.all(ratio_b < NOISE_TOL), ratio_b
        # ---- the rotated, offset, reaction sensor gives the same residuals
        assert set(probes[1].residuals) == set(probes[0].residuals)
        peak = np.max(np.abs(turning))
        for s, r in probes[0].residuals.items():
            assert_allclose(probes[1].residuals[s], r, rtol=0, atol=ROUND_OFF * peak)
        # ---- the other statuses
        latest = probes[0].statuses[-1]
        enc = {kv.key: kv.value for kv in latest['encoder input'].values}
        assert int(enc['used']) == n_rest + t_all.size and enc['rejected: name'] == '1'
        assert latest['model'].level == bytes([diagnostics.OK])
        # follow mode publishes from the calibrated design's cycle table, verified
        evaluation = {kv.key: kv.value for kv in latest['model'].values}['evaluation']
        assert evaluation.startswith('cycle table of '), evaluation
        assert 'verified accuracy' in evaluation
        assert values_b['rejected: wrench.force'] == '1'
        assert 'follow mode' in latest['publisher'].message
        # ---- ~reset returns to the scene
        reset = probes[0].call(probes[0].reset)
        assert reset.success and 'calibration dropped' in reset.message
    finally:
        for p in probes:
            p.destroy()
        logs = [rig.stop() for rig in rigs]
    for log in logs:
        assert 'Traceback' not in log, log
        # a table for the scene, another for the calibrated design (~/identify)
        assert log.count("': cycle table of ") >= 2, log
