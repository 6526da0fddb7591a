"""NumPy rotation helpers: roll-pitch-yaw, quaternions, slerp, look-at frames."""
import numpy as np
import pytest

from dcslam.geometry.rotations import (look_rotation, nearest_rotation, quaternion_to_rotation, rotation_from_rpy,
                                       rotation_to_quaternion, rpy_from_rotation, slerp)


class TestRollPitchYaw:
    def test_rotation_order_is_z_y_x(self):
        R = rotation_from_rpy([0.3], [0.2], [0.1])[0]
        def rot(axis, a):
            c, s = np.cos(a), np.sin(a)
            i, j = [k for k in range(3) if k != axis]
            m = np.eye(3)
            m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
            return m if axis != 1 else m.T
        assert R == pytest.approx(rot(2, 0.1) @ rot(1, 0.2) @ rot(0, 0.3))
        assert rotation_from_rpy([0.0], [0.0], [np.pi / 2])[0] @ [1, 0, 0] == pytest.approx([0, 1, 0])

    def test_round_trip(self):
        rng = np.random.default_rng(0)
        roll, pitch, yaw = rng.uniform(-0.3, 0.3, 10), rng.uniform(-0.3, 0.3, 10), rng.uniform(-3, 3, 10)
        back = rpy_from_rotation(rotation_from_rpy(roll, pitch, yaw))
        np.testing.assert_allclose(np.stack(back), np.stack([roll, pitch, yaw]), atol=1e-12)


class TestQuaternions:
    def test_known_answers(self):
        Rz90 = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
        assert rotation_to_quaternion(Rz90) == pytest.approx([0, 0, np.sqrt(0.5), np.sqrt(0.5)])
        assert rotation_to_quaternion(np.eye(3)) == pytest.approx([0, 0, 0, 1])
        assert quaternion_to_rotation([0, 0, 1, 1]) == pytest.approx(Rz90)  # normalised on the way

    @pytest.mark.parametrize("axis", range(3))
    def test_half_turns(self, axis):
        q = np.zeros(4)
        q[axis] = 1.0
        R = quaternion_to_rotation(q)
        assert np.allclose(np.diag(R), [1 if i == axis else -1 for i in range(3)])
        back = rotation_to_quaternion(R)
        assert abs(back[axis]) == pytest.approx(1.0) and quaternion_to_rotation(back) == pytest.approx(R)

    def test_batch_shapes_and_round_trip(self):
        q = np.random.default_rng(3).normal(size=(2, 5, 4))
        R = quaternion_to_rotation(q)
        assert R.shape == (2, 5, 3, 3)
        assert np.abs(R @ np.swapaxes(R, -1, -2) - np.eye(3)).max() < 1e-12
        assert np.allclose(np.linalg.det(R), 1.0)
        back = rotation_to_quaternion(R)
        assert back.shape == (2, 5, 4) and np.all(back[..., 3] >= 0)
        expect = q / np.linalg.norm(q, axis=-1, keepdims=True) * np.sign(q[..., 3:])
        assert back == pytest.approx(expect, abs=1e-12)


class TestSlerp:
    def test_end_points_middle_and_shorter_arc(self):
        q0 = np.array([0.0, 0.0, 0.0, 1.0])
        q1 = rotation_to_quaternion(rotation_from_rpy([0.0], [0.0], [1.0]))[0]
        assert slerp(q0, q1, 0.0) == pytest.approx(q0) and slerp(q0, q1, 1.0) == pytest.approx(q1)
        half = quaternion_to_rotation(slerp(q0, q1, 0.5))
        assert rpy_from_rotation(half[None])[2][0] == pytest.approx(0.5)
        assert quaternion_to_rotation(slerp(q0, -q1, 0.5)) == pytest.approx(half)  # -q1 is the same rotation
        assert slerp(q0, q0, 0.3) is q0


class TestLookRotation:
    def test_looks_along_forward_with_y_up_and_is_proper(self):
        forward = np.array([[1.0, 0.0, 0.0], [0.3, -0.5, -0.2]])
        R = look_rotation(forward, np.zeros(2))
        assert np.allclose(np.linalg.det(R), 1.0) and np.allclose(R @ np.swapaxes(R, 1, 2), np.eye(3))
        assert np.allclose(R[:, :, 2], forward / np.linalg.norm(forward, axis=1, keepdims=True))
        assert R[0, :, 1] == pytest.approx([0, 0, 1])  # level camera: image y is the world's up
        rolled = look_rotation(forward[:1], np.array([np.pi / 2]))
        assert rolled[0, :, 2] == pytest.approx(R[0, :, 2]) and abs(rolled[0, 2, 1]) < 1e-12


def test_nearest_rotation_projects_drifted_matrices_back_onto_so3():
    rng = np.random.default_rng(3)
    R = rotation_from_rpy(rng.uniform(-3, 3, 5), rng.uniform(-1.5, 1.5, 5), rng.uniform(-3, 3, 5))
    drifted = R + 1e-4 * rng.standard_normal(R.shape)
    fixed = nearest_rotation(drifted)
    assert np.allclose(fixed @ np.swapaxes(fixed, -1, -2), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(fixed), 1.0, atol=1e-12)
    assert np.abs(fixed - R).max() < 5e-4                      # a small correction, not another rotation
    assert np.allclose(nearest_rotation(R), R, atol=1e-12)     # rotations stay as they are
    with pytest.raises(ValueError, match="expected"):
        nearest_rotation(np.eye(4))
