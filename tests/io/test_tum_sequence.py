"""Indexing TUM RGB-D and ICL-NUIM sequence folders: pose lookup, pairing, intrinsics, ground-truth names,
errors; the folders are written by IclWriter or by hand (tests/fixtures/tum.py)."""

import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.io import tum_rgbd as tr
from dcslam.io import tum_sequence as ts
from tests.fixtures import tum as fx

H, W, pose, write_tum_sequence, write_icl_sequence = fx.H, fx.W, fx.pose, fx.write_tum_sequence, fx.write_icl_sequence


class TestPoses:
    def test_interpolates_between_close_poses(self):
        gt_t = np.arange(0.0, 1.0, 0.01)
        T, found = ts.interpolate_poses(np.array([0.123, 0.5]), gt_t, np.stack([pose(t) for t in gt_t]))
        assert found.all()
        for k, t in enumerate([0.123, 0.5]):
            assert np.abs(T[k] - pose(t)).max() < 1e-9  # lerp / slerp are exact for this motion

    def test_nearest_within_tolerance_across_a_gap_else_none(self):
        gt_t = np.array([0.0, 1.0, 2.0])
        T_gt = np.stack([pose(t) for t in gt_t])
        T, found = ts.interpolate_poses(np.array([-0.5, 0.01, 1.0, 1.5, 2.019, 2.5]), gt_t, T_gt)
        assert found.tolist() == [False, True, True, False, True, False]
        assert np.array_equal(T[1], T_gt[0]) and np.array_equal(T[2], T_gt[1]) and np.array_equal(T[4], T_gt[2])


