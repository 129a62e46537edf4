"""
Follow mode's cycle table (mech_balance/ros/cycle_table.py): against the exact core.

Behaviour only (its speed is in ``mech-balance bench --section node``): on every built-in,
planar and spatial, the table agrees with the model's exact evaluation within the accuracy
it states (measured when it is built) at angles, speeds and accelerations it was not built
or checked on; a new design gets a new table; where the table cannot be trusted (not affine,
near-singular, not periodic, a failing core, too sharp for the bound) it is refused with the
reason and follow mode evaluates the core.
"""

from dataclasses import replace
import math
import re

from mech_balance import schema as scene_mod
from mech_balance.ros import cycle_table, description, streamer as streaming_threads, streaming
from mech_balance.schema import scene as scenes
import numpy as np
import pytest

SCENES = sorted(scenes.builtin_scenes())
TOL_FACTOR = 4.0
"""Off the check points the error may exceed the largest one found there a little (the
stated accuracy is a measured maximum, not a bound): allowed this factor."""


def _model(name):
    return description.twin_for(scene_mod.load(name))


def _errors(table, exact, got):
    """Return the largest error of ``got`` per channel, relative to the table's scale."""
    want, got = cycle_table._stack(exact), cycle_table._stack(got)
    j = exact.joint_position.shape[1]
    diff = np.abs(got - want)
    angular = table._angular
    diff[:, :j] = np.where(angular, np.abs(cycle_table.wrap_angle(got[:, :j] - want[:, :j])),
                           diff[:, :j])
    scale = cycle_table._floored(np.max(np.abs(want), axis=0), j,
                                 exact.joint_effort is not None)
    return np.max(diff, axis=0) / scale


@pytest.mark.parametrize('name', SCENES)
def test_table_agrees_with_the_core_within_its_stated_accuracy(name):
    model = _model(name)
    table = model.cycle_table()
    assert table is not None, model.table_status
    assert model.table_status == table.report.summary()
    assert 0.0 <= table.accuracy <= cycle_table.BOUND
    assert f'{table.accuracy:.1e}' in model.table_status
    rng = np.random.default_rng(22)
    n = 300
    psi = rng.uniform(-4.0 * math.pi, 6.0 * math.pi, n)   # encoders that do not wrap too
    speed = rng.uniform(-60.0, 60.0, n)
    accel = rng.uniform(-400.0, 400.0, n)
    exact = model.evaluate(psi, speed, accel)
    got = model.follow_evaluate(psi, speed, accel)
    assert got.joint_names == exact.joint_names == model.joint_names
    assert (got.joint_effort is None) == (exact.joint_effort is None)
    err = _errors(table, exact, got)
    assert np.max(err) <= TOL_FACTOR * max(table.accuracy, 1e-15), (name, err)
    # as published: angles in (-pi, pi], no -0.0, a sample alone as in a batch
    pos = got.joint_position[:, table._angular]
    assert np.all(pos > -math.pi) and np.all(pos <= math.pi)
    for values in (got.joint_position, got.joint_velocity, got.force_N, got.moment_Nm):
        assert not np.any(np.signbit(values) & (values == 0.0))
    one = model.follow_evaluate(psi[3:4], speed[3], accel[3])
    np.testing.assert_allclose(one.force_N[0], got.force_N[3], rtol=1e-13, atol=1e-13)
    # the body poses (the recording's) are the core's, evaluated when read
    np.testing.assert_allclose(got.bodies.origin_m, exact.bodies.origin_m, rtol=0, atol=1e-12)
    # the crank joint is the crank angle, wrapped
    crank = got.joint_position[:, model.crank_index]
    exact_crank = exact.joint_position[:, model.crank_index]
    assert np.max(np.abs(cycle_table.wrap_angle(crank - exact_crank))) <= 1e-12


def test_a_new_design_gets_a_new_table():
    for name in ('hoeken', 'rssr_skew'):
        model = _model(name)
        base = model.cycle_table()
        sc = model.scene
        first = sc.links[1]
        heavier = sc.with_links([replace(lk, mass_kg=lk.mass_kg * 1.5 + 0.1)
                                 if lk.name == first.name else lk for lk in sc.links])
        other = model.with_design(heavier)
        table = other.cycle_table()
        assert table is not None and table is not base, other.table_status
        psi = np.linspace(0.05, 6.2, 40)
        old = model.follow_evaluate(psi, 7.0, 3.0)
        new = other.follow_evaluate(psi, 7.0, 3.0)
        assert np.max(np.abs(new.force_N - old.force_N)) > 1e-6 * np.max(np.abs(old.force_N))
        err = _errors(table, other.evaluate(psi, 7.0, 3.0), new)
        assert np.max(err) <= TOL_FACTOR * max(table.accuracy, 1e-15)


def _refused(evaluate, model, match):
    """Return the reason the table of ``evaluate`` is refused (it must be, naming ``match``)."""
    with pytest.raises(cycle_table.TableRefused, match=match) as info:
        cycle_table.CycleTable.build(evaluate, model.published_angular())
    return str(info.value)


