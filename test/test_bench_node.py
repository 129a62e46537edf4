"""
The node bench's day-ahead ``~/identify`` section: registered, its inputs right (issue 20).

Behaviour only: the bench measures times and memory, this checks what it feeds the node and
the bound it reports against, never a time.
"""

import math

from mech_balance import schema
from mech_balance.bench import core, identify_stamps, node
from mech_balance.ros import sensor
import numpy as np
import pytest


def test_section_is_registered_under_its_name():
    names = [core.section_name(s) for s in core.SECTIONS]
    assert 'identify_stamps' in names
    fills = identify_stamps.ID_SECONDS * identify_stamps.ID_RATE_HZ   # fills the buffer
    assert fills >= sensor.IDENTIFY_CAPACITY


def test_buffer_bound_is_the_sensor_series_at_twice_their_capacity():
    # encoder track (stamp + 2 columns), pending (stamp + 6), measured (6), paired (13)
    by_hand = 2 * 8 * (sensor.IDENTIFY_CAPACITY * (1 + 2) + sensor.PENDING_CAPACITY * (1 + 6)
                       + sensor.IDENTIFY_CAPACITY * (1 + 6) + sensor.PAIRED_CAPACITY * (1 + 13))
    assert identify_stamps.identify_buffer_bytes() == by_hand


def test_rig_stream_is_a_quantized_wrapped_encoder_and_a_planar_wrench():
    t_ns, pos, force, torque = identify_stamps.rig_stream(schema.load('hoeken'), 0.05,
                                                          counts=4096)
    assert t_ns.shape == (50,) and force.shape == torque.shape == (50, 3)
    assert np.all(np.diff(t_ns) == 1_000_000)
    assert np.all((pos >= 0.0) & (pos < 2.0 * math.pi))
    counts = pos / (2.0 * math.pi / 4096)
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)
    assert np.all(force[:, 2] == 0.0) and np.all(torque[:, :2] == 0.0)
    assert np.all(np.isfinite(force)) and np.ptp(force[:, 0]) > 0.0


def test_follow_path_times_the_nodes_own_follow_path():
    # the bench's follow figures: the node's Publisher and Streamer on encoder messages,
    # one payload (both messages serialized) per accepted message, the table or the core
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState
    from geometry_msgs.msg import WrenchStamped
    for exact in (False, True):
        path = node.FollowPath('slider_crank', exact=exact, messages=40)
        try:
            assert path.run(1) == []              # the first position primes the fit
            payloads = path.run(1) + path.run(node.FOLLOW_BATCH)
            assert len(payloads) == 1 + node.FOLLOW_BATCH
            assert path.evaluation().startswith(
                'exact core per sample (follow.exact)' if exact else 'cycle table of ')
            joints = [deserialize_message(p[0], JointState) for p in payloads]
            wrench = [deserialize_message(p[1], WrenchStamped) for p in payloads]
            psi = np.array([j.position[path.model.crank_index] for j in joints])
            speed = np.array([j.velocity[path.model.crank_index] for j in joints])
            ref = path.model.evaluate(psi, speed, 0.0)   # constant speed: accel ~ 0
            got = np.array([[w.wrench.force.x, w.wrench.force.y] for w in wrench])
            scale = np.max(np.abs(ref.force_N[:, :2]))
            assert np.max(np.abs(got - ref.force_N[:, :2])) <= 1e-9 * scale
            with pytest.raises(RuntimeError, match='used up'):
                path.run(40)
        finally:
            path.close()
