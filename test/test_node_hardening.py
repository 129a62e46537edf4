"""
The rig node under hostile input (issue 12) and the ros2cli papercuts (issue 15 item 5).

Node tests run the node in a second process with real rclpy (the helpers of
``test_node.py``), wait for matched endpoints and answers, never sleep-and-hope.  Each
issue-12 class has a test named for it (``test_class<N>_...``).  The pieces without ROS (the
guard, the estimator, the streamer's last check, the near-singular threshold) are tested
in-process first.
"""

import math
import os
from pathlib import Path
import sys
import threading
import time

from mech_balance import balancing
from mech_balance import schema as scene_mod
from mech_balance.analysis import cycle as analysis
from mech_balance.core.planar import kinematics
from mech_balance.core.rig import rig_for
from mech_balance.ros import guard as guards
from mech_balance.ros import params, streamer as streamer_mod, streaming as twin
import numpy as np
import pytest
from rcl_interfaces.msg import ParameterType
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile
from std_msgs.msg import String
import yaml

sys.path.insert(0, os.path.dirname(__file__))
import test_node as tn  # noqa: E402, I100  (RigProcess, Probe: the node in another process)

ROOT = Path(__file__).resolve().parent.parent
RATE_HZ = 100.0
PERIOD_NS = round(1e9 / RATE_HZ)
KEEPS_PUBLISHING = 150
"""Samples that must still arrive after an attack (behaviour; the rate itself is measured by
``mech-balance bench --section faults``, issue 19 item 6)."""
STORM = 320
"""Invalid parameter updates in the storm (issue 12: at least 300)."""
NESTING = 3000
"""Nesting depth of the hostile scene file (issue 12: a few thousand levels)."""
BRACKETS = 5000
IN_FLIGHT = 5
"""Parameter requests in flight at once in the storm (the service's request history is 10)."""


# ------------------------------------------------------------------------------ no ROS


def test_class1_guard_turns_any_exception_into_a_refusal_or_a_counted_skip():
    warnings = []
    guard = guards.Guard(warnings.append)

    def deep(n):
        return deep(n + 1)

    refused = guard.refusing('parameters', lambda exc, ps: guards.parameter_reason(ps, exc))(
        lambda ps: deep(0))
    p = Parameter('balance.mass_bounds', value='[' * BRACKETS)
    reason = refused([p])
    assert reason.startswith("balance.mass_bounds: got '[[[")
    assert 'RecursionError' in reason and len(reason) < guards.MAX_REASON_CHARS + 100

    @guard.skipping('crank_joint_state')
    def callback(msg):
        raise MemoryError

    for _ in range(50):
        assert callback(None) is None
    assert guard.counts == {'parameters': 1, 'crank_joint_state': 50}
    assert len(warnings) == 1 and 'crank_joint_state: skipped (1 so far)' in warnings[0]
    # a package error keeps its own reason when it names a parameter of the update
    own = guard.refusing('p', lambda exc, ps: guards.parameter_reason(ps, exc))(
        lambda ps: (_ for _ in ()).throw(ValueError('publish_rate: got 0.0, expected ...')))
    assert own([Parameter('publish_rate', value=0.0)]) == 'publish_rate: got 0.0, expected ...'


def test_class4_estimator_checks_velocity_against_the_step_limit():
    est = twin.CrankEstimator(window=5, max_speed=100.0)
    est.update(1_000_000_000, 0.0, 1.0)
    with pytest.raises(ValueError, match=r'velocity: got 1e\+300 rad/s, expected at most '
                                         r'follow.max_speed = 100'):
        est.update(1_001_000_000, 0.001, 1e300)
    with pytest.raises(ValueError, match='velocity: got -100.5 rad/s'):
        est.update(1_001_000_000, 0.001, -100.5)
    assert est.update(1_001_000_000, 0.001, 1.0).speed_rad_s == 1.0


