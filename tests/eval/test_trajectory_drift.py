"""KITTI odometry drift (t_rel %, r_rel deg/100 m) as the odometry devkit computes it."""
import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dcslam.errors import DcslamError
from dcslam.eval.trajectory import (DRIFT_LENGTHS_M, drift_segments, kitti_drift, path_distances,
                                    score_trajectory)
from dcslam.io.kitti_poses import read_kitti_poses

DATA = Path(__file__).parents[1] / "data"
_spec = importlib.util.spec_from_file_location("kitti_drift_reference", DATA / "kitti_drift_reference.py")
reference_script = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(reference_script)


def line(n: int, step_m: float = 1.0) -> np.ndarray:
    """n poses along the camera's z axis, ``step_m`` apart (a straight drive)."""
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, 2, 3] = step_m * np.arange(n)
    return T


def starts(n_frames: int, length: float) -> int:
    """Segments of one length on ``line(n_frames)``: starts f = 0, 10, ... with f + length + 1 <= n_frames - 1."""
    return len(range(0, n_frames - int(length) - 1, 10))


class TestKnownAnswers:
    def test_scale_error(self):
        # est moves 1 % too far each frame; a segment of length L ends at the first frame *beyond* L, L + 1 m away,
        # so its error is 0.01 (L + 1) / L
        gt = line(1001)
        est = gt.copy()
        est[:, 2, 3] *= 1.01
        drift = kitti_drift(gt, est)
        counts = {L: starts(1001, L) for L in DRIFT_LENGTHS_M}
        assert drift.overall.segments == sum(counts.values()) == 90 + 80 + 70 + 60 + 50 + 40 + 30 + 20
        expected = sum(counts[L] * 0.01 * (L + 1) / L for L in DRIFT_LENGTHS_M) / sum(counts.values())
        assert drift.overall.t_rel_percent == pytest.approx(100 * expected, rel=1e-12)
        assert drift.overall.r_rel_deg_per_100m == pytest.approx(0.0, abs=1e-9)
        for L in DRIFT_LENGTHS_M:
            assert drift.per_length[L].segments == counts[L]
            assert drift.per_length[L].t_rel_percent == pytest.approx(100 * 0.01 * (L + 1) / L, rel=1e-12)
        assert drift.path_length_m == pytest.approx(1000.0)

    def test_heading_drift(self):
        # est turns 1e-4 rad per frame about the direction of travel: a segment's rotation error is
        # 1e-4 (L + 1) rad over L m, and its translation error 0
        gt = line(601)
        est = gt.copy()
        est[:, :3, :3] = Rotation.from_rotvec(np.outer(1e-4 * np.arange(601), [0, 0, 1])).as_matrix()
        drift = kitti_drift(gt, est)
        assert drift.overall.t_rel_percent == pytest.approx(0.0, abs=1e-9)
        for L, figures in drift.per_length.items():
            assert figures.r_rel_deg_per_100m == pytest.approx(100 * np.degrees(1e-4 * (L + 1) / L), rel=1e-6)
        assert sorted(drift.per_length) == [100.0, 200.0, 300.0, 400.0, 500.0]

    def test_perfect_estimate(self):
        gt = line(300, 1.3)
        drift = kitti_drift(gt, gt.copy())
        assert drift.overall.t_rel_percent == 0.0 and drift.overall.r_rel_deg_per_100m == pytest.approx(0, abs=1e-7)

    def test_lengths_come_from_the_ground_truth(self):
        gt = line(401)
        est = gt.copy()
        est[:, 2, 3] *= 3.0     # the estimate travels 1200 m; segments still follow the 400 m of ground truth
        segments = drift_segments(gt, est)
        assert {s.length_m for s in segments} == {100.0, 200.0, 300.0}
        assert all(s.last - s.first == s.length_m + 1 for s in segments)
        assert [s.first for s in segments[:4]] == [0, 0, 0, 10]   # devkit order: starts, then lengths

    def test_starts_every_ten_frames_whatever_the_speed(self):
        gt = line(500, 0.5)           # 249.5 m
        segments = drift_segments(gt, gt)
        assert sorted({s.first for s in segments if s.length_m == 100.0}) == list(range(0, 299, 10))

    def test_per_length_means_add_up_to_the_overall(self):
        gt = read_kitti_poses(reference_script.POSES_04)
        drift = kitti_drift(gt, reference_script.perturb(gt))
        total = sum(f.segments for f in drift.per_length.values())
        weighted = sum(f.segments * f.t_rel_percent for f in drift.per_length.values()) / total
        assert total == drift.overall.segments
        assert weighted == pytest.approx(drift.overall.t_rel_percent, rel=1e-12)


class TestAgainstIndependentImplementation:
    def test_sequence_04_matches_kiss_icp(self):
        """Sequence 04 (271 frames, 393.6 m) against a perturbed copy; figures by KISS-ICP's C++ port of the devkit
        (tests/data/kitti_drift_reference.py made the JSON)."""
        reference = json.loads((DATA / "kitti_drift_reference.json").read_text())
        gt = read_kitti_poses(reference_script.POSES_04)
        drift = kitti_drift(gt, reference_script.perturb(gt))
        assert drift.overall.segments == 43
        assert drift.overall.t_rel_percent == pytest.approx(reference["t_rel_percent"], rel=1e-6)
        r_rel_deg_per_100m = reference["kiss_icp_r_rel_deg_per_m"] * 3.14 / np.pi * 100
        assert drift.overall.r_rel_deg_per_100m == pytest.approx(r_rel_deg_per_100m, rel=1e-6)


class TestShortAndBad:
    def test_too_short_is_a_clear_result(self):
        gt = line(30, 1.5)            # 43.5 m: no 100 m segment
        drift = kitti_drift(gt, gt)
        assert drift.overall is None and drift.per_length == {}
        assert "too short" in drift.note and "43.5 m" in drift.note
        row = score_trajectory(gt, gt).flat()
        assert row["kitti_t_rel_percent"] is None and row["kitti_r_rel_deg_per_100m"] is None
        assert row["kitti_segments"] == 0

    def test_exactly_one_length_long_is_too_short(self):
        # the devkit needs a frame strictly beyond start + 100 m
        assert kitti_drift(line(101), line(101)).overall is None
        assert kitti_drift(line(102), line(102)).overall.segments == 1

    def test_single_pose(self):
        assert kitti_drift(line(1), line(1)).overall is None
        assert path_distances(line(1)).tolist() == [0.0]

    def test_score_trajectory_carries_drift(self):
        gt = line(201)
        est = gt.copy()
        est[:, 2, 3] *= 1.02
        row = score_trajectory(gt, est).flat()
        assert row["kitti_segments"] == starts(201, 100.0)
        assert row["kitti_t_rel_percent"] == pytest.approx(2.0 * 101 / 100, rel=1e-12)

    def test_mismatched_lengths_fail(self):
        with pytest.raises(DcslamError, match="different lengths"):
            kitti_drift(line(200), line(199))
