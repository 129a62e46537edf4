"""Message conversion for the rig node: pure functions, no node is ever created here."""

from array import array
import math
import struct

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import WrenchStamped
from mech_balance.ros import params
import numpy as np
from rcl_interfaces.msg import ParameterDescriptor
from rcl_interfaces.msg import ParameterType
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState

NS_PER_S = 1_000_000_000

_ROS_TYPES = {params.STRING: ParameterType.PARAMETER_STRING,
              params.DOUBLE: ParameterType.PARAMETER_DOUBLE,
              params.INTEGER: ParameterType.PARAMETER_INTEGER,
              params.BOOL: ParameterType.PARAMETER_BOOL,
              params.DOUBLE_ARRAY: ParameterType.PARAMETER_DOUBLE_ARRAY}


def stamp_from_ns(stamp_ns):
    """Return the ``builtin_interfaces/Time`` of an int time in ns (>= 0)."""
    sec, nanosec = divmod(int(stamp_ns), NS_PER_S)
    return Time(sec=sec, nanosec=nanosec)


def ns_from_stamp(stamp):
    """Return a ``builtin_interfaces/Time`` as int ns."""
    return stamp.sec * NS_PER_S + stamp.nanosec


def _doubles(row):
    out = array('d')
    out.frombytes(row.tobytes())
    return out


def joint_state_template(msg, joint_names):
    """Set the joint names of a reusable ``JointState`` (they never change for a scene)."""
    msg.name = list(joint_names)
    return msg


def fill_joint_state(msg, samples, i, stamp):
    """Fill ``msg`` (a JointState, names set) with sample ``i`` (effort empty if none)."""
    msg.header.stamp = stamp
    msg.position = _doubles(samples.joint_position[i])
    msg.velocity = _doubles(samples.joint_velocity[i])
    msg.effort = _doubles(samples.joint_effort[i]) if samples.joint_effort is not None \
        else array('d')
    return msg


def fill_wrench(msg, samples, i, stamp, frame_id):
    """Fill ``msg`` (``geometry_msgs/WrenchStamped``) with the shaking wrench of sample ``i``."""
    return _fill_wrench(msg, stamp, frame_id, (*samples.force_N[i], *samples.moment_Nm[i]))


def _fill_wrench(msg, stamp, frame_id, wrench):
    msg.header.stamp, msg.header.frame_id = stamp, frame_id
    f, m = msg.wrench.force, msg.wrench.torque
    f.x, f.y, f.z, m.x, m.y, m.z = (float(v) for v in wrench)
    return msg


def serialized_samples(samples, stamps_ns, frame_id):
    """Return ``[(joint_state_bytes, wrench_bytes)]`` per sample, by rclpy's serializer."""
    joints = joint_state_template(JointState(), samples.joint_names)
    wrench = WrenchStamped()
    out = []
    for i, stamp_ns in enumerate(stamps_ns):
        stamp = stamp_from_ns(stamp_ns)
        out.append((serialize_message(fill_joint_state(joints, samples, i, stamp)),
                    serialize_message(fill_wrench(wrench, samples, i, stamp, frame_id))))
    return out


VERIFIED_BATCHES = 4
"""Batches of a :class:`SampleSerializer` read back with rclpy before it is trusted."""
SMALL_BATCH = 32
"""Batches of at most this many samples are packed with ``struct``, larger ones with numpy."""
_INT, _UINT = struct.Struct('<i'), struct.Struct('<I')
_PROBE_SEC, _PROBE_NANOSEC = 0x1A2B3C4D, 0x05060708
"""Distinctive stamp of the probe messages (found by value in their bytes)."""


