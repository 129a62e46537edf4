"""
Follow a crank encoder with the rig node: encoder in, joint states and shaking wrench out.

::

    ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST python examples/follow_encoder.py

Starts the rig node in follow mode (on a Jazzy install: ``ros2 run mech_balance rig_node
--ros-args -p mode:=follow``), publishes a crank encoder (``sensor_msgs/msg/JointState`` on
``crank_joint_state``, the crank turning at the scene's speed) and receives what the node
publishes for every encoder message, stamped as it: ``joint_states`` (every joint) and
``shaking_wrench`` (``geometry_msgs/msg/WrenchStamped``).  ``follow.exact`` evaluates the
core at every sample (docs/node.md, "Follow mode").
"""

import signal
import subprocess
import sys
import time

from geometry_msgs.msg import WrenchStamped
import mech_balance as mb
import rclpy
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState

SCENE = 'hoeken'
SAMPLES = 40
PERIOD_NS = 10_000_000          # a 100 Hz encoder
TIMEOUT_S = 60.0

speed = mb.load_scene(SCENE).crank_speed_rad_s
node = subprocess.Popen([sys.executable, '-m', 'mech_balance.ros.node', '--ros-args',
                         '-p', f'scene:={SCENE}', '-p', 'mode:=follow',
                         '-p', 'follow.exact:=true'])
rclpy.init()
me = rclpy.create_node('encoder')
joints, wrenches = {}, {}


def stamp_ns(msg):
    """Return a message's header stamp in nanoseconds."""
    return msg.header.stamp.sec * 10 ** 9 + msg.header.stamp.nanosec


me.create_subscription(JointState, 'joint_states',
                       lambda m: joints.setdefault(stamp_ns(m), m), QoSProfile(depth=100))
me.create_subscription(WrenchStamped, 'shaking_wrench',
                       lambda m: wrenches.setdefault(stamp_ns(m), m), QoSProfile(depth=100))
encoder = me.create_publisher(JointState, 'crank_joint_state', QoSProfile(depth=100))


def spin_until(done, what):
    """Spin until ``done()``; give up after TIMEOUT_S naming ``what``."""
    deadline = time.monotonic() + TIMEOUT_S
    while not done():
        if time.monotonic() > deadline or node.poll() is not None:
            raise SystemExit(f'gave up waiting for {what}')
        rclpy.spin_once(me, timeout_sec=0.05)


try:
    # the node is up when it subscribes to the encoder and publishes both topics to us
    spin_until(lambda: encoder.get_subscription_count() >= 1 and
               me.count_publishers('/joint_states') >= 1 and
               me.count_publishers('/shaking_wrench') >= 1, 'the rig node')
    t0 = me.get_clock().now().nanoseconds
    stamps = [t0 + k * PERIOD_NS for k in range(SAMPLES)]
    for k, t in enumerate(stamps):
        msg = JointState(name=['O1'], position=[0.3 + speed * k * PERIOD_NS * 1e-9],
                         velocity=[speed])
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t, 10 ** 9)
        encoder.publish(msg)
    spin_until(lambda: stamps[-1] in joints and stamps[-1] in wrenches,
               'the answer to the last encoder message')
finally:
    node.send_signal(signal.SIGINT)
    node.wait(timeout=30)
    me.destroy_node()
    rclpy.shutdown()

answered = [t for t in stamps if t in joints and t in wrenches]
print(f'{SCENE}: {len(answered)} of {SAMPLES} encoder messages answered')
for t in answered[-1::-10][::-1]:
    js, ws = joints[t], wrenches[t].wrench
    crank = js.name.index('O1')
    print(f'stamp {t - t0} ns: crank {js.position[crank]:.9g} rad at '
          f'{js.velocity[crank]:.9g} rad/s, joints',
          ' '.join(f'{q:.6g}' for q in js.position))
    print(f'  shaking force N: {ws.force.x:.9g} {ws.force.y:.9g} {ws.force.z:.9g}; '
          f'moment N m: {ws.torque.x:.9g} {ws.torque.y:.9g} {ws.torque.z:.9g}')
