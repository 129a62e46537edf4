"""The one home of rotations and angle wrapping against scipy's Rotation and by invariants."""

import math

from mech_balance import rotations
import numpy as np
from numpy.testing import assert_allclose
import pytest
from scipy.spatial.transform import Rotation

RNG_SEED = 7


def _random_rpy(n):
    rng = np.random.default_rng(RNG_SEED)
    return rng.uniform([-math.pi, -0.5 * math.pi, -math.pi], [math.pi, 0.5 * math.pi, math.pi],
                       (n, 3))


def test_rpy_matrix_is_scipys_extrinsic_xyz():
    for rpy in _random_rpy(50):
        assert_allclose(rotations.rpy_matrix(rpy),
                        Rotation.from_euler('xyz', rpy).as_matrix(), atol=1e-15)
    deg = np.degrees(_random_rpy(1)[0])
    assert_allclose(rotations.rpy_matrix(deg, degrees=True),
                    Rotation.from_euler('xyz', deg, degrees=True).as_matrix(), atol=1e-15)


def test_matrix_rpy_inverts_rpy_matrix_over_a_stack():
    rpy = _random_rpy(200)
    mats = Rotation.from_euler('xyz', rpy).as_matrix()
    roll, pitch, yaw = rotations.matrix_rpy(mats)
    assert_allclose(np.stack([roll, pitch, yaw], axis=1), rpy, atol=1e-12)
    assert_allclose(np.stack(rotations.matrix_rpy(mats, degrees=True), axis=1),
                    np.degrees(rpy), atol=1e-10)


@pytest.mark.parametrize('pitch', [0.5 * math.pi, -0.5 * math.pi])
def test_matrix_rpy_at_gimbal_lock_puts_the_turn_into_roll(pitch):
    mat = Rotation.from_euler('xyz', [0.3, pitch, 0.4]).as_matrix()
    roll, got_pitch, yaw = (float(v) for v in rotations.matrix_rpy(mat))
    assert yaw == 0.0
    assert_allclose(Rotation.from_euler('xyz', [roll, got_pitch, yaw]).as_matrix(), mat,
                    atol=1e-12)


def test_axis_angle_forms_agree_with_the_rotation_vector():
    rng = np.random.default_rng(RNG_SEED)
    for axis, angle in zip(rng.normal(size=(20, 3)), rng.uniform(-4.0, 4.0, 20)):
        axis /= np.linalg.norm(axis)
        want = Rotation.from_rotvec(axis * angle).as_matrix()
        assert_allclose(rotations.axis_angle_matrix(axis, angle), want, atol=1e-14)
        assert_allclose(rotations.rot_axis(axis, np.array([angle]))[0], want, atol=1e-14)
        assert_allclose(rotations.expmap((axis * angle)[None])[0], want, atol=1e-14)
        assert_allclose(rotations.angle_about(axis, want[None])[0],
                        math.remainder(angle, 2.0 * math.pi), atol=1e-12)
    assert_allclose(rotations.expmap(np.array([[1e-10, 0.0, 0.0]]))[0],
                    Rotation.from_rotvec([1e-10, 0.0, 0.0]).as_matrix(), atol=1e-18)


@pytest.mark.parametrize('frm,to', [([1, 0, 0], [0, 1, 0]), ([0, 0, 1], [0, 0, 1]),
                                    ([0, 0, 1], [0, 0, -1]), ([0.6, 0.8, 0.0], [0, 0.6, 0.8])])
def test_min_rotation_takes_frm_onto_to_by_the_smallest_angle(frm, to):
    frm, to = np.array(frm, dtype=float), np.array(to, dtype=float)
    rot = rotations.min_rotation(frm, to)
    assert_allclose(rot @ frm, to, atol=1e-14)
    assert_allclose(rot @ rot.T, np.eye(3), atol=1e-14)
    angle = Rotation.from_matrix(rot).magnitude()
    assert angle == pytest.approx(math.acos(np.clip(frm @ to, -1.0, 1.0)), abs=1e-7)


def test_wrap_angle_range_no_negative_zero_and_the_scalar_path():
    x = np.array([-3.0 * math.pi, -math.pi, -0.0, 0.0, math.pi, 3.0 * math.pi, 7.0, -7.0])
    w = rotations.wrap_angle(x)
    assert np.all(w > -math.pi) and np.all(w <= math.pi)
    assert not np.any(np.signbit(w[w == 0.0]))
    assert_allclose(np.cos(w), np.cos(x), atol=1e-12)
    for v in x:
        s = rotations.wrap_angle(float(v))
        assert type(s) is float
        assert s == float(rotations.wrap_angle(np.array(v)))


def test_quaternion_matrix_is_scipys_and_normalizes():
    rng = np.random.default_rng(RNG_SEED)
    for q in rng.normal(size=(20, 4)):
        want = Rotation.from_quat(q / np.linalg.norm(q)).as_matrix()
        assert_allclose(rotations.quaternion_matrix(3.0 * q), want, atol=1e-14)
