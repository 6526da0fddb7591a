import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dcslam.errors import DcslamError
from dcslam.eval.trajectory import (Statistics, ate_errors, kitti_drift, localisation_accuracy, localisation_errors,
                                    pair_by_timestamps, rpe_errors, score_trajectory, umeyama_alignment)
from dcslam.io.kitti_poses import read_kitti_poses
from dcslam.io.tum import read_tum

DATA = Path(__file__).parent / "data"
POSES_04 = Path(__file__).parents[1] / "data" / "kitti-sample" / "odometry" / "poses" / "04.txt"


def pose(rotvec=(0, 0, 0), t=(0, 0, 0)):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = t
    return T


def straight_line(n=5):
    return np.stack([pose(t=(0, 0, float(i))) for i in range(n)])


class TestLocalisation:
    def test_known_answer(self):
        gt = straight_line(3)
        est = gt.copy()
        est[1] = gt[1] @ pose(t=(0.3, 0.4, 0))          # 0.5 m error
        est[2] = gt[2] @ pose(rotvec=(0, 0.2, 0))        # 0.2 rad error
        np.testing.assert_allclose(localisation_errors(gt, est), [0.0, 0.5, 0.2], atol=1e-12)

    def test_thesis_clamp_defect(self):
        gt = straight_line(2)
        est = gt.copy()
        est[1] = gt[1] @ pose(rotvec=(2.5, 0, 0))        # 2.5 rad > 90°
        assert localisation_errors(gt, est)[1] == pytest.approx(2.5)
        assert localisation_errors(gt, est, thesis_clamp=True)[1] == pytest.approx(np.pi / 2)

    def test_identical_is_zero_and_order_of_frames(self):
        rng = np.random.default_rng(0)
        gt = np.stack([pose(rng.normal(size=3), rng.normal(size=3)) for _ in range(4)])
        assert np.allclose(localisation_errors(gt, gt), 0, atol=1e-6)

    def test_different_lengths_fail(self):
        with pytest.raises(DcslamError, match="different lengths"):
            localisation_errors(straight_line(3), straight_line(4))

    @pytest.mark.parametrize("angle", [0.0, 1e-8, 1e-3, np.pi / 2, np.pi - 1e-6, np.pi])
    def test_rotation_errors_near_0_and_pi(self, angle):
        """acos of the trace read 1e-8 rad as 0 and lost half its digits near pi."""
        gt = straight_line(2)
        est = gt.copy()
        est[1] = gt[1] @ pose(rotvec=(0, angle, 0))
        assert abs(localisation_errors(gt, est)[1] - angle) <= 1e-14 + 1e-12 * angle
        assert localisation_errors(gt, est, thesis_clamp=True)[1] == pytest.approx(min(angle, np.pi / 2),
                                                                                    rel=1e-12, abs=1e-14)

    def test_kitti_poses_against_themselves_score_zero(self):
        """KITTI's poses are printed to ~7 digits, so their rotations are orthonormal to ~1.5e-7 only: inverting one
        by its transpose scored sequence 04 against itself at 1.55e-4."""
        T = read_kitti_poses(POSES_04)
        R = T[:, :3, :3]
        assert np.abs(np.swapaxes(R, 1, 2) @ R - np.eye(3)).max() > 1e-8
        assert localisation_accuracy(T, T) < 1e-9
        assert localisation_accuracy(T, T, thesis_clamp=True) < 1e-9
        trans, rot = rpe_errors(T, T)
        assert trans.max() < 1e-9 and rot.max() < 1e-9
        assert kitti_drift(T, T).overall.r_rel_deg_per_100m < 1e-9


class TestUmeyama:
    def test_recovers_known_transform(self):
        rng = np.random.default_rng(1)
        x = rng.normal(size=(20, 3))
        R = Rotation.from_rotvec([0.4, -1.0, 0.3]).as_matrix()
        y = 1.7 * x @ R.T + [1, 2, 3]
        R_fit, t_fit, s_fit = umeyama_alignment(x, y, with_scale=True)
        np.testing.assert_allclose(R_fit, R, atol=1e-10)
        np.testing.assert_allclose(t_fit, [1, 2, 3], atol=1e-10)
        assert s_fit == pytest.approx(1.7)

    def test_degenerate_fails(self):
        with pytest.raises(DcslamError, match="degenerate"):
            umeyama_alignment(np.zeros((4, 3)), np.zeros((4, 3)))