def test_class6_estimator_resynchronizes_after_consecutive_rejections():
    est = twin.CrankEstimator(window=5, max_speed=100.0, resync_after=4)
    t0, dt, omega = 10_000_000_000, 1_000_000, 5.0
    for k in range(5):
        est.update(t0 + k * dt, omega * k * dt * 1e-9)
    est.update(t0 + 10 ** 15, 0.0)  # one glitch far in the future: a long gap restarts
    rejected = 0
    for k in range(5, 20):
        t = t0 + k * dt
        try:
            s = est.update(t, omega * k * dt * 1e-9)
        except twin.StreamRejected:
            rejected += 1
            continue
        if est.just_resynced:
            assert rejected == 3 and est.resyncs == 1 and 'consecutive' in est.last_resync
            assert s is None  # the resynchronizing message primes a new fit
        else:
            assert s.speed_rad_s == pytest.approx(omega, rel=1e-9)
    assert est.resyncs == 1 and est.rejected_in_a_row == 0


def test_class4_streamer_withholds_a_non_finite_sample():
    """The last check before publishing: a NaN row is counted and warned, never sent."""
    model = twin.model_for(scene_mod.load('hoeken'))
    assert model.cycle_table() is not None  # follow mode evaluates by the table

    class Poisoned:
        """The twin, but its shaking force at crank angle 0.2 rad is NaN (both paths)."""

        def __getattr__(self, name):
            return getattr(model, name)

        def evaluate(self, psi, speed, accel=0.0, how=model.evaluate):
            s = how(psi, speed, accel)
            s.force_N[np.isclose(np.asarray(psi, dtype=float), 0.2), 0] = math.nan
            return s

        def follow_evaluate(self, psi, speed, accel=0.0):  # follow mode's (cycle table)
            return self.evaluate(psi, speed, accel, how=model.follow_evaluate)

    sent, warned, done = [], [], threading.Event()

    def publish(payload):
        sent.append(payload)
        if len(sent) >= 7:
            done.set()

    streamer = streamer_mod.Streamer(lambda: 5_000_000_000, lambda s, t: [
        (int(ti), s.force_N[i].copy()) for i, ti in enumerate(t)], publish, warned.append)
    try:
        for k in range(4):
            streamer.push(twin.CrankSample(1_000 + k, 0.1 * k, 0.1 * k, 1.0, 0.0))
        streamer.follow(Poisoned())
        for k in range(8):
            streamer.push(twin.CrankSample(2_000 + k, 0.1 * k, 0.1 * k, 1.0, 0.0))
        assert done.wait(30.0)
    finally:
        streamer.stop()
    assert all(np.all(np.isfinite(p[1])) for p in sent)
    assert 2_002 not in [p[0] for p in sent] and streamer.stats.withheld >= 1
    assert any('withheld a sample with a non-finite value' in w for w in warned)


def test_streamer_treats_a_clock_jump_as_a_jump_not_as_skipped_ticks():
    """use_sim_time switched on or off: the clock jumps; no absurd skipped-tick count."""
    model = twin.model_for(scene_mod.load('hoeken'))
    clock = {'now': 10_000_000_000}
    sent, warned = [], []
    streamer = streamer_mod.Streamer(lambda: clock['now'], lambda s, t: list(t), sent.append,
                                     warned.append)
    try:
        streamer.clock(model, 1.0, PERIOD_NS)
        while len(sent) < 3:
            clock['now'] += PERIOD_NS // 2
            threading.Event().wait(0.001)
        clock['now'] += 1_800_000_000 * 10 ** 9  # wall time after simulated time
        while not any('clock jumped forward' in w for w in warned):
            threading.Event().wait(0.001)
        count = len(sent)
        while len(sent) < count + 3:
            clock['now'] += PERIOD_NS // 2
            threading.Event().wait(0.001)
        assert streamer.stats.skipped == 0
        clock['now'] = 0  # use_sim_time on, no /clock yet
        sent_before = len(sent)
        while not any('clock has read 0' in w for w in warned):
            threading.Event().wait(0.05)
        assert len(sent) <= sent_before + 1
    finally:
        streamer.stop()


def _hoeken_near_change_point(eps):
    """Hoeken's four-bar with rocker = a + b - d + eps (a Grashof change point at eps = 0)."""
    text = (ROOT / 'config' / 'hoeken.yaml').read_text()
    a, b, d = 0.038, 0.11476, 0.0893  # crank, coupler, frame of config/hoeken.yaml
    rocker = a + b - d + eps
    text = text.replace('points: {O3: [0.0, 0.0], B: [0.11476, 0.0]}',
                        f'points: {{O3: [0.0, 0.0], B: [{rocker!r}, 0.0]}}')
    text = text.replace('link_angles_deg: {coupler: 77.0, rocker: 103.0}',
                        'link_angles_deg: {coupler: 20.0, rocker: 90.0}')
    return text


