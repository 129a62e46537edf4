"""
joint_states drives the URDF, and the node publishes the URDF on robot_description.

Forward kinematics of the URDF (yourdfpy, an independent URDF library) at the published
joint values must put every joint point, both points of each cut joint included, where the
core puts them.  In this process for every built-in scene (:class:`description.UrdfTwin`,
what the node publishes from); across processes for hoeken and the RGGR, from the URDF the
node publishes on ``robot_description``, received by a late-joining (transient local)
subscriber, and the ``joint_states`` it publishes over a full crank turn.
"""

import io
import math
import os

from mech_balance import schema as scene_mod
from mech_balance.balancing import redistribution
from mech_balance.core.rig import rig_for
from mech_balance.ros import description, streaming as twin, urdf
import numpy as np
from numpy.testing import assert_allclose
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String
from test_node import DISCOVERY_TIMEOUT_S, DOMAIN_ID, Probe, RigProcess

yourdfpy = pytest.importorskip('yourdfpy')

POINT_TOL_M = 1e-9
"""Acceptance: URDF forward kinematics at the published joints against the core's points."""
SCENES = sorted(scene_mod.builtin_scenes())
CRANK_SPEED = 10.0
"""Crank speed of the node runs, rad/s: at 100 Hz a turn is 63 samples."""
TURN_SAMPLES = 80
"""Samples collected from the node: more than one turn at :data:`CRANK_SPEED`."""
MAX_GAP_RAD = 0.2
"""The collected crank angles leave no gap wider than this on the circle (a full turn)."""


def _robot(text):
    robot = yourdfpy.URDF.load(io.StringIO(text), load_meshes=False,
                               build_collision_scene_graph=False)
    assert robot.validate()
    return robot


def _pins(robot):
    """Return ``{(link, point): xyz in the URDF link frame}`` of the pin visuals."""
    return {(name, v.name[4:]): v.origin[:3, 3] for name, link in robot.link_map.items()
            for v in link.visuals if v.name and v.name.startswith('pin_')}


def _worst_point_error(robot, root, rig, psi, speed, names, positions):
    """
    Return the largest distance between URDF and core joint points over the samples.

    The URDF side: forward kinematics at ``positions`` (the published joint values, by
    ``names``) of every pin of every link.  The core side: the rig's body poses at the
    published crank angles ``psi`` and its drawing's points (independent of the URDF).  A
    planar rig is compared in its plane (the URDF draws its links in layers along z).
    """
    drawing = rig.drawing
    points = {b.name: b.points for b in drawing.bodies}
    pins = _pins(robot)
    for body, local in points.items():  # every joint point: both ends of the cut joints too
        assert {(body, p) for p in local} <= set(pins), body
    data = rig.at(psi, speed)
    actuated = set(robot.actuated_joint_names)
    assert actuated <= set(names)
    dim = drawing.dimension
    worst = 0.0
    for k in range(len(psi)):
        robot.update_cfg({n: float(v) for n, v in zip(names, positions[k]) if n in actuated})
        for (link, point), local in pins.items():
            t = robot.get_transform(link, root)
            got = t[:3, :3] @ local + t[:3, 3]
            if link == root:
                core = np.asarray(drawing.frame[point], dtype=float)
            else:
                core = data.bodies.world(link, points[link][point])[k]
            worst = max(worst, float(np.abs(got[:dim] - core[:dim]).max()))
    return worst


# ----------------------------------------------------------------------------- in process


