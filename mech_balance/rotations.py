"""
The one home of rotations and angle wrapping (roll-pitch-yaw, axis-angle, (-pi, pi]).

Roll-pitch-yaw is the URDF's, ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (scipy's extrinsic
``'xyz'``); why numpy and not scipy: docs/core.md#rotations.
"""

import math

import numpy as np

__all__ = ['EYE3', 'GIMBAL_LOCK_COS', 'TWO_PI', 'angle_about', 'axis_angle_matrix', 'expmap',
           'matrix_rpy', 'min_rotation', 'quaternion_matrix', 'rot_axis', 'rpy_matrix', 'skew',
           'wrap_angle']

TWO_PI = 2.0 * math.pi
GIMBAL_LOCK_COS = 1e-12
"""|cos(pitch)| below which roll and yaw turn about one axis: the whole turn goes to roll."""
EXPMAP_SMALL_RAD = 1e-8
"""Rotation angles below this use the series of exp's coefficients (no 0/0)."""
PARALLEL_SIN = 1e-15
"""|frm x to| below which :func:`min_rotation` takes the two unit vectors as parallel."""
EYE3 = np.eye(3)
EYE3.flags.writeable = False


def rpy_matrix(rpy, degrees=False):
    """Return the rotation ``(3, 3)`` of one roll-pitch-yaw ``(3,)`` (rad, or deg)."""
    r, p, y = (math.radians(v) for v in rpy) if degrees else (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), \
        math.cos(y), math.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def axis_angle_matrix(axis, angle_rad):
    """Return the rotation ``(3, 3)`` by ``angle_rad`` about the unit vector ``axis``."""
    return rot_axis(np.asarray(axis, dtype=float), np.array([float(angle_rad)]))[0]


def quaternion_matrix(xyzw):
    """Return the rotation ``(3, 3)`` of a quaternion ``(x, y, z, w)`` (normalized first)."""
    from scipy.spatial.transform import Rotation
    return Rotation.from_quat(np.asarray(xyzw, dtype=float)).as_matrix()


def matrix_rpy(rot, degrees=False):
    """Return ``(roll, pitch, yaw)`` (rad) of rotations ``(..., 3, 3)`` (:func:`rpy_matrix`^-1)."""
    rot = np.asarray(rot, dtype=float)
    cos_pitch = np.hypot(rot[..., 0, 0], rot[..., 1, 0])
    pitch = np.arctan2(-rot[..., 2, 0], cos_pitch)
    roll = np.arctan2(rot[..., 2, 1], rot[..., 2, 2])
    yaw = np.arctan2(rot[..., 1, 0], rot[..., 0, 0])
    lock = cos_pitch < GIMBAL_LOCK_COS
    if np.any(lock):
        roll = np.where(lock, np.arctan2(-rot[..., 1, 2], rot[..., 1, 1]), roll)
        yaw = np.where(lock, 0.0, yaw)
    if degrees:
        return np.degrees(roll), np.degrees(pitch), np.degrees(yaw)
    return roll, pitch, yaw


def skew(v):
    """Return the cross-product matrices ``(..., 3, 3)`` of vectors ``(..., 3)``."""
    v = np.asarray(v, dtype=float)
    out = np.zeros(v.shape + (3,))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def rot_axis(axis, angle):
    """Return rotations ``(n, 3, 3)`` by ``angle`` ``(n,)`` about the unit ``axis`` (3,)."""
    k = skew(axis)
    k2 = k @ k
    s, c = np.sin(angle), np.cos(angle)
    return EYE3 + s[:, None, None] * k + (1.0 - c)[:, None, None] * k2


def expmap(v):
    """Return the rotations ``exp(v^)`` ``(n, 3, 3)`` of rotation vectors ``(n, 3)``."""
    th = np.sqrt(np.einsum('ni,ni->n', v, v))
    small = th < EXPMAP_SMALL_RAD
    safe = np.where(small, 1.0, th)
    a = np.where(small, 1.0 - th ** 2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - th ** 2 / 24.0, (1.0 - np.cos(safe)) / safe ** 2)
    k = skew(v)
    return EYE3 + a[:, None, None] * k + b[:, None, None] * (k @ k)


def wrap_angle(angle_rad):
    """Return angles wrapped to (-pi, pi], with no -0.0 (array in, array out; float in, out)."""
    if type(angle_rad) is float:
        w = math.pi - (math.pi - angle_rad) % TWO_PI
        return (w + TWO_PI if w <= -math.pi else w) + 0.0   # mod may round up to 2 pi
    w = math.pi - np.mod(math.pi - np.asarray(angle_rad, dtype=float), TWO_PI)
    return np.where(w <= -math.pi, w + TWO_PI, w) + 0.0


def min_rotation(frm, to):
    """Return the smallest rotation (3, 3) taking the unit vector ``frm`` onto ``to``."""
    frm, to = np.asarray(frm, dtype=float), np.asarray(to, dtype=float)
    c = float(frm @ to)
    axis = _cross3(frm, to)
    s = float(np.linalg.norm(axis))
    if s < PARALLEL_SIN:
        if c > 0.0:
            return np.eye(3)
        helper = np.eye(3)[int(np.argmin(np.abs(frm)))]   # a half turn about any normal
        axis = _cross3(frm, helper)
        return rot_axis(axis / np.linalg.norm(axis), np.array([math.pi]))[0]
    return rot_axis(axis / s, np.array([math.atan2(s, c)]))[0]


def angle_about(axis, rot):
    """Return the angle ``(n,)`` of rotations ``rot`` ``(n, 3, 3)`` about the unit ``axis``."""
    skw = rot - np.swapaxes(rot, -1, -2)
    vee = 0.5 * np.stack([skw[..., 2, 1], skw[..., 0, 2], skw[..., 1, 0]], -1)
    cos = 0.5 * (np.trace(rot, axis1=-2, axis2=-1) - 1.0)
    return np.arctan2(vee @ axis, cos)


def _cross3(a, b):
    """Return ``a x b`` of two 3-vectors (the arithmetic of the kinematics' cross)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])