def test_class9_near_singular_warning_from_the_error_bound(tmp_path):
    # the threshold is where 2 kappa^2 NEWTON_TOL reaches the printed resolution
    assert 2.0 * kinematics.COND_WARN ** 2 * kinematics.NEWTON_TOL == \
        pytest.approx(kinematics.PRINTED_RTOL, rel=1e-12)
    near = tmp_path / 'near.yaml'
    near.write_text(_hoeken_near_change_point(1e-8))
    psi = np.linspace(0.0, 2.0 * math.pi, 360, endpoint=False)
    with pytest.warns(RuntimeWarning, match='near-singular'):
        sc = scene_mod.load(str(near))
        data = rig_for(sc).at(psi, 1.0, 0.0)
        report = analysis.analyze(sc)
    cond = float(np.max(data.condition))
    assert kinematics.COND_WARN < cond < 1e4  # the old round threshold missed it
    assert np.any(data.near_singular) and report.data['near_singular']
    assert 'WARNING: near-singular' in report.text
    normal = scene_mod.load('hoeken')
    data = rig_for(normal).at(psi, 1.0, 0.0)
    report = analysis.analyze(normal)
    assert not np.any(data.near_singular) and not report.data['near_singular']
    assert 'WARNING' not in report.text


def test_balance_summary_names_method_figures_and_certificate():
    design = balancing.balance(rig_for(scene_mod.load('slider_crank')), 'analytic')
    line = design.summary()
    assert len(line) < 200 and '\n' not in line
    assert line.startswith('balanced slider_crank (analytic): RMS shaking force')
    force = next(r for r in design.report['table'] if r['quantity'].startswith('shaking force'))
    assert f'{force["before_si"]:.4g} -> {force["after_si"]:.4g} N' in line
    assert 'certificate closed form' in line


def test_per_link_typed_parameters_and_integers_are_checked():
    assert params.check('balance.links.crank.mass_bounds', [1, 2]) == [1.0, 2.0]
    assert params.check('publish_rate', 100) == 100.0
    assert params.coerced('publish_rate', 100) == 100.0
    assert params.coerced('balance.links.crank.mass_bounds', []) == []
    for name, value, reason in (
            ('balance.links.crank.mass_bounds', [2.0, 1.0], r'\[\] \(the factors\), \[min\]'),
            ('balance.links.crank.mass_bounds', [0.0], '0 < min'),
            ('balance.links.crank.distance_bounds', [1.0, math.nan], 'finite numbers'),
            ('balance.density', -1.0, 'a number > 0'),
            ('balance.method', 'magic', 'one of redistribution, counterweights, analytic'),
            ('publish_rate', 10 ** 400, 'a finite number')):
        with pytest.raises(ValueError, match=reason) as err:
            params.check(name, value)
        assert str(err.value).startswith(f'{name}: got ')
    values = params.defaults()
    values.update({'balance.mass_bounds': '{crank: [0.3, 1.6]}',
                   'balance.links.crank.mass_bounds': [0.5],
                   'balance.links.rocker.mass_bounds': [0.7, 2.0]})
    with pytest.raises(ValueError, match='balance.links.crank.mass_bounds: got .* no second'):
        params.check_links(values, ['crank', 'coupler', 'rocker'])
    values['balance.mass_bounds'] = ''
    opts = params.balance_options(values)
    assert opts['mass_bounds'] == {'crank': (0.5, None), 'rocker': (0.7, 2.0)}


# ------------------------------------------------------------------------------ processes


@pytest.fixture(scope='module')
def clock_rig(context):
    """One hoeken node in clock mode at RATE_HZ for the parameter tests, and its probe."""
    ns = tn._namespace('hard')
    rig = tn.RigProcess(ns, '-p', f'publish_rate:={RATE_HZ}')
    probe = tn.Probe(context, ns)
    try:
        probe.wait_for_rig(rig)
        yield rig, probe
    finally:
        probe.destroy()
        rig.stop()


def _set(probe, name, value):
    future = probe.params.set_parameters([Parameter(name, value=value)])
    probe.spin_until(future.done, what='the parameter service')
    return future.result().results[0]


