"""Values that make a camera or a pose meaningless are refused where they are read, in one line naming the file."""
import re
import shutil

import h5py
import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.io.kitti_calib import read_calibration
from dcslam.io.validate import check_intrinsics, check_poses
from tests.fixtures.kitti import SAMPLE

K = np.array([[700.0, 0, 600], [0, 700, 180], [0, 0, 1]])


@pytest.mark.parametrize("bad, match", [
    (np.zeros((3, 3)), "is not a camera's intrinsic matrix"),
    (np.diag([700.0, 0.0, 1.0]), "is not a camera's intrinsic matrix"),
    (np.where(np.eye(3) > 0, np.nan, 0.0), "holds non-finite values"),
    (np.ones((3, 4)), r"has shape \(3, 4\)"),
])
def test_intrinsics_that_are_no_camera(bad, match):
    with pytest.raises(DcslamError, match=f"^cam.txt: .*{match}"):
        check_intrinsics(bad, "cam.txt")
    icl = np.array([[481.2, 0, 319.5], [0, -480.0, 239.5], [0, 0, 1]])   # a negative fy is a camera (ICL-NUIM)
    assert np.array_equal(check_intrinsics(icl, "icl"), icl)


@pytest.mark.parametrize("change, match", [
    (lambda T: T.__setitem__((1, 0, 0), np.inf), "pose 1 is not finite"),
    (lambda T: T.__setitem__((2, slice(0, 3), slice(0, 3)), 2 * np.eye(3)),
     "the rotation of pose 2 is not orthonormal"),
    (lambda T: T.__setitem__((0, 3, 0), 1.0), r"pose 0 has bottom row \[1.0, 0.0, 0.0, 1.0\]"),
])
def test_poses_that_are_no_pose(change, match):
    T = np.tile(np.eye(4), (3, 1, 1))
    change(T)
    with pytest.raises(DcslamError, match=f"^p.h5: {match}"):
        check_poses(T, "p.h5")


def _calibration(tmp_path, key, value):
    date = tmp_path / "2011_09_26"
    shutil.copytree(SAMPLE / "raw" / "2011_09_26", date, ignore=shutil.ignore_patterns("*_sync"))
    path = date / "calib_cam_to_cam.txt"
    lines = [f"{key}: {value}" if line.startswith(f"{key}:") else line for line in path.read_text().splitlines()]
    path.write_text("\n".join(lines) + "\n")
    return date


@pytest.mark.parametrize("key, value, match", [
    ("P_rect_02", " ".join(["0"] * 12), r"P_rect_02: K = \[0 0 0 .*\] is not a camera's intrinsic matrix"),
    ("P_rect_02", "nan " + " ".join(["1"] * 11), "P_rect_02 holds non-finite values"),
    ("R_rect_00", "1 0 0 0 1 0 0 0 0", "R_rect_00 is not a rotation matrix"),
])
def test_a_calibration_that_holds_no_camera(tmp_path, key, value, match):
    date = _calibration(tmp_path, key, value)
    with pytest.raises(DcslamError, match=f"calib_cam_to_cam.txt: {match}"):
        read_calibration(date)


@pytest.mark.parametrize("name, value, match", [
    ("K", np.zeros((3, 3)), "K: K = .* is not a camera's intrinsic matrix"),
    ("T_world_cam", 3.0, "T_world_cam: the rotation of pose 1 is not orthonormal"),
])
def test_slam_over_a_drive_without_a_camera_is_one_line(cli, tmp_path, name, value, match):
    from tests.fixtures.depth import write_workspace

    ws = write_workspace(tmp_path / "ws", n=4)
    drive = ws / "drives" / "drive_d.h5"
    with h5py.File(drive, "a") as h5:
        if name == "K":
            h5["K"][...] = value
        else:
            h5["T_world_cam"][1, :3, :3] = value * np.eye(3)
    result = cli("slam", "-w", str(ws), "--odometry", "icp", "--frames", "3")
    assert result.exit_code == 1, result.output
    assert result.stderr.strip().splitlines() == [result.stderr.strip()]
    assert str(drive) in result.stderr and "prepare-kitti --force" in result.stderr
    assert re.search(match, result.stderr)
    assert not (ws / "slam").exists()