@pytest.mark.parametrize('name', SCENES)
def test_published_joints_drive_the_urdf_to_the_core_points(name):
    sc = scene_mod.load(name)
    model = description.twin_for(sc)
    rig = model.rig
    rng = np.random.default_rng(11)
    psi = np.sort(rng.uniform(0.0, 2.0 * math.pi, 60))
    speed = rng.uniform(-8.0, 8.0, psi.size)          # follow mode: a speed per sample
    s = model.evaluate(psi, speed)
    ref = twin.model_for(sc).evaluate(psi, speed)
    tree = urdf.tree_model(sc)
    # the layout: the scene's joints in the rig's order, then the URDF-only ones
    assert model.twin_joint_names == ref.joint_names
    assert model.joint_names[:len(ref.joint_names)] == ref.joint_names
    assert set(model.joint_names) == set(ref.joint_names) | set(tree.names)
    assert s.joint_names == model.joint_names
    assert model.joint_names[model.crank_index] == model.crank_joint
    assert not np.any(np.signbit(s.joint_position) & (s.joint_position == 0.0))
    # the wrench and the efforts are the twin's, the URDF-only joints carry none
    assert_allclose(s.force_N, ref.force_N, rtol=0, atol=0)
    for j, n in enumerate(model.joint_names):
        if n in ref.joint_names:
            assert np.array_equal(s.joint_effort[:, j], ref.joint_effort[:, ref.joint_names
                                                                         .index(n)])
        else:
            assert not np.any(s.joint_effort[:, j])
    # every URDF joint: the URDF's value, velocities scaled with each sample's speed
    for j, spec in enumerate(tree.joints):
        col = model.joint_names.index(spec.name)
        if spec.joint_type != 'prismatic':
            assert np.all(s.joint_position[:, col] > -math.pi)
            assert np.all(s.joint_position[:, col] <= math.pi)
        for k in (0, psi.size // 2):
            single = model.evaluate(psi[k:k + 1], speed[k])
            assert_allclose(single.joint_position[0, col], s.joint_position[k, col],
                            rtol=0, atol=1e-12)
            assert_allclose(single.joint_velocity[0, col], s.joint_velocity[k, col],
                            rtol=1e-12, atol=1e-12)
    # a cut joint keeps the rig's value, wrapped when it is an angle
    for n, joint_type in tree.cuts:
        if n not in ref.joint_names:
            continue
        got = s.joint_position[:, model.joint_names.index(n)]
        want = ref.joint_position[:, ref.joint_names.index(n)]
        diff = got - want if joint_type == 'prismatic' else urdf.wrap_angle(got - want)
        assert_allclose(diff, 0.0, atol=1e-12)
    root = urdf.DEFAULT_FRAME_ID
    worst = _worst_point_error(_robot(urdf.urdf_xml(sc)), root, rig, psi, speed,
                               model.joint_names, s.joint_position)
    print(f'{name}: worst joint-point mismatch {worst:.2e} m over {psi.size} angles')
    assert worst < POINT_TOL_M


@pytest.mark.parametrize('name', ['rggr', 'spatial_two_loop'])
def test_spatial_velocities_are_the_rates_of_the_joint_angles(name):
    sc = scene_mod.load(name)
    model = description.twin_for(sc)
    psi = np.linspace(0.05, 6.2, 40)
    speed = 3.5
    s = model.evaluate(psi, speed)
    h = 1e-6
    plus = model.evaluate(psi + h, speed).joint_position
    minus = model.evaluate(psi - h, speed).joint_position
    rate = urdf.wrap_angle(plus - minus) / (2.0 * h) * speed
    scale = np.abs(s.joint_velocity).max()
    assert_allclose(s.joint_velocity, rate, rtol=0, atol=1e-6 * scale)
    # the published positions are the URDF's at the rig's own evaluation (scene speed)
    rig = rig_for(sc)
    names, positions, _ = urdf.rig_joint_positions(sc, rig.at(psi))
    for k, joint in enumerate(names):
        if joint in model.joint_names:
            got = s.joint_position[:, model.joint_names.index(joint)]
            assert_allclose(urdf.wrap_angle(got - positions[:, k]), 0.0, atol=1e-12)


def test_a_balanced_design_shares_the_layout():
    sc = scene_mod.load('hoeken')
    model = description.twin_for(sc)
    design = redistribution.optimize(sc, weights=(0.5, 0.5)).balanced_scene
    balanced = model.with_design(design)
    assert isinstance(balanced, description.UrdfTwin) and balanced.layout is model.layout
    psi = np.linspace(0.0, 6.0, 7)
    assert np.array_equal(balanced.evaluate(psi, 1.0).joint_position,
                          model.evaluate(psi, 1.0).joint_position)
    assert description.urdf_twin(balanced) is balanced


def test_cell_bench_is_a_section_and_reads_process_cpu():
    from mech_balance.bench import cell, core
    assert 'mech_balance.bench.cell:bench_section' in core.SECTIONS
    total = sum(x * x for x in range(200_000))   # some CPU time of this process
    assert total > 0
    # /proc/<pid>/stat between two readings of the kernel's own account of this process:
    # both count clock ticks of the same counters, so the read is bracketed (to one tick of
    # rounding), whatever the machine's load (no time threshold)
    before = os.times()
    got = cell.process_cpu_s(os.getpid())
    after = os.times()
    tick = 1.0 / os.sysconf('SC_CLK_TCK')
    assert before.user + before.system - tick <= got <= after.user + after.system + tick
    assert got > 0.0


# ----------------------------------------------------------------------------- node


class LateListener:
    """A robot_description subscriber made after the node published (transient local)."""

    def __init__(self, probe):
        self.texts = []
        qos = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                         reliability=ReliabilityPolicy.RELIABLE)
        self.sub = probe.node.create_subscription(
            String, f'{probe.ns}/{description.ROBOT_DESCRIPTION}',
            lambda msg: self.texts.append(msg.data), qos)

    def wait(self, probe, count=1, what='the URDF on robot_description'):
        probe.spin_until(lambda: len(self.texts) >= count, what=what)
        return self.texts[-1]