def _keeps_publishing(probe, count=KEEPS_PUBLISHING):
    """Wait for ``count`` more samples, each on the clock-mode schedule (a period multiple)."""
    probe.collect(count)
    stamps = np.unique([j[0] for j in probe.joints])
    assert stamps.size >= count and np.all(np.diff(stamps) % PERIOD_NS == 0)


def _deep_scene(tmp_path):
    path = tmp_path / 'deep.yaml'
    path.write_text('a: ' + '[' * NESTING + ']' * NESTING + '\n')
    return str(path)


def test_class1_deep_nesting_parameter_refused_and_publishing_goes_on(clock_rig, tmp_path):
    rig, probe = clock_rig
    result = _set(probe, 'scene', _deep_scene(tmp_path))
    assert not result.successful and result.reason.startswith('scene'), result.reason
    assert 'nesting deeper than' in result.reason
    result = _set(probe, 'balance.mass_bounds', '[' * BRACKETS + ']' * BRACKETS)
    assert not result.successful
    assert result.reason.startswith('balance.mass_bounds'), result.reason
    assert rig.alive()
    _keeps_publishing(probe)
    assert probe.get_param('scene').string_value == 'hoeken'


def test_class1_parameter_storm_is_answered_and_publishing_goes_on(clock_rig, tmp_path):
    rig, probe = clock_rig
    deep = _deep_scene(tmp_path)
    bad = [('scene', deep), ('balance.mass_bounds', '[' * BRACKETS), ('publish_rate', math.nan),
           ('publish_rate', -1.0), ('publish_rate', 'fast'), ('balance.weights', [0.0, 0.0]),
           ('frame_id', 'x' * 100_000), ('balance.links.crank.mass_bounds', [3.0, 1.0]),
           ('balance.fixed_links', 'crank,crank'), ('mode', 'dance')]
    futures = []
    probe.after_ns = probe.node.get_clock().now().nanoseconds
    probe.joints.clear()
    probe.wrenches.clear()
    for i in range(STORM):  # at most IN_FLIGHT requests queued (the service's history)
        probe.spin_until(lambda: sum(not f.done() for f in futures) < IN_FLIGHT,
                         what='the parameter service')
        name, value = bad[i % len(bad)]
        futures.append(probe.params.set_parameters([Parameter(name, value=value)]))
    probe.spin_until(lambda: all(f.done() for f in futures), 120.0, 'the storm to be answered')
    results = [f.result().results[0] for f in futures]
    assert not any(r.successful for r in results)
    assert all(r.reason.startswith(bad[i % len(bad)][0]) for i, r in enumerate(results))
    stamps = np.unique([j[0] for j in probe.joints])
    print(f'storm: {STORM} refused updates, {stamps.size} ticks received meanwhile')
    assert stamps.size > 0, 'nothing published during the storm'
    assert rig.alive()
    _keeps_publishing(probe)


def test_integer_for_a_double_is_accepted(clock_rig):
    rig, probe = clock_rig
    result = _set(probe, 'publish_rate', 50)  # Parameter type INTEGER, as ros2 param set 50
    assert result.successful, result.reason
    assert probe.get_param('publish_rate').type == ParameterType.PARAMETER_DOUBLE
    probe.collect(20)
    stamps = np.unique([j[0] for j in probe.joints])
    assert np.median(np.diff(stamps)) == 2 * PERIOD_NS
    assert _set(probe, 'publish_rate', RATE_HZ).successful


@pytest.mark.parametrize('name, value', [
    ('publish_rate', -5.0), ('publish_rate', math.nan), ('publish_rate', 'fast'),
    ('crank_speed', 1e9), ('follow.window', 1), ('follow.window', 2.5),
    ('mode', 'dance'), ('balance.weights', [1.0]), ('balance.samples', 3),
    ('balance.links.crank.mass_bounds', [0.0, 1.0]),
    ('balance.links.crank.mass_bounds', ['a']), ('balance.fixed_links', 'wheel'),
    ('balance.counterweight_links', 'crank,crank'), ('balance.density', 0.0),
    ('balance.clearance_margin', -0.001), ('balance.disc_side', 'left'),
    ('balance.max_overhang', -1.0), ('balance.method', 'magic'), ('use_balanced', 'yes'),
    ('scene', 'no_such_scene'),
])
def test_every_refusal_reason_starts_with_the_parameter_name(clock_rig, name, value):
    rig, probe = clock_rig
    result = _set(probe, name, value)
    assert not result.successful
    assert result.reason.startswith(f'{name}: got '), result.reason


