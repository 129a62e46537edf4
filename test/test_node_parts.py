"""
The rig node's parts, each on its own: in this process, real rclpy where a part needs a node.

The parts (``mech_balance/ros``): the recording and live view (:mod:`live`), the real rig's
sensor tracks (:mod:`sensor`), the diagnostics (:mod:`diagnostics`), the parameters
(:mod:`params`, :mod:`parameters`), the balancing (:mod:`balance_service`), the publisher
(:mod:`publisher`, :mod:`streaming`) and the shared name checks (:mod:`mech_balance.
identifiers`).  The node across processes: ``test_node.py``, ``test_node_faults.py``.
"""

import math
import os
import re
import socket
import sys
import threading

from geometry_msgs.msg import WrenchStamped
from mech_balance import balancing, conventions, identifiers
from mech_balance import schema as scene_mod
from mech_balance.ros import balance_service, conversions as conv, description, diagnostics
from mech_balance.ros import live, parameters, params
from mech_balance.ros import publisher as pub, real_rig, sensor, streamer as streaming_threads
from mech_balance.ros import streaming
from mech_balance.ros.rig_state import RigState
import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState

sys.path.insert(0, os.path.dirname(__file__))
import test_node as tn  # noqa: E402, I100  (the domain of this test process)

NON_FINITE = re.compile(r'\b(nan|inf|infinity)\b', re.IGNORECASE)
"""What no published text may contain."""
WAIT_S = 30.0
"""Upper bound of every wait on a thread here (never reached when the code is right)."""


# ------------------------------------------------------------------------------ live view


class _Recorder:
    """A recorder whose constructor, log and close block until released (a dead viewer)."""

    made = []

    def __init__(self, release, path, url):
        self.release, self.path, self.url = release, path, url
        self.logged = 0
        self.closed = False
        _Recorder.made.append(self)
        release.wait(WAIT_S)

    def log_sample(self, t, psi, data=None):
        self.release.wait(WAIT_S)
        self.logged += len(t)

    def close(self, timeout_s=None):
        self.release.wait(WAIT_S)
        self.closed = True


def _free_port():
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def _batch(n=4):
    return None, np.arange(n, dtype=float), np.arange(n, dtype=np.int64) * 10 ** 6


def test_recording_start_and_push_never_wait_for_the_recorder(tmp_path):
    release, logs = threading.Event(), []
    rec = live.Recording(lambda level, text: logs.append((level, text)),
                         make=lambda path, url, scene, bal: _Recorder(release, path, url))
    try:
        made = len(_Recorder.made)
        rec.start(str(tmp_path / 'a.rrd'), '', 'scene')
        for _ in range(int(WAIT_S / 0.01)):
            if len(_Recorder.made) > made:
                break
            threading.Event().wait(0.01)
        for _ in range(live.QUEUE_BATCHES + 10):   # the recorder is stuck in its constructor
            rec.push(*_batch())
        assert not release.is_set()                # start and push returned meanwhile
        assert rec.dropped == 10                   # bounded: the oldest batches dropped
        release.set()
        done = threading.Event()
        threading.Thread(target=lambda: (rec.close(WAIT_S), done.set())).start()
        assert done.wait(WAIT_S)
        assert _Recorder.made[-1].closed
    finally:
        release.set()
        rec.close(WAIT_S)


