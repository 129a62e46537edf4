"""
A scene switch publishes the new rig before its background work ends (issue 31 item 3).

The rig node runs in this process (rclpy, its own context) with the follow-mode cycle table
build held back by an event: after ``scene`` is set, samples of the new scene arrive while
the table of the new scene is still being built (follow mode evaluates the exact core
meanwhile); once released, the table is built.  Every published JointState belongs to one
scene: its names are the old scene's or the new one's, with as many values as names, and
none of the old scene follows the first of the new.  Counts and order, never a time.
"""

import math
import os
import sys
import threading

from mech_balance.ros import node as rig_node, parameters as node_params, streaming
import pytest
import rclpy
from rclpy.executors import MultiThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState

sys.path.insert(0, os.path.dirname(__file__))
import test_node as tn  # noqa: E402, I100

OLD, NEW = 'slider_crank', 'hoeken'
TIMEOUT_S = 60.0
"""Upper bound of every wait (the machine may be loaded); the test never asserts a time."""


@pytest.fixture
def held_tables(monkeypatch):
    """Hold every cycle-table build of a ``NEW`` twin until the event is set."""
    release = threading.Event()
    started = threading.Event()
    build = streaming.TwinModel.cycle_table

    def held(model):
        if model.scene.name == NEW:
            started.set()
            release.wait(TIMEOUT_S)
        return build(model)
    monkeypatch.setattr(streaming.TwinModel, 'cycle_table', held)
    yield started, release
    release.set()


def test_the_new_rig_publishes_before_its_cycle_table_is_built(held_tables):
    started, release = held_tables
    old, new = node_params.build_model(OLD), node_params.build_model(NEW)
    assert set(old.joint_names) != set(new.joint_names)
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=tn.DOMAIN_ID)
    ns = tn._namespace('switch')
    rig = rig_node.RigNode(context=ctx, namespace=ns, parameter_overrides=[
        Parameter('scene', value=OLD), Parameter('mode', value='follow'),
        Parameter('publish_robot_description', value=False)])
    probe = rclpy.create_node('switch_probe', namespace=ns, context=ctx)
    received = []
    lock = threading.Lock()

    def keep(msg):
        with lock:
            received.append((tuple(msg.name), len(msg.position), len(msg.velocity)))
    probe.create_subscription(JointState, 'joint_states', keep, QoSProfile(depth=1000))
    encoder = probe.create_publisher(JointState, 'crank_joint_state', QoSProfile(depth=1000))
    executor = MultiThreadedExecutor(num_threads=4, context=ctx)
    executor.add_node(rig)
    executor.add_node(probe)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    stamp = [10 ** 12]

    def feed_until(model, done, what):
        """Send the encoder of ``model`` (1 kHz stamps) until ``done()``; fail after long."""
        omega = model.scene.crank_speed_rad_s
        end = threading.Event()
        for _ in range(int(TIMEOUT_S / 0.002)):
            if done():
                return
            stamp[0] += 1_000_000
            angle = math.remainder(0.3 + omega * stamp[0] * 1e-9, 2 * math.pi)
            encoder.publish(tn._encoder([model.crank_joint], stamp[0], [angle]))
            end.wait(0.002)
        pytest.fail(f'no {what} within {TIMEOUT_S:g} s')

    def got(names):
        with lock:
            return any(r[0] == names for r in received)

    try:
        feed_until(old, lambda: got(old.joint_names), f'sample of {OLD}')
        assert rig.set_parameters([Parameter('scene', value=NEW)])[0].successful
        feed_until(new, lambda: got(new.joint_names), f'sample of {NEW}')
        published = rig._state.published
        assert published.scene.name == NEW
        # the new rig publishes while its cycle table is still being built (held here)
        assert started.is_set() and not release.is_set()
        assert published.table_status is None
        release.set()
        feed_until(new, lambda: published.table_status is not None, 'cycle table of NEW')
        with lock:
            count = len(received)
        feed_until(new, lambda: len(received) > count + 20, f'more samples of {NEW}')
    finally:
        release.set()
        executor.shutdown()
        rig.destroy_node()
        probe.destroy_node()
        rclpy.try_shutdown(context=ctx)
    with lock:
        seen = list(received)
    scenes = {old.joint_names: OLD, new.joint_names: NEW}
    for names, n_position, n_velocity in seen:
        assert names in scenes, f'a JointState of neither scene: {names}'
        assert n_position == n_velocity == len(names)
    first_new = [scenes[n] for n, _, _ in seen].index(NEW)
    assert all(scenes[n] == NEW for n, _, _ in seen[first_new:]), \
        f'a sample of {OLD} published after the first of {NEW}'