def test_typed_per_link_bounds_through_the_parameter_service(clock_rig):
    rig, probe = clock_rig
    name = 'balance.links.crank.mass_bounds'
    assert probe.get_param(name).type == ParameterType.PARAMETER_DOUBLE_ARRAY
    assert _set(probe, name, [0.3, 1.6]).successful  # DOUBLE_ARRAY, as ros2 param set
    assert _set(probe, 'balance.links.rocker.mass_bounds', [1, 3]).successful  # INTEGER_ARRAY
    value = probe.get_param('balance.links.rocker.mass_bounds')
    assert value.type == ParameterType.PARAMETER_DOUBLE_ARRAY
    assert list(value.double_array_value) == [1.0, 3.0]
    result = _set(probe, 'balance.mass_bounds', '{crank: [0.4, 1.0]}')
    assert not result.successful and 'no second bound' in result.reason
    answer = probe.call(probe.balance, 120.0)
    assert answer.success, answer.message
    report = yaml.safe_load(answer.message)['report']   # Design.to_dict(): the method's
    assert report['bounds']['crank']['mass_kg'] == [0.3, 1.6]
    assert report['bounds']['rocker']['mass_kg'] == [1.0, 3.0]
    assert _set(probe, name, []).successful and probe.call(probe.reset).success
    assert _set(probe, 'balance.links.rocker.mass_bounds', []).successful


def test_balance_answer_first_line_is_a_summary_and_the_result_is_published(clock_rig):
    rig, probe = clock_rig
    answer = probe.call(probe.balance, 120.0)
    assert answer.success, answer.message
    first, second, third, rest = answer.message.split('\n', 3)
    # the headline fits ros2 topic echo's 128-character cut (with "data: '" before it)
    assert len(first) < 128 - 7 and first.startswith('# balanced hoeken (redistribution): ')
    for word in ('RMS shaking force', 'moment', '->', 'certified'):
        assert word in first, first
    assert third.startswith('# certificate Solved'), third
    assert '--full-length' in second and not rest.startswith('#')
    assert '\n  ' in rest   # block YAML, nested keys indented a line each
    path = second.split('full result: ')[1].split(' and ')[0]
    assert Path(path).read_text() == answer.message   # one text: answer, file and topic
    assert yaml.safe_load(answer.message) == yaml.safe_load(rest)  # comments: still YAML
    got = []
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    sub = probe.node.create_subscription(String, 'rig/balance_result',
                                         lambda m: got.append(m.data), latched)
    try:
        probe.spin_until(lambda: got, what='~/balance_result (a late joiner)')
    finally:
        probe.node.destroy_subscription(sub)
    assert got[-1] == answer.message
    assert probe.call(probe.reset).success


def test_balance_method_counterweights_answer_carries_counterweights(clock_rig):
    rig, probe = clock_rig
    assert _set(probe, 'balance.method', 'counterweights').successful
    assert _set(probe, 'balance.counterweight_links', 'crank,rocker').successful
    assert _set(probe, 'balance.weights', [1.0, 0.0]).successful
    try:
        answer = probe.call(probe.balance, 120.0)
        assert answer.success, answer.message
        assert answer.message.startswith('# balanced hoeken (counterweights): ')
        report = yaml.safe_load(answer.message)['report']
        expected = balancing.balance(rig_for(scene_mod.load('hoeken')), 'counterweights',
                                     links=('crank', 'rocker'), weights=(1.0, 0.0)).report
        assert set(report['counterweights']) == {'crank', 'rocker'}
        for link, discs in report['counterweights'].items():
            (disc,) = discs
            # collision-free by default (issue 29): each disc in its layer, on its mount
            assert set(disc) == {'mass_kg', 'centre_m', 'radius_m', 'thickness_m',
                                 'density_kg_m3', 'plane_m', 'mount'}
            ref = expected['counterweights'][link][0]
            assert disc['plane_m'] == ref['plane_m'] and disc['mount'] == ref['mount']
            assert disc['mass_kg'] == pytest.approx(ref['mass_kg'], rel=1e-6)
        assert report['certificate']['gap_rel'] <= 1e-7
        design = report['clearance_design']
        assert design['status'] == 'collision-free'
        assert design['lower_bound'] <= design['objective']
        assert design['least_clearance_m'] >= design['margin_m']
        # the clearance over the cycle (issue 19 item 5; issue 29: clear by default)
        least = report['clearance']['least_clearance_m']
        assert least == pytest.approx(expected['clearance']['least_clearance_m'], abs=1e-6)
        assert least >= design['margin_m'] and report['warnings'] == []
    finally:
        for name, value in (('balance.method', 'redistribution'),
                            ('balance.counterweight_links', ''), ('balance.weights', [0.5, 0.5])):
            assert _set(probe, name, value).successful
        probe.call(probe.reset)