def test_recording_reports_a_dead_viewer_and_keeps_the_file(tmp_path):
    release, logs = threading.Event(), []
    release.set()
    url = f'rerun+http://127.0.0.1:{_free_port()}/proxy'   # nothing listens there
    rec = live.Recording(lambda level, text: logs.append((level, text)),
                         make=lambda path, u, scene, bal: _Recorder(release, path, u))
    try:
        assert rec.status == live.OFF
        rec.start(str(tmp_path / 'a.rrd'), url, 'scene')
        deadline = threading.Event()
        for _ in range(int(WAIT_S / 0.01)):
            if rec.status.startswith(live.DEAD):
                break
            deadline.wait(0.01)
        assert rec.status.startswith('dead: nothing answers at 127.0.0.1:'), rec.status
        status = rec.diagnostic_status('/rig', 'hoeken')
        assert status.level == diagnostics.ERROR and 'dead' in status.message
        assert any(level == 'error' and 'the viewer is dead' in text for level, text in logs)
        files = [r for r in _Recorder.made if r.path == str(tmp_path / 'a.rrd')]
        assert files, 'the file recorder was not made'
        rec.push(*_batch())
        for _ in range(int(WAIT_S / 0.01)):
            if files[-1].logged:
                break
            deadline.wait(0.01)
        assert files[-1].logged == 4
    finally:
        rec.close(WAIT_S)


def test_recording_close_is_bounded_when_the_recorder_hangs(tmp_path, monkeypatch):
    monkeypatch.setattr(live, 'CLOSE_TIMEOUT_S', 0.2)
    monkeypatch.setattr(live, 'FILE_CLOSE_TIMEOUT_S', 0.2)     # a stuck disk, not a load
    monkeypatch.setattr(_Recorder, 'made', [])
    release, first, logs = threading.Event(), threading.Event(), []
    first.set()
    rec = live.Recording(lambda level, text: logs.append((level, text)),
                         make=lambda path, url, scene, bal: _Recorder(first, path, url))
    rec.start(str(tmp_path / 'a.rrd'), '', 'scene')
    rec.push(*_batch())
    for _ in range(int(WAIT_S / 0.01)):
        if _Recorder.made and _Recorder.made[-1].logged:
            break
        threading.Event().wait(0.01)
    _Recorder.made[-1].release = release           # now its close hangs
    done = threading.Event()
    threading.Thread(target=lambda: (rec.close(WAIT_S), done.set())).start()
    assert done.wait(WAIT_S)
    assert any('did not close within' in text for _, text in logs), logs
    release.set()


def test_viewer_address_and_probe():
    assert live.viewer_address('rerun+http://127.0.0.1:9877/proxy') == ('127.0.0.1', 9877)
    assert live.viewer_address('rerun+http://localhost/proxy') == ('localhost', 9876)
    with socket.socket() as server:
        server.bind(('127.0.0.1', 0))
        server.listen(1)
        port = server.getsockname()[1]
        assert live.probe_viewer(f'rerun+http://127.0.0.1:{port}/proxy') is None
    assert 'nothing answers' in live.probe_viewer(f'rerun+http://127.0.0.1:{_free_port()}/proxy')


# ------------------------------------------------------------------------------ sensor tracks


def test_series_truncate_from_forgets_the_newer_samples():
    s = sensor.Series(1, 10)
    s.append([1, 2, 3, 86_400 * 10 ** 9], [[1.0], [2.0], [3.0], [4.0]])
    s.truncate_from(3)
    assert s.stamps_ns.tolist() == [1, 2] and s.values[:, 0].tolist() == [1.0, 2.0]
    s.append([3], [[5.0]])
    assert s.newest_ns == 3


def test_series_is_allocated_whole_at_its_first_sample():
    """Nothing before the first sample, then both arrays whole, never allocated again."""
    s = sensor.Series(2, 50)
    assert s._t.size == 0 and len(s) == 0 and s.newest_ns is None
    s.append_one(1, (0.5, 0.25))
    arrays = (s._t, s._v)
    assert s._t.shape == (100,) and s._v.shape == (100, 2) and s.nbytes == 100 * 24
    for k in range(2, 400):                   # compacted several times over
        if k % 2:
            s.append([2 * k, 2 * k + 1], [[k, 0.0], [k, 1.0]])
        else:
            s.append_one(2 * k, (k, 0.0))
    assert s._t is arrays[0] and s._v is arrays[1]
    assert len(s) == 50 and s.newest_ns == 2 * 399 + 1
    assert np.all(np.diff(s.stamps_ns) > 0)