class SampleSerializer:
    """
    Serialize batches of samples to JointState and WrenchStamped bytes, vectorized.

    The layout is fixed by the names, frame and lengths: a probe message serialized by rclpy
    is the template, its values found by their bytes.  The first sample of each of the first
    :data:`VERIFIED_BATCHES` batches is read back with rclpy; on a difference it falls back
    to :func:`serialized_samples` for good (``fast`` False).
    """

    def __init__(self, joint_names, has_effort, frame_id):
        self.joint_names, self.has_effort = tuple(joint_names), bool(has_effort)
        self.frame_id = frame_id
        n = len(self.joint_names)
        count = 3 if self.has_effort else 2
        probe = _probe_values(count * n + 6)
        js = joint_state_template(JointState(), self.joint_names)
        js.header.stamp = Time(sec=_PROBE_SEC, nanosec=_PROBE_NANOSEC)
        js.position, js.velocity = probe[:n].tolist(), probe[n:2 * n].tolist()
        js.effort = probe[2 * n:3 * n].tolist() if self.has_effort else []
        w = probe[count * n:]
        ws = _fill_wrench(WrenchStamped(), js.header.stamp, frame_id, w)
        self._joint = _Template(serialize_message(js), probe[:count * n])
        self._wrench = _Template(serialize_message(ws), w)
        self.fast = self._joint.ok and self._wrench.ok
        self.verified = 0           # batches read back and found equal

    def serialize(self, samples, stamps_ns):
        """Return ``[(joint_state_bytes, wrench_bytes)]`` of a batch (its ``stamps_ns``)."""
        if not self.fast:
            return serialized_samples(samples, stamps_ns, self.frame_id)
        stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
        sec, nanosec = np.divmod(stamps_ns, NS_PER_S)
        parts = [samples.joint_position, samples.joint_velocity]
        if self.has_effort:
            parts.append(samples.joint_effort)
        if stamps_ns.size <= SMALL_BATCH:  # sample by sample: no numpy call overhead
            joints = np.concatenate(parts, axis=1).tolist()
            wrench = np.concatenate([samples.force_N, samples.moment_Nm], axis=1).tolist()
            sec, nanosec = sec.tolist(), nanosec.tolist()
            out = [(self._joint.pack(sec[i], nanosec[i], joints[i]),
                    self._wrench.pack(sec[i], nanosec[i], wrench[i]))
                   for i in range(stamps_ns.size)]
        else:
            joints = self._joint.fill(sec, nanosec, np.hstack(parts))
            wrench = self._wrench.fill(sec, nanosec, np.hstack([samples.force_N,
                                                                samples.moment_Nm]))
            out = [(joints[i].tobytes(), wrench[i].tobytes()) for i in range(stamps_ns.size)]
        if out and self.verified < VERIFIED_BATCHES:
            if not self._same_as_rclpy(samples, stamps_ns[0], out[0]):
                self.fast = False
                return serialized_samples(samples, stamps_ns, self.frame_id)
            self.verified += 1
        return out

    def _same_as_rclpy(self, samples, stamp_ns, payload):
        """Return whether ``payload`` reads back as the messages of sample 0 (padding aside)."""
        stamp = stamp_from_ns(stamp_ns)
        joints = fill_joint_state(joint_state_template(JointState(), self.joint_names),
                                  samples, 0, stamp)
        wrench = fill_wrench(WrenchStamped(), samples, 0, stamp, self.frame_id)
        return (deserialize_message(payload[0], JointState) == joints and
                deserialize_message(payload[1], WrenchStamped) == wrench)


class _Template:
    """The serialized probe of one message type and where its values sit."""

    def __init__(self, data, doubles):
        self.data = np.frombuffer(data, dtype=np.uint8)
        offsets = [_find_once(data, struct.pack('<d', x)) for x in doubles]
        self.sec = _find_once(data, struct.pack('<i', _PROBE_SEC))
        self.nanosec = _find_once(data, struct.pack('<I', _PROBE_NANOSEC))
        self.ok = None not in offsets and None not in (self.sec, self.nanosec)
        if self.ok:
            self.index = (np.array(offsets)[:, None] + np.arange(8)).ravel()
            # runs of consecutive doubles: (first value, count, byte offset) for pack
            self.runs = []
            for k, at in enumerate(offsets):
                if self.runs and at == self.runs[-1][2] + 8 * self.runs[-1][1]:
                    first, count, start = self.runs[-1]
                    self.runs[-1] = (first, count + 1, start)
                else:
                    self.runs.append((k, 1, at))
            self.runs = [(first, first + count, struct.Struct(f'<{count}d'), start)
                         for first, count, start in self.runs]
            self._bytes = bytes(data)

    def pack(self, sec, nanosec, values):
        """Return the bytes of one message: the template with ``values`` (a list) written."""
        out = bytearray(self._bytes)
        _INT.pack_into(out, self.sec, sec)
        _UINT.pack_into(out, self.nanosec, nanosec)
        for first, end, packer, start in self.runs:
            packer.pack_into(out, start, *values[first:end])
        return bytes(out)

    def fill(self, sec, nanosec, values):
        """Return ``(n, size)`` bytes: the template with ``values`` ``(n, m)`` written in."""
        n = values.shape[0]
        out = np.tile(self.data, (n, 1))
        out[:, self.sec:self.sec + 4] = sec.astype('<i4').view(np.uint8).reshape(n, 4)
        out[:, self.nanosec:self.nanosec + 4] = \
            nanosec.astype('<u4').view(np.uint8).reshape(n, 4)
        out[:, self.index] = np.ascontiguousarray(values, dtype='<f8').view(np.uint8) \
            .reshape(n, -1)
        return out


