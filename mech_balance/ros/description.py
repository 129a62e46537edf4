"""
What the rig node tells robot_state_publisher: the URDF joints on ``joint_states`` and the URDF.

The published joints and their values: `docs/rviz_launch.md` (*joint_states drives the
URDF*, *robot_description*).
"""

from dataclasses import replace
import threading

from mech_balance.ros import streaming, urdf
import numpy as np
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

ROBOT_DESCRIPTION = 'robot_description'
"""Topic of the URDF (relative: in the node's namespace, as robot_state_publisher's)."""
ANGULAR = ('revolute', 'continuous', 'spherical')
"""Joint types whose published position is an angle (wrapped)."""


class JointLayout:
    """The published joints of a rig (``names``; ``twin_names`` the rig's), once per geometry."""

    def __init__(self, rig):
        tree = urdf.tree_model(rig.scene)
        self.tree = tree
        self.twin_names = tuple(rig.joint_names)
        extra = tuple(n for n in tree.names if n not in self.twin_names)
        self.names = self.twin_names + extra
        n_tree, n_twin = len(tree.names), len(self.twin_names)
        cut_types = dict(tree.cuts)
        # columns of [URDF values | rig values] (positions, velocities) and of
        # [rig efforts | 0] for each published joint
        self._value_index = np.array([tree.names.index(n) if n in tree.names
                                      else n_tree + self.twin_names.index(n)
                                      for n in self.names], dtype=int)
        self._effort_index = np.array([self.twin_names.index(n) if n in self.twin_names
                                       else n_twin for n in self.names], dtype=int)
        self._wrap_twin = np.array([cut_types.get(n, 'revolute') in ANGULAR and
                                    n not in tree.names for n in self.twin_names], dtype=bool)

    def angular(self, samples, twin_angular):
        """Return which published positions are angles, from a RigData and the rig's own."""
        tree = self.tree
        _, _, tree_angular = tree.coordinates(tree, tree.state_of(samples))
        both = np.concatenate([np.asarray(tree_angular, dtype=bool),
                               np.asarray(twin_angular, dtype=bool)])
        return both[self._value_index]

    def apply(self, samples):
        """Return ``samples`` (RigData of the rig) with the published joints' values."""
        _, position, velocity = urdf.rig_joint_positions(self.tree, samples)
        twin_position = np.where(self._wrap_twin, urdf.wrap_angle(samples.joint_position),
                                 samples.joint_position)
        position = np.hstack([position, twin_position])[:, self._value_index] + 0.0
        velocity = np.hstack([velocity, samples.joint_velocity])[:, self._value_index] + 0.0
        effort = samples.joint_effort
        if effort is not None:
            zero = np.zeros((effort.shape[0], 1))
            effort = np.hstack([effort, zero])[:, self._effort_index] + 0.0
        return replace(samples, joint_position=position, joint_velocity=velocity,
                       joint_effort=effort, joint_names=self.names)


class UrdfTwin(streaming.TwinModel):
    """A :class:`~mech_balance.ros.streaming.TwinModel` whose samples carry the URDF joints."""

    def __init__(self, rig, layout=None):
        super().__init__(rig)
        self.layout = JointLayout(rig) if layout is None else layout
        self.twin_joint_names = self.joint_names
        self.joint_names = self.layout.names

    def with_design(self, scene):
        """Return the twin of another design (inertia) of the same geometry."""
        return UrdfTwin(self.rig.with_scene(scene), self.layout)

    def evaluate(self, psi, speed, accel=0.0):
        """Return the published RigData at crank angles ``psi`` ``(n,)``."""
        return self.layout.apply(super().evaluate(psi, speed, accel))

    def published_angular(self):
        """Return which published joint positions are angles (wrapped to (-pi, pi])."""
        sample = self.rig.at(np.zeros(1), 1.0, 0.0, outputs=self.outputs)
        return self.layout.angular(sample, self.angular)


def twin_for(scene):
    """Return the :class:`UrdfTwin` of a scene of any kind."""
    return UrdfTwin(streaming.model_for(scene).rig)


def urdf_twin(model):
    """Return ``model`` (a TwinModel) as a :class:`UrdfTwin` (itself if it is one)."""
    return model if isinstance(model, UrdfTwin) else UrdfTwin(model.rig)


class DescriptionPublisher:
    """
    The node's ``robot_description`` publisher: the URDF of the published design, latched.

    :meth:`show` (any thread) publishes when the scene object or ``frame_id`` changed; a scene
    the URDF cannot describe is logged, never raised.
    """

    def __init__(self, node):
        self._node = node
        self._lock = threading.Lock()
        self._pub = None
        self._shown = None      # (scene, frame_id) last published

    def show(self, enabled, model, frame_id):
        """Publish the URDF of ``model``'s scene with root ``frame_id`` (if enabled, new)."""
        with self._lock:
            if not enabled:
                if self._pub is not None:
                    self._node.destroy_publisher(self._pub)
                    self._pub, self._shown = None, None
                return
            if self._pub is None:
                qos = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                                 reliability=ReliabilityPolicy.RELIABLE)
                # no QoS event handlers: they would be waitables of the (multi-threaded)
                # executor, and destroying the publisher from a parameter callback while
                # another executor thread waits on them raises InvalidHandle there
                self._pub = self._node.create_publisher(
                    String, ROBOT_DESCRIPTION, qos,
                    event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))
            shown = self._shown
            if shown is not None and shown[0] is model.scene and shown[1] == frame_id:
                return
            try:
                text = urdf.urdf_xml(model.scene, frame_id=frame_id,
                                     linkage=model.layout.tree.linkage)
            except ValueError as exc:
                self._node.get_logger().warning(f'{ROBOT_DESCRIPTION}: not published: {exc}')
                return
            self._pub.publish(String(data=text))
            self._shown = (model.scene, frame_id)
            topic = self._pub.topic_name
        self._node.get_logger().info(
            f'publishing {topic} (std_msgs/msg/String, transient local): the URDF of '
            f'{model.scene.name!r} ({len(text)} characters), root link {frame_id!r}')