def test_encoder_track_resynchronizes_after_a_day_ahead_stamp():
    track = sensor.EncoderTrack(0.2, resync_after=5)
    t = 10 ** 9 + np.arange(40) * 4_000_000
    for k in range(20):
        assert track.add(t[k], 0.01 * k)
    assert track.add(t[19] + 86_400 * 10 ** 9, 0.3)         # a day ahead: taken, then ...
    refused = [track.add(t[k], 0.01 * k) for k in range(20, 25)]
    assert refused == [False] * 4 + [True]                   # ... the fifth in a row resyncs
    assert track.resyncs == 1 and track.series.newest_ns == t[24]
    assert track.add(t[25], 0.25)
    # the estimator re-synchronized on a sample: the track follows at once
    track.add(t[25] + 86_400 * 10 ** 9, 0.3)
    assert track.add(t[26], 0.26, resync=True) and track.series.newest_ns == t[26]


def _comparison(resync_after=3):
    return sensor.Comparison(sensor.SensorPose(), (0.0, 0.0, 0.0), 0.2,
                             resync_after=resync_after)


def test_measurements_resynchronize_after_a_day_ahead_stamp():
    c = _comparison()
    zero = np.zeros(3)
    c.measurement(1_000, zero, zero)
    c.measurement(1_000 + 86_400 * 10 ** 9, zero, zero)
    for stamp in (2_000, 3_000):
        with pytest.raises(ValueError, match='stamp: .* is not after the previous'):
            c.measurement(stamp, zero, zero)
    c.measurement(4_000, zero, zero)
    assert c.just_resynced and c.resyncs == 1 and 'consecutive measurements' in c.last_resync
    assert c.measured.stamps_ns.tolist() == [1_000, 4_000]
    assert c.pending.stamps_ns.tolist() == [1_000, 4_000]
    c.measurement(5_000, zero, zero)
    assert not c.just_resynced


def test_a_measurement_beyond_the_sensor_range_is_refused():
    c = _comparison()
    with pytest.raises(ValueError, match=r'wrench: .* expected components of at most 1e\+09'):
        c.measurement(1, [1e300, 0.0, 0.0], np.zeros(3))
    assert len(c.measured) == 0


def test_identification_data_is_bounded_in_time_span():
    c = _comparison()
    zero = np.zeros(3)
    day = 86_400 * 10 ** 9
    # an old stretch a day before, then 130 s at 10 Hz (the span bound is 120 s)
    stamps = [1_000] + list(day + np.arange(1300) * 100_000_000)
    for k, t in enumerate(stamps):
        c.encoder(t, 0.01 * k)
        c.measurement(t, zero, zero)
    te, angle, tw, w, t0 = c.identification_data()
    assert te[-1] - te[0] <= sensor.IDENTIFY_SPAN_S * (1 + 1e-12)
    assert tw[0] >= te[0] and tw[-1] <= te[-1] and w.shape == (tw.size, 3)
    # clock mode: the measurements' newest span alone
    schedule = streaming.ClockSchedule(0, 10 ** 6, 0.0, 1.0)
    te, _, tw, _, _ = c.identification_data(schedule)
    assert tw[-1] - tw[0] <= sensor.IDENTIFY_SPAN_S * (1 + 1e-12)


# ------------------------------------------------------------------------------ diagnostics


def _texts(status):
    return [status.message] + [v for _, v in status.values]