def _turn(probe, rig_process):
    """Return the published joints over more than a crank turn: names, psi, positions."""
    probe.collect(TURN_SAMPLES)
    assert rig_process.alive()
    joints = sorted(probe.joints, key=lambda j: j[0])
    names = joints[0][1]
    assert all(j[1] == names for j in joints)
    psi = np.array([j[2][0] for j in joints])
    gaps = np.diff(np.sort(np.mod(psi, 2.0 * math.pi)))
    wrap_gap = 2.0 * math.pi - np.mod(psi, 2.0 * math.pi).max() + \
        np.mod(psi, 2.0 * math.pi).min()
    assert max(gaps.max(), wrap_gap) < MAX_GAP_RAD, 'the samples must cover a full turn'
    return names, psi, np.array([j[2] for j in joints])


def _fk_over_a_turn(probe, rig_process, sc, text, frame_id):
    names, psi, positions = _turn(probe, rig_process)
    worst = _worst_point_error(_robot(text), frame_id, rig_for(sc), psi, CRANK_SPEED, names,
                               positions)
    print(f'{sc.name}: node joint_states x node URDF, worst joint-point mismatch '
          f'{worst:.2e} m over {psi.size} samples')
    assert worst < POINT_TOL_M


def test_node_urdf_late_joiner_and_forward_kinematics_hoeken(context):
    ns = f'/t{DOMAIN_ID}_describe_hoeken'
    rig = RigProcess(ns, '-p', 'scene:=hoeken', '-p', f'crank_speed:={CRANK_SPEED}',
                     '-p', 'publish_rate:=100.0')
    probe = Probe(context, ns)
    sc = scene_mod.load('hoeken')
    topic = f'{ns}/{description.ROBOT_DESCRIPTION}'
    try:
        probe.wait_for_rig(rig)
        probe.collect(5)           # publishing: the URDF went out before the first sample
        late = LateListener(probe)
        text = late.wait(probe)
        assert text == urdf.urdf_xml(sc, frame_id='rig_frame')
        _fk_over_a_turn(probe, rig, sc, text, 'rig_frame')

        # a new root link name, then a new design: republished, still latched
        assert probe.set_params(frame_id='cell_frame')[0].successful
        text = late.wait(probe, 2, 'the URDF with the new frame_id')
        assert '<link name="cell_frame"' in text and 'rig_frame' not in text
        answer = probe.call(probe.balance)
        assert answer.success, answer.message
        text = late.wait(probe, 3, 'the URDF of the balanced design')
        design = redistribution.optimize(sc, weights=(0.5, 0.5)).balanced_scene
        robot = _robot(text)
        for link in design.links:
            assert_allclose(robot.link_map[link.name].inertial.mass, link.mass_kg, rtol=1e-9)
        assert robot.link_map['crank'].inertial.mass != sc.link('crank').mass_kg
        second = LateListener(probe)   # a late joiner gets the latest URDF only
        assert second.wait(probe) == text and len(second.texts) == 1
        _fk_over_a_turn(probe, rig, design, text, 'cell_frame')

        # publish_robot_description false: no publisher; true again: latched again
        assert probe.set_params(publish_robot_description=False)[0].successful
        probe.spin_until(lambda: probe.node.count_publishers(topic) == 0,
                         DISCOVERY_TIMEOUT_S, 'robot_description to be unpublished')
        assert probe.set_params(publish_robot_description=True)[0].successful
        third = LateListener(probe)
        assert third.wait(probe) == text
        assert rig.alive()
    finally:
        probe.destroy()
        log = rig.stop()
    assert f'publishing {topic} (std_msgs/msg/String, transient local)' in log


def test_node_urdf_late_joiner_and_forward_kinematics_rggr(context):
    ns = f'/t{DOMAIN_ID}_describe_rggr'
    rig = RigProcess(ns, '-p', 'scene:=rggr', '-p', f'crank_speed:={CRANK_SPEED}',
                     '-p', 'publish_rate:=100.0')
    probe = Probe(context, ns)
    sc = scene_mod.load('rggr')
    try:
        probe.wait_for_rig(rig)
        probe.collect(5)
        text = LateListener(probe).wait(probe)
        assert text == urdf.urdf_xml(sc, frame_id='rig_frame')
        _fk_over_a_turn(probe, rig, sc, text, 'rig_frame')
    finally:
        probe.destroy()
        rig.stop()