def test_balance_with_no_clear_counterweights_fails_with_the_reason(clock_rig):
    """No collision-free design: the call fails naming why, the node publishes none."""
    rig, probe = clock_rig
    for name, value in (('balance.method', 'counterweights'),
                        ('balance.counterweight_links', 'crank,rocker'),
                        ('balance.max_overhang', 0.001)):
        assert _set(probe, name, value).successful
    try:
        answer = probe.call(probe.balance, 120.0)
        assert not answer.success
        assert answer.message.startswith('balancing failed: ') and \
            'max overhang 0.001 m' in answer.message, answer.message
        assert _set(probe, 'balance.clearance', False).successful   # the convex optimum
        answer = probe.call(probe.balance, 120.0)
        assert answer.success, answer.message
        report = yaml.safe_load(answer.message)['report']
        assert report['clearance_design'] is None and report['warnings']
    finally:
        for name, value in (('balance.method', 'redistribution'), ('balance.clearance', True),
                            ('balance.counterweight_links', ''), ('balance.max_overhang', 0.0)):
            assert _set(probe, name, value).successful
        probe.call(probe.reset)


def test_wrapped_joint_positions_and_no_negative_zero(clock_rig):
    rig, probe = clock_rig
    assert _set(probe, 'crank_speed', 6.0).successful  # a full turn in about 1 s
    try:
        probe.collect(int(RATE_HZ * 1.2))
    finally:
        assert _set(probe, 'crank_speed', 0.0).successful
    positions = np.array([j[2] for j in probe.joints])
    assert np.all((positions > -math.pi) & (positions <= math.pi))
    assert np.ptp(positions[:, 0]) > 5.0  # the crank went round (and was wrapped)
    values = np.concatenate([np.concatenate([j[2], j[3], j[4]]) for j in probe.joints])
    assert not np.any((values == 0.0) & np.signbit(values))


def _follow_rig(context, tag, *args):
    ns = tn._namespace(tag)
    rig = tn.RigProcess(ns, '-p', 'scene:=slider_crank', '-p', 'mode:=follow', *args)
    probe = tn.Probe(context, ns)
    probe.wait_for_rig(rig)
    probe.spin_until(lambda: probe.encoder.get_subscription_count() >= 1,
                     tn.DISCOVERY_TIMEOUT_S, 'the node to subscribe to the encoder')
    # Matched on our side is not matched on the node's: until its encoder reader and its
    # wrench writer know our endpoints, messages are dropped or re-sent in a burst.  Send
    # stamped readings (with a velocity: each one is a sample) until a wrench comes back,
    # then ignore everything stamped up to the last of them (the tests' stamps are later).
    sent = {'stamp': HANDSHAKE_STAMP_NS, 'next': 0.0}

    def answered():   # one more reading every 50 ms until a wrench comes back
        if probe.wrenches:
            return True
        if time.monotonic() >= sent['next']:
            sent['stamp'] += 1_000_000
            sent['next'] = time.monotonic() + 0.05
            probe.encoder.publish(tn._encoder(['O'], sent['stamp'], [0.3], [1.0]))
        return False
    probe.spin_until(answered, tn.DISCOVERY_TIMEOUT_S, 'a wrench for a handshake reading')
    probe.after_ns = sent['stamp']
    probe.joints.clear()
    probe.wrenches.clear()
    return rig, probe