class TestAteRpe:
    def test_hand_computed_offset(self):
        # estimate = ground truth shifted by (1, 2, 2): unaligned ATE 3 m everywhere, aligned 0, RPE 0
        gt = np.stack([pose(rotvec=(0, 0.1 * i, 0), t=(np.sin(i), 0, float(i))) for i in range(5)])
        est = gt.copy()
        est[:, :3, 3] += [1, 2, 2]
        np.testing.assert_allclose(ate_errors(gt, est, align=False), 3.0)
        np.testing.assert_allclose(ate_errors(gt, est, align=True), 0.0, atol=1e-9)
        trans, rot = rpe_errors(gt, est)
        np.testing.assert_allclose(trans, 0.0, atol=1e-12)
        np.testing.assert_allclose(rot, 0.0, atol=1e-6)

    def test_hand_computed_rpe(self):
        # ground truth moves 1 m forward per frame; the estimate moves 1.5 m and turns 10° about y each frame,
        # so every relative error is a 10° rotation and a 0.5 m translation.
        gt = straight_line(4)
        step = pose(rotvec=(0, np.radians(10), 0), t=(0, 0, 1.5))
        est = [np.eye(4)]
        for _ in range(3):
            est.append(est[-1] @ step)
        trans, rot = rpe_errors(gt, np.stack(est))
        np.testing.assert_allclose(trans, 0.5, atol=1e-12)
        np.testing.assert_allclose(rot, 10.0, atol=1e-9)
        stats = Statistics.of(np.array([1.0, 2.0, 3.0, 6.0]))
        assert stats.rmse == pytest.approx(np.sqrt(50 / 4)) and stats.mean == 3 and stats.median == 2.5
        assert stats.std == pytest.approx(np.sqrt(((1 - 3) ** 2 + 1 + 0 + 9) / 4)) and stats.min == 1
        assert stats.max == 6

    def test_matches_evo(self):
        # evo_reference.json was written by evo 1.38.1 on these two TUM files (see its _generated_by)
        reference = json.loads((DATA / "evo_reference.json").read_text())
        _, gt = read_tum(DATA / "traj_gt.tum")
        _, est = read_tum(DATA / "traj_est.tum")
        scores = score_trajectory(gt, est)
        for name in ("ate_aligned", "ate", "rpe_trans_m", "rpe_rot_deg"):
            for stat, value in reference[name].items():
                assert getattr(getattr(scores, name), stat) == pytest.approx(value, rel=1e-9, abs=1e-9), (name, stat)

    def test_matches_evo_live(self):
        # evo is in the test extra: a missing evo is a broken test set-up, not a reason to skip
        from evo.core import metrics
        from evo.tools import file_interface

        ref = file_interface.read_tum_trajectory_file(str(DATA / "traj_gt.tum"))
        est = file_interface.read_tum_trajectory_file(str(DATA / "traj_est.tum"))
        ape = metrics.APE(metrics.PoseRelation.translation_part)
        ape.process_data((ref, est))
        _, gt = read_tum(DATA / "traj_gt.tum")
        _, est_T = read_tum(DATA / "traj_est.tum")
        assert score_trajectory(gt, est_T).ate.rmse == pytest.approx(ape.get_statistic(metrics.StatisticsType.rmse))

    @pytest.mark.parametrize("angle", [1e-8, 1e-3, np.pi - 1e-7])
    def test_rpe_angle_near_0_and_pi(self, angle):
        est = np.stack([np.eye(4), pose(rotvec=(0, 0, angle))])
        _, rot = rpe_errors(np.stack([np.eye(4), np.eye(4)]), est)
        assert np.radians(rot[0]) == pytest.approx(angle, rel=1e-9)

    def test_single_pose_has_no_rpe(self):
        scores = score_trajectory(straight_line(1), straight_line(1))
        assert scores.rpe_trans_m is None and scores.flat()["rpe_rot_deg_rmse"] is None
        assert scores.ate_aligned is None and scores.ate.rmse == 0


class TestPairing:
    def test_prefix(self):
        assert pair_by_timestamps(np.arange(3) * 0.1, np.arange(5) * 0.1, allow_prefix=True) == 3

    def test_different_lengths_fail(self):
        with pytest.raises(DcslamError, match="different lengths"):
            pair_by_timestamps(np.arange(3) * 0.1, np.arange(5) * 0.1)

    def test_unsorted_fail(self):
        with pytest.raises(DcslamError, match="not strictly increasing"):
            pair_by_timestamps(np.array([0.0, 0.2, 0.1]), np.array([0.0, 0.1, 0.2]))

    def test_mismatched_timestamps_fail(self):
        with pytest.raises(DcslamError, match="do not match"):
            pair_by_timestamps(np.array([0.0, 0.1, 0.25]), np.array([0.0, 0.1, 0.2]))