def test_no_status_carries_a_non_finite_value():
    first = diagnostics.RateMeter().rate(10, 1_000)
    assert first is None
    statuses = [diagnostics.publisher_status('p', 'h', 'clock', 100.0, first, 0, 0, 0),
                diagnostics.publisher_status('p', 'h', 'follow', None, math.nan, 0, 0, 0)]
    zero6 = np.zeros(6)
    for measured in (zero6, np.full(6, np.inf), np.array([1.0, 1.0, 0.0, 0.0, 0.0, 1.0])):
        rms = {'residual': np.ones(6), 'measured': measured, 'model': np.ones(6),
               'samples': 10, 'oldest_ns': 0, 'newest_ns': 10}
        statuses.append(diagnostics.measurement_status(
            'm', 'h', rms, sensor.COMPONENTS, sensor.UNITS, 0.1, 0.5, 10, 10, {}, 0.1,
            np.zeros(6), 'hoeken', resyncs=2))
    for status in statuses:
        for text in _texts(status):
            assert not NON_FINITE.search(text), (status.name, text)
    constant = statuses[2]
    assert dict(constant.values)['force_x fraction'] == 'not modelled'
    assert '2 re-synchronizations' in statuses[-1].message
    assert 'not measured yet' in statuses[0].message


# ------------------------------------------------------------------------------ names, params


@pytest.mark.parametrize('value', ['a b', 'x\ny', '<bad>', 'a' * 257, '', '/rig'])
def test_frame_id_is_checked_alike_by_the_node_and_the_urdf_command(value):
    with pytest.raises(ValueError, match='--frame-id: got'):
        identifiers.check_frame_id(value, '--frame-id')
    with pytest.raises(ValueError, match='frame_id: got'):
        params.check('frame_id', value)


def test_names_are_capped_at_the_same_length_everywhere():
    cap = conventions.MAX_NAME_LENGTH
    assert identifiers.check_name('j' * cap, 'crank_joint') == 'j' * cap
    for name in ('crank_joint', 'frame_id'):
        with pytest.raises(ValueError, match=f'{name}: got a name of {cap + 1} characters'):
            params.check(name, 'j' * (cap + 1))
    with pytest.raises(ValueError, match='crank_joint: got a name of 100000 characters'):
        params.check('crank_joint', 'j' * 100_000)
    for bad in ('a b', '<j>'):
        with pytest.raises(ValueError, match='crank_joint: got'):
            params.check('crank_joint', bad)


def test_link_lists_are_checked_alike_by_the_node_and_the_balance_command():
    for field in ('balance.counterweight_links', 'balance.fixed_links'):
        with pytest.raises(ValueError, match=f"{field}: got 'crank' twice"):
            params.check(field, 'crank,crank')
    with pytest.raises(ValueError, match="--counterweights: got 'crank' twice"):
        identifiers.check_name_list('crank,crank', '--counterweights')
    assert identifiers.check_name_list('crank, rocker', '--counterweights') == \
        ['crank', 'rocker']
    with pytest.raises(ValueError, match='--counterweights: .* no empty one'):
        identifiers.check_name_list('crank,,rocker', '--counterweights')


def test_recording_path_naming_a_directory_is_refused(tmp_path):
    for value in (f'{tmp_path}/', f'{tmp_path}/x.rrd/', f'{tmp_path}/.'):
        with pytest.raises(ValueError, match='recording_path: got .* a directory, expected a '
                           r'file name ending in \.rrd'):
            params.check('recording_path', value)


@pytest.mark.parametrize('text, expected', [('1e9', 1e9), ('1e3', 1000.0), (' 250 ', 250.0),
                                            ('-2.5', -2.5), ('.5', 0.5)])
def test_a_number_as_text_becomes_the_declared_double(text, expected):
    assert params.coerced('publish_rate', text) == expected
    assert params.coerced('frame_id', text) == text        # a string parameter keeps it


def test_a_number_as_text_gets_the_same_checks():
    with pytest.raises(ValueError, match='publish_rate: got 1000000000.0, expected 0.1 <= '):
        params.check('publish_rate', params.coerced('publish_rate', '1e9'))
    for text in ('fast', '1e', 'nan', '0x10'):
        assert params.coerced('publish_rate', text) == text   # refused by the check