def _probe_values(count):
    """Return ``count`` doubles whose 8-byte patterns are distinct and unlikely elsewhere."""
    return np.pi * 1e-100 * (1.0 + np.arange(count) / 7.0)


def _find_once(data, pattern):
    at = data.find(pattern)
    return at if at >= 0 and data.find(pattern, at + 1) < 0 else None


def wrench_values(msg):
    """Return ``(force (3,), moment (3,))`` of a ``WrenchStamped`` as tuples of floats."""
    f, m = msg.wrench.force, msg.wrench.torque
    return (f.x, f.y, f.z), (m.x, m.y, m.z)


def crank_reading(msg, joint):
    """Return ``(stamp_ns, position_rad, velocity_rad_s or None)`` of ``joint``; ValueError."""
    names = list(msg.name)
    if joint not in names:
        raise ValueError(f'name: no joint {joint!r} in {names}, expected the crank joint '
                         '(parameter crank_joint)')
    i = names.index(joint)
    if len(msg.position) != len(names):
        raise ValueError(f'position: got {len(msg.position)} values for {len(names)} '
                         'names, expected one per joint')
    position = float(msg.position[i])
    if not math.isfinite(position):
        raise ValueError(f'position of {joint!r}: got {position!r}, expected a finite angle')
    velocity = None
    if len(msg.velocity):
        if len(msg.velocity) != len(names):
            raise ValueError(f'velocity: got {len(msg.velocity)} values for {len(names)} '
                             'names, expected one per joint or none')
        velocity = float(msg.velocity[i])
        if not math.isfinite(velocity):
            raise ValueError(f'velocity of {joint!r}: got {velocity!r}, expected a finite '
                             'speed or an empty velocity array')
    return ns_from_stamp(msg.header.stamp), position, velocity


def parameter_descriptor(spec):
    """
    Return the ROS ``ParameterDescriptor`` of a :class:`mech_balance.ros.params.Spec`.

    ``dynamic_typing``, no rclpy ranges: the node checks type and range itself
    (:func:`mech_balance.ros.params.check`; `docs/node.md#parameters`, *Typing*).
    """
    constraints = f'type {spec.value_type}; {spec.constraints}' if spec.constraints else \
        f'type {spec.value_type}'
    return ParameterDescriptor(name=spec.name, type=_ROS_TYPES[spec.value_type],
                               description=spec.description,
                               additional_constraints=constraints, dynamic_typing=True)


def ros_parameter(name, value):
    """Return an ``rclpy.parameter.Parameter`` of a checked value, of its declared type."""
    spec = params.spec_for(name)
    kind = Parameter.Type(_ROS_TYPES[spec.value_type]) if spec is not None else None
    return Parameter(name, kind, value)


def parameter_value(parameter):
    """Return the plain Python value of an ``rclpy.parameter.Parameter`` (lists for arrays)."""
    value = parameter.value
    if value is not None and not isinstance(value, (str, bool, int, float)):
        value = list(value)
    return value


def wrench_reading(msg):
    """Return ``(stamp_ns, force (3,), torque (3,))`` of a ``WrenchStamped`` (ValueError: NaN)."""
    force, torque = wrench_values(msg)
    for name, values in (('force', force), ('torque', torque)):
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f'wrench.{name}: got {list(values)}, expected finite values')
    return ns_from_stamp(msg.header.stamp), force, torque


def fill_wrench_values(msg, stamp_ns, frame_id, wrench):
    """Fill a ``WrenchStamped`` with a ``(6,)`` wrench (force xyz N, torque xyz N*m)."""
    return _fill_wrench(msg, stamp_from_ns(stamp_ns), frame_id, wrench)


def diagnostic_array(statuses, stamp_ns):
    """Return the ``diagnostic_msgs/DiagnosticArray`` of :class:`diagnostics.Status` items."""
    out = DiagnosticArray()
    out.header.stamp = stamp_from_ns(stamp_ns)
    for s in statuses:
        out.status.append(DiagnosticStatus(
            level=bytes([s.level]), name=s.name, message=s.message, hardware_id=s.hardware_id,
            values=[KeyValue(key=k, value=v) for k, v in s.values]))
    return out
