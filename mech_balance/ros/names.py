"""The ROS names of the rig: topics, frames and defaults, spelled once (docs/node.md)."""

ENCODER_TOPIC = '/crank_joint_state'
"""Default encoder topic of a recording (the node subscribes ``crank_joint_state``)."""
WRENCH_TOPIC = '/measured_wrench'
"""Default force-sensor topic of a recording (the node subscribes ``measured_wrench``)."""
DEFAULT_FRAME_ID = 'rig_frame'
"""The rig frame: the node's ``frame_id`` default and the URDF's root link when none is given."""
NODE_NAME = 'rig'
"""The rig node's name, as ROS params files address it (``/**``, ``rig``, ``/cell/rig``)."""