def test_describe_shows_the_bounds_quoted_or_typed():
    for name in ('balance.mass_bounds', 'balance.distance_bounds'):
        spec = params.BY_NAME[name]
        text = f'{spec.description} {spec.constraints}'
        assert "'{crank" in text and 'balance.links.crank.' in text, text
        assert "'{link: [min, max]}'" in spec.constraints


def test_result_file_is_named_by_namespace_and_node():
    a = balance_service.result_path('/cell3/rig')
    b = balance_service.result_path('/cell4/rig')
    assert a != b and os.path.basename(a) == 'mech_balance_cell3__rig_balance.yaml'
    assert os.path.basename(balance_service.result_path('/rig')) == \
        'mech_balance_rig_balance.yaml'
    # ROS names have no repeated '_': '__' separates the namespace unambiguously
    assert balance_service.result_path('/a_b/rig') != balance_service.result_path('/a/b_rig')


def test_scene_switch_conflicts_name_the_refuted_options():
    values = params.defaults()
    values.update({'balance.counterweight_links': 'crank,rocker',
                   'balance.mass_bounds': '{rocker: [0.1, 1.0]}'})
    model = parameters.build_model('slider_crank')
    out = parameters.scene_conflicts(values, model)
    assert set(out) == {'balance.counterweight_links', 'balance.mass_bounds'}
    assert 'rocker' in out['balance.counterweight_links']
    assert parameters.scene_conflicts(params.defaults(), model) == {}


def test_a_switch_to_the_rggr_has_no_conflict_and_balances_by_its_weights():
    """The RGGR is a spatial scene: links, per-link options and its own method (issue 28)."""
    model = parameters.build_model('rggr')
    assert [lk.name for lk in model.scene.links] == ['crank', 'coupler', 'output']
    assert parameters.scene_conflicts(params.defaults(), model) == {}
    assert balance_service.balance_method(params.defaults(), model.rig) == 'weights'
    values = params.defaults()
    values['balance.fixed_links'] = 'rocker'
    assert set(parameters.scene_conflicts(values, model)) == {'balance.fixed_links'}


def test_spatial_mass_factors_are_checked_against_the_spatial_range():
    """
    Check balance.mass_factors against the range of the scene's redistribution.

    Up to 1e6 holds for a planar rig; a spatial one's redistribution certifies up to 100
    (defaults.SPATIAL_MASS_FACTOR_RANGE): refused where set, cleared on a switch to a
    spatial scene.
    """
    values = params.defaults()
    values['balance.mass_factors'] = [1.0, 1e6]
    assert parameters.scene_conflicts(values, parameters.build_model('hoeken')) == {}
    spatial = parameters.build_model('rssr_skew')
    out = parameters.scene_conflicts(values, spatial)
    assert set(out) == {'balance.mass_factors'}
    assert '1e+06, outside [1e-06, 100]' in out['balance.mass_factors']
    values['balance.mass_factors'] = [1.0, 100.0]
    assert parameters.scene_conflicts(values, spatial) == {}
    assert balancing.option_ranges(spatial.rig, 'counterweights') == {}
    assert balancing.option_ranges(parameters.build_model('hoeken').rig, 'redistribution') == {}


# ------------------------------------------------------------------------------ with a node


@pytest.fixture(scope='module')
def node():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=tn.DOMAIN_ID)
    n = rclpy.create_node(f'parts_{os.getpid()}', context=ctx)
    yield n
    n.destroy_node()
    rclpy.try_shutdown(context=ctx)


def _state_of(values):
    return RigState(values, parameters.build_model(values['scene']))