class TestIndexSequence:
    def test_tum(self, tmp_path):
        rgb_t = [10.0 + 0.033 * k for k in range(6)]
        depth_t = [t + 0.004 for t in rgb_t[:5]] + [rgb_t[5] + 0.03]  # the last depth has no partner
        root = write_tum_sequence(tmp_path / "rgbd_dataset_freiburg1_xyz", rgb_t, depth_t,
                                  list(np.arange(9.9, 10.3, 0.01)))
        seq = ts.index_sequence(root)
        assert seq.format == tr.TUM and seq.name == "rgbd_dataset_freiburg1_xyz" and len(seq) == 5
        assert np.array_equal(seq.K, tr.TUM_K) and seq.groundtruth == root / "groundtruth.txt"
        assert seq.timestamps == pytest.approx(depth_t[:5]) and seq.frame_ids.tolist() == [0, 1, 2, 3, 4]
        assert [p.name for p in seq.rgb_paths] == [f"{t:.6f}.png" for t in rgb_t[:5]]
        for k, t in enumerate(depth_t[:5]):  # pose at the depth timestamp, interpolated
            assert np.abs(seq.T_world_cam[k] - pose(t)).max() < 1e-6
        assert any("1 of 6 depth images have no colour image" in n for n in seq.notes)
        rgb, depth = next(seq.frames())
        assert rgb.shape == (H, W, 3) and depth.shape == (H, W) and depth.dtype == np.float32

    def test_icl_negative_fy_and_trajectory_round_trip(self, tmp_path):
        root = write_icl_sequence(tmp_path / "living_room_traj0_frei_png", frames=4)
        seq = ts.index_sequence(root)
        assert seq.format == tr.ICL and seq.K[1, 1] == -480.0 and np.array_equal(seq.K, tr.ICL_K)
        assert seq.timestamps.tolist() == [0, 1, 2, 3] and len(seq) == 4
        assert np.abs(seq.T_world_cam - np.stack([pose(k) for k in range(4)])).max() < 1e-9
        assert (root / "associations.txt").read_text().splitlines()[0] == "0 depth/0.png 0 rgb/0.png"

    def test_icl_groundtruth_in_parent_and_first_frame_without_pose(self, tmp_path):
        root = write_icl_sequence(tmp_path / "living_room_traj2n_frei_png", frames=5, gt_from=1)
        (root / "livingRoom0.gt.freiburg").rename(tmp_path / "livingRoom2.gt.freiburg")
        seq = ts.index_sequence(root)
        assert seq.groundtruth == tmp_path / "livingRoom2.gt.freiburg"
        assert seq.frame_ids.tolist() == [1, 2, 3, 4] and seq.timestamps.tolist() == [1, 2, 3, 4]
        assert any("1 frame(s) without a ground-truth pose" in n for n in seq.notes)
        assert seq.subsample(2).frame_ids.tolist() == [1, 3] and seq.subsample(1, 2).frame_ids.tolist() == [1, 2]

    def test_intrinsics_given_then_file_then_default(self, tmp_path):
        K = tr.make_K(100.0, -90.0, 3.5, 2.5)
        root = write_icl_sequence(tmp_path / "living_room_traj0_frei_png", K=K)
        assert np.array_equal(ts.index_sequence(root).K, K)                      # intrinsics.txt
        assert np.array_equal(ts.index_sequence(root, intrinsics=tr.TUM_K).K, tr.TUM_K)
        (root / tr.INTRINSICS_FILE).unlink()
        assert np.array_equal(ts.index_sequence(root).K, tr.ICL_K)

    def test_missing_image(self, tmp_path):
        root = write_icl_sequence(tmp_path / "living_room_traj0_frei_png")
        (root / "rgb" / "2.png").unlink()
        with pytest.raises(DcslamError, match=r"rgb/2.png not found \(listed in .*associations.txt\)"):
            ts.index_sequence(root)

    def test_missing_tum_depth_image(self, tmp_path):
        root = write_tum_sequence(tmp_path / "seq", [1.0, 1.1], [1.0, 1.1], [0.9, 1.0, 1.05, 1.1, 1.2])
        (root / "depth" / "1.100000.png").unlink()
        with pytest.raises(DcslamError, match=r"1.100000.png not found \(listed in .*depth.txt\)"):
            ts.index_sequence(root)

    def test_unsorted_association(self, tmp_path):
        root = write_icl_sequence(tmp_path / "living_room_traj0_frei_png")
        lines = (root / "associations.txt").read_text().splitlines()
        (root / "associations.txt").write_text("\n".join([lines[1], lines[0], *lines[2:]]) + "\n")
        with pytest.raises(DcslamError, match="associations.txt:2: .*strictly increasing"):
            ts.index_sequence(root)

    def test_no_groundtruth(self, tmp_path):
        root = write_icl_sequence(tmp_path / "living_room_traj3_frei_png")
        (root / "livingRoom0.gt.freiburg").unlink()
        with pytest.raises(DcslamError, match=r"no ground-truth trajectory .*livingRoom3.gt.freiburg"):
            ts.index_sequence(root)

    def test_no_pose_overlap(self, tmp_path):
        root = write_tum_sequence(tmp_path / "seq", [1.0, 1.1], [1.0, 1.1], [5.0, 5.01])
        with pytest.raises(DcslamError, match="no frame has a ground-truth pose"):
            ts.index_sequence(root)

    def test_not_a_sequence(self, tmp_path):
        (tmp_path / "empty").mkdir()
        with pytest.raises(DcslamError, match="not a TUM RGB-D or ICL-NUIM sequence"):
            ts.index_sequence(tmp_path / "empty")
        with pytest.raises(DcslamError, match="no TUM RGB-D or ICL-NUIM sequence in"):
            ts.find_sequences(tmp_path / "empty")
        with pytest.raises(DcslamError, match="is not a folder"):
            ts.find_sequences(tmp_path / "none")


def test_find_sequences_and_groundtruth_names(tmp_path):
    for name in ("living_room_traj1_frei_png", "living_room_traj0_frei_png"):
        write_icl_sequence(tmp_path / name, frames=1)
    (tmp_path / "notes").mkdir()
    assert [p.name for p in ts.find_sequences(tmp_path)] == ["living_room_traj0_frei_png",
                                                           "living_room_traj1_frei_png"]
    assert ts.find_sequences(tmp_path / "living_room_traj1_frei_png") == [tmp_path / "living_room_traj1_frei_png"]
    office = tmp_path / "traj2_frei_png"
    office.mkdir()
    (tmp_path / "traj2.gt.freiburg").write_text("0 0 0 0 0 0 0 1\n")
    assert ts.find_groundtruth(office) == tmp_path / "traj2.gt.freiburg"
    one = tmp_path / "living_room_traj0_frei_png"
    (one / "other.gt.freiburg").write_text("0 0 0 0 0 0 0 1\n")
    assert ts.find_groundtruth(one) == one / "livingRoom0.gt.freiburg"  # of two, the one named as ICL-NUIM's
    (one / "livingRoom0.gt.freiburg").rename(one / "third.gt.freiburg")
    with pytest.raises(DcslamError, match="2 \\*.gt.freiburg files"):
        ts.find_groundtruth(one)
    (one / "groundtruth.txt").write_text("0 0 0 0 0 0 0 1\n")
    assert ts.find_groundtruth(one) == one / "groundtruth.txt"
