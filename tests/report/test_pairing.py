"""Pairing an estimated trajectory with its reference: by index only when both have as many poses; by time with
the poses left out on either side said in one line."""
import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.io.kitti_poses import write_kitti_poses
from dcslam.io.tum import write_tum
from dcslam.report.layers import load_pair
from dcslam.report.scores import trajectory_table


def _poses(n: int) -> np.ndarray:
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, 0, 3] = np.arange(n) * 0.5
    return T


def test_a_shorter_kitti_estimate_is_not_scored_against_the_first_reference_poses(tmp_path):
    est, ref = tmp_path / "est.kitti.txt", tmp_path / "04.txt"
    write_kitti_poses(est, _poses(100))
    write_kitti_poses(ref, _poses(271))
    with pytest.raises(DcslamError, match=r"est\.kitti\.txt has 100 poses, its reference .*04\.txt 271: without "
                                          r"timestamps .* paired by index, which needs as many on each side"):
        load_pair(est, ref)


def test_a_tum_estimate_against_a_kitti_sequence_of_another_length_is_refused(tmp_path):
    est, ref = tmp_path / "drive.txt", tmp_path / "04.txt"
    write_tum(est, 0.1 * np.arange(10), _poses(10))
    write_kitti_poses(ref, _poses(271))
    with pytest.raises(DcslamError, match=r"drive\.txt has 10 poses, its reference .*04\.txt 271"):
        load_pair(est, ref)


def test_by_index_with_as_many_poses_on_each_side(tmp_path):
    est, ref = tmp_path / "est.kitti.txt", tmp_path / "ref.txt"
    write_kitti_poses(est, _poses(5))
    write_tum(ref, 1.0 + 0.1 * np.arange(5), _poses(5))
    pair = load_pair(est, ref)
    assert pair.summary() == "5 poses paired by index" and pair.left_out() is None
    assert np.allclose(pair.timestamps, 1.0 + 0.1 * np.arange(5))


def test_poses_left_out_by_time_are_said_in_one_line(tmp_path):
    est, ref = tmp_path / "est.txt", tmp_path / "ref.txt"
    write_tum(est, 5.0 + 0.1 * np.arange(4), _poses(4))     # 5.2 s and 5.3 s have no reference pose within 10 ms
    write_tum(ref, 0.1 * np.arange(52), _poses(52))          # 0 .. 5.1 s
    pair = load_pair(est, ref)
    line = pair.left_out()
    assert line == "2 of 4 estimated and 50 of 52 reference poses left out (no pose within 10 ms on the other side)"
    table = trajectory_table({"est": pair}, "t")
    assert f"est: {line}" in table.notes
    complete = load_pair(ref, ref)
    assert complete.left_out() is None and not any("left out" in n for n in trajectory_table({"r": complete},
                                                                                             "t").notes)