def test_parameters_hold_a_link_of_the_scene_to_come(node):
    part = parameters.NodeParameters(node)
    values = part.declare_all()
    part.declare_link_parameters(parameters.build_model(values['scene']))
    held = 'balance.links.rod.mass_bounds'
    assert not node.has_parameter(held)                      # hoeken has no rod
    out = part.coerce([Parameter(held, value=[0.1, 1.0])])
    assert node.has_parameter(held) and out[0].name == held
    model = parameters.build_model('slider_crank')
    candidate = [Parameter(held, value=[0.1, 1.0])]
    assert part.check(candidate, parameters.build_model('hoeken')).successful
    values[held] = [0.1, 1.0]
    part.declare_link_parameters(model)                      # the scene switch keeps it
    assert node.has_parameter(held) and values[held] == [0.1, 1.0]
    assert not node.has_parameter('balance.links.rocker.mass_bounds')
    # an invalid held value is not declared (rclpy then refuses it as undeclared)
    part.coerce([Parameter('balance.links.slide.mass_bounds', value=[3.0, 1.0])])
    assert not node.has_parameter('balance.links.slide.mass_bounds')
    # a spatial scene's redistribution refuses mass factors above its certified range
    rssr = parameters.build_model('rssr_skew')
    with pytest.raises(ValueError, match=r'balance.mass_factors: got \[1.0, 1000.0\].*'
                       r'outside \[1e-06, 100\]'):
        part.check([Parameter('balance.mass_factors', value=[1.0, 1e3])], rssr)
    assert part.check([Parameter('balance.mass_factors', value=[1.0, 1e3])],
                      parameters.build_model('hoeken')).successful


def test_balancer_answers_busy_while_a_run_is_in_progress(node):
    from mech_balance.ros.guard import Guard
    state = _state_of(params.defaults())
    part = balance_service.Balancer(node, state, Guard(lambda text: None))
    with part.lock:
        assert part.busy
        assert part.balance() == (None, balance_service.BUSY)
    model, text = part.balance()
    assert model is not None and text.startswith('# ')


def test_a_background_run_queues_behind_a_running_one_and_balances_its_own_scene(node):
    """A scene switched to during a run is balanced once that run ends (not 'busy')."""
    from mech_balance.ros.guard import Guard
    state = _state_of(params.defaults())
    part = balance_service.Balancer(node, state, Guard(lambda text: None))
    answers = []

    def done(model, text):
        answers.append((model, text))

    with part.lock:                                   # a run of the previous scene
        thread = part.in_background(done)
        thread.join(0.2)
        assert thread.is_alive() and not answers      # queued, not answered 'busy'
    thread.join()
    (model, text), = answers
    assert model is not None and text.startswith('# '), text
    assert model.scene.name.startswith(state.original.scene.name)
    # a run whose design another run has published meanwhile is not repeated
    with part.lock:
        thread = part.in_background(done)
        with state.lock:
            state.balanced = model
    thread.join()
    assert len(answers) == 1


def test_publisher_and_real_rig_statuses_are_finite_from_the_first(node):
    from mech_balance.ros.guard import Guard
    values = params.defaults()
    state = _state_of(values)
    guard = Guard(lambda text: None)
    publisher = pub.Publisher(node, state, guard, lambda text: None)
    try:
        rig = real_rig.RealRig(node, state, guard, lambda text: None, publisher)
        statuses = rig.statuses(node.get_clock().now().nanoseconds)
        assert [s.name.rsplit(': ', 1)[1] for s in statuses] == \
            ['publisher', 'encoder input', 'model', 'measured wrench']
        for status in statuses:
            for text in _texts(status):
                assert not NON_FINITE.search(text), (status.name, text)
    finally:
        publisher.stop()