HANDSHAKE_STAMP_NS = 1_000 * 10 ** 9
"""Stamps of :func:`_follow_rig`'s handshake readings (before every test's own stamps)."""


def _send(probe, msgs):
    for m in msgs:
        probe.encoder.publish(m)
        probe.executor.spin_once(timeout_sec=0.002)


def _all_finite(probe):
    return all(np.all(np.isfinite(w[2])) for w in probe.wrenches) and all(
        np.all(np.isfinite(np.concatenate(j[2:]))) for j in probe.joints)


def test_class4_absurd_velocity_publishes_nothing_non_finite_and_recovers(context):
    rig, probe = _follow_rig(context, 'vel')
    omega, dt, t0 = 40.0, 1_000_000, 2_000 * 10 ** 9
    try:
        good = [t0 + k * dt for k in range(30)]
        msgs = []
        for k, t in enumerate(good):
            msgs.append(tn._encoder(['O'], t, [0.3 + omega * k * 1e-3], [omega]))
            if k in (10, 20):
                msgs.append(tn._encoder(['O'], t + 1, [0.3 + omega * k * 1e-3], [1e300]))
        _send(probe, msgs)
        probe.spin_until(lambda: {w[0] for w in probe.wrenches} >= set(good) and
                         {j[0] for j in probe.joints} >= set(good), what='the good stream')
        assert _all_finite(probe) and {w[0] for w in probe.wrenches} == set(good)
        assert rig.alive()
    finally:
        probe.destroy()
        log = rig.stop()
    assert 'velocity: got 1e+300 rad/s, expected at most follow.max_speed' in log


def test_class6_far_future_stamp_resynchronizes_on_the_stream(context):
    rig, probe = _follow_rig(context, 'future', '-p', 'follow.resync_after:=5')
    omega, dt, t0 = 40.0, 1_000_000, 3_000 * 10 ** 9
    try:
        first = [t0 + k * dt for k in range(10)]
        future = t0 + 86_400 * 10 ** 9  # a day ahead
        later = [t0 + (10 + k) * dt for k in range(30)]
        msgs = [tn._encoder(['O'], t, [0.3 + omega * (t - t0) * 1e-9], [omega]) for t in first]
        msgs.append(tn._encoder(['O'], future, [0.3], [omega]))
        msgs += [tn._encoder(['O'], t, [0.3 + omega * (t - t0) * 1e-9], [omega]) for t in later]
        _send(probe, msgs)
        # 4 rejected, the 5th re-synchronizes (published: it has a velocity), then all
        followed = set(later[4:])
        probe.spin_until(lambda: {w[0] for w in probe.wrenches} >= followed, what='recovery')
        got = {w[0] for w in probe.wrenches}
        assert got == set(first) | {future} | followed
        assert _all_finite(probe) and rig.alive()
    finally:
        probe.destroy()
        log = rig.stop()
    assert log.count('re-synchronized on the incoming stream') == 1, log


def test_class5_zero_stamps_are_followed_at_their_receive_time(context):
    rig, probe = _follow_rig(context, 'zero')
    try:
        sent_after = probe.node.get_clock().now().nanoseconds
        msgs = [tn._encoder(['O'], 0, [0.5 + 0.01 * k]) for k in range(20)]
        for m in msgs:  # as `ros2 topic pub -r 100`: paced, stamp 0
            probe.encoder.publish(m)
            due = time.monotonic() + 0.01
            probe.spin_until(lambda: time.monotonic() >= due, what='the next send time')
        probe.spin_until(lambda: len(probe.wrenches) >= 19, what='a sample per message')
        stamps = sorted(w[0] for w in probe.wrenches)
        assert len(stamps) == 19 and stamps[0] > sent_after  # the first message primes
        assert np.all(np.diff(stamps) > 0) and _all_finite(probe)
    finally:
        probe.destroy()
        log = rig.stop()
    assert log.count('unset (zero) stamp') == 1, log


def test_use_sim_time_without_clock_is_reported(context):
    with tn.matched_rig(context, tn._namespace('noclock'), '-p', 'use_sim_time:=true') as \
            (rig, probe):
        probe.spin_until(lambda: 'no /clock message has arrived' in rig.output(),
                         what='the warning about a missing /clock')
        assert not probe.joints and rig.alive()