def _accuracy_in(reason):
    """Return the verified accuracy and the grid a 'too coarse' refusal names."""
    m = re.search(r'verified accuracy (\S+) exceeds the bound \S+ on (\d+) angles', reason)
    assert m, reason
    return float(m.group(1)), int(m.group(2))


def test_refused_where_the_outputs_are_not_affine_in_speed_and_acceleration():
    model = _model('slider_crank')

    def coulomb(psi, speed, accel=0.0):  # a dry friction torque: sign(w), not affine
        s = model.evaluate(psi, speed, accel)
        w = np.broadcast_to(np.asarray(speed, dtype=float), s.force_N.shape[:1])
        s.joint_effort = s.joint_effort + 0.3 * np.sign(w)[:, None]
        return s
    assert cycle_table.CycleTable.build(model.evaluate, model.published_angular()).accuracy \
        <= cycle_table.BOUND                     # the same rig without the friction: built
    accuracy, grid = _accuracy_in(_refused(coulomb, model, 'accuracy'))
    assert accuracy > 1e3 * cycle_table.BOUND    # the sign term is an O(1) error
    assert grid == max(cycle_table.GRIDS)        # refused after the finest grid was tried


def test_refused_where_the_rig_is_near_singular_or_the_core_fails():
    model = _model('hoeken')

    def near(psi, speed, accel=0.0):
        s = model.evaluate(psi, speed, accel)
        s.near_singular = np.abs(np.mod(s.crank_angle_rad, 2 * math.pi) - 1.0) < 0.03
        return s
    _refused(near, model, 'near-singular')

    def fails(psi, speed, accel=0.0):
        if np.any(np.abs(np.mod(psi, 2 * math.pi) - 2.0) < 0.05):
            raise ValueError('the linkage cannot be assembled')
        return model.evaluate(psi, speed, accel)
    _refused(fails, model, 'fails')

    def nan(psi, speed, accel=0.0):
        s = model.evaluate(psi, speed, accel)
        s.force_N = np.where(np.abs(np.mod(s.crank_angle_rad, 2 * math.pi) - 3.0)[:, None]
                             < 0.05, np.nan, s.force_N)
        return s
    _refused(nan, model, 'not finite')


def test_refused_where_a_position_is_not_periodic_or_too_sharp_for_the_bound():
    model = _model('hoeken')

    def half_turn(psi, speed, accel=0.0):  # a joint turning half as fast as the crank
        s = model.evaluate(psi, speed, accel)
        s.joint_position = s.joint_position.copy()
        s.joint_position[:, 2] = streaming.wrap_angle(0.5 * np.asarray(s.crank_angle_rad))
        return s
    assert 'joint position' in _refused(half_turn, model, 'not periodic')

    def sharp(psi, speed, accel=0.0):  # a force spike no grid of GRIDS resolves to 1e-10
        s = model.evaluate(psi, speed, accel)
        d = np.mod(s.crank_angle_rad, 2 * math.pi) - 1.0
        s.force_N = s.force_N + (1.0 / (1.0 + (d / 1e-4) ** 2))[:, None]
        return s
    accuracy, grid = _accuracy_in(_refused(sharp, model, 'accuracy'))
    assert accuracy > cycle_table.BOUND and grid == max(cycle_table.GRIDS)


def test_follow_mode_evaluates_the_core_when_the_table_is_refused():
    model = _model('hoeken')
    real = model.evaluate
    calls = []

    def near(psi, speed, accel=0.0):
        calls.append(len(np.atleast_1d(psi)))
        s = real(psi, speed, accel)
        s.near_singular = np.ones(len(s), dtype=bool)
        return s
    model.evaluate = near
    assert model.cycle_table() is None
    assert model.table_status.startswith('exact core per sample (no cycle table: ')
    assert 'near-singular' in model.table_status
    calls.clear()
    model.follow_evaluate([0.4], [3.0], [0.0])
    assert calls == [1]   # the exact evaluation


def test_the_streamer_uses_the_table_unless_follow_exact():
    class Model:
        def __init__(self):
            self.used = []
            self.inner = _model('slider_crank')
            self.inner.cycle_table()

        def evaluate(self, psi, speed, accel=0.0):
            self.used.append('exact')
            return self.inner.evaluate(psi, speed, accel)

        def follow_evaluate(self, psi, speed, accel=0.0):
            self.used.append('table')
            return self.inner.follow_evaluate(psi, speed, accel)

    streamer = streaming_threads.Streamer(lambda: 1, lambda samples, stamps: list(stamps),
                                          lambda payload: None, lambda text: None)
    try:
        streamer.stop()
        model = Model()
        batch = [streaming.CrankSample(5 + k, 0.1 * k, 0.1 * k, 2.0, 0.0) for k in range(3)]
        assert streamer._evaluate_follow(model, batch) == [5, 6, 7]
        streamer.follow_exact = True
        assert streamer._evaluate_follow(model, batch) == [5, 6, 7]
        assert model.used == ['table', 'exact']
    finally:
        streamer.stop()