def test_zero_stamps_take_the_middleware_stamp_so_a_burst_keeps_its_spacing(node):
    from mech_balance.ros.guard import Guard
    values = dict(params.defaults(), scene='slider_crank', mode='follow')
    state = _state_of(values)
    warned = []
    publisher = pub.Publisher(node, state, Guard(warned.append), warned.append)
    try:
        publisher.streamer.stop()
        publisher.apply_mode()
        sub = publisher._encoder_sub
        assert sub._callback_type is type(sub).CallbackType.WithMessageInfo
        crank = state.original.crank_joint
        sent = node.get_clock().now().nanoseconds - 10 ** 9
        for k in range(20):   # written 10 ms apart, re-sent in a burst, taken back to back
            info = {'source_timestamp': sent + k * 10 ** 7,
                    'received_timestamp': sent + 10 ** 8 + k * 1000}
            sub.callback(tn._encoder([crank], 0, [0.5 + 0.01 * k]), info)
        for k in range(20, 25):   # no source stamp: the reception stamp
            info = {'source_timestamp': 0, 'received_timestamp': sent + k * 10 ** 7}
            sub.callback(tn._encoder([crank], 0, [0.5 + 0.01 * k]), info)
        pending = list(publisher.streamer._pending)
        assert publisher.skipped_inputs == 0, warned
        assert [s.stamp_ns for s in pending] == [sent + k * 10 ** 7 for k in range(1, 25)]
        assert np.allclose([s.speed_rad_s for s in pending], 1.0)   # 0.01 rad per 10 ms
        publisher.estimator.reset()
        publisher.streamer._pending.clear()
        before = node.get_clock().now().nanoseconds
        publisher.on_encoder(tn._encoder([crank], 0, [0.5]))   # no message info (a direct
        after = node.get_clock().now().nanoseconds               # call): the node's clock
        assert before <= publisher.estimator._last[0] <= after
    finally:
        publisher.stop()


def test_streamer_tells_a_stall_from_a_clock_jump():
    model = streaming.model_for(scene_mod.load('hoeken'))
    clock = {'now': 10_000_000_000}
    hold = threading.Event()
    hold.set()
    sent, warned = [], []

    def publish(payload):
        hold.wait(WAIT_S)
        sent.append(payload)

    period = 10_000_000
    streamer = streaming_threads.Streamer(lambda: clock['now'], lambda s, t: list(t), publish,
                                          warned.append)
    stall = streaming_threads.CLOCK_JUMP_S + 1.0
    try:
        streamer.clock(model, 1.0, period)
        while len(sent) < 3:
            clock['now'] += period // 2
            threading.Event().wait(0.001)
        # the publishing thread held (a stuck callback) while the clock runs on in step
        hold.clear()
        threading.Event().wait(0.05)
        started = len(sent)
        clock['now'] += int(stall * 1e9)
        streamer._last_step = (clock['now'] - int(stall * 1e9), 0.0)  # held since then
        hold.set()
        while not warned and len(sent) < started + 50:
            clock['now'] += period // 2
            threading.Event().wait(0.001)
        assert any('publishing was held up' in w for w in warned), warned
        assert not any('clock jumped forward' in w for w in warned), warned
    finally:
        hold.set()
        streamer.stop()


def test_serializer_reads_back_its_first_batches_only_and_stays_exact():
    model = description.twin_for(scene_mod.load('hoeken'))
    ser = conv.SampleSerializer(model.joint_names, model.has_effort, 'rig_frame')
    for k in range(conv.VERIFIED_BATCHES + 3):
        psi = np.linspace(0.1, 2.0, 1 + k % 3)
        samples = model.evaluate(psi, 1.0, 0.0)
        stamps = np.arange(psi.size, dtype=np.int64) + 10 ** 9 * k
        payloads = ser.serialize(samples, stamps)
        assert ser.fast and ser.verified == min(k + 1, conv.VERIFIED_BATCHES)
        # every sample, verified batch or not, reads back as the filled messages
        for i, (joints, wrench) in enumerate(payloads):
            stamp = conv.stamp_from_ns(int(stamps[i]))
            assert deserialize_message(joints, JointState) == conv.fill_joint_state(
                conv.joint_state_template(JointState(), model.joint_names), samples, i, stamp)
            assert deserialize_message(wrench, WrenchStamped) == conv.fill_wrench(
                WrenchStamped(), samples, i, stamp, 'rig_frame')
