"""The real 2011-09-26 calibration shipped as package data, read through dcslam.io and copied beside the drives."""
import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.io.kitti_calib import CALIB_FILES, copy_calibration
from dcslam.synth.street.generate import CALIB_DIR, street_calibration
from tests.fixtures.kitti import SAMPLE

CALIB_2011_09_26 = SAMPLE / "raw" / "2011_09_26"  # the committed KITTI sample's calibration (tests/data/)


def test_calibration_is_the_real_kitti_camera_2():
    calib = street_calibration()
    assert calib.size_rect_02 == (1242, 375)
    np.testing.assert_allclose(calib.K_cam2, [[721.5377, 0, 609.5593], [0, 721.5377, 172.854], [0, 0, 1]])
    # camera 2 is ~0.27 m ahead of and ~0.08 m below the Velodyne (x forward, z up there; z forward, y down here)
    T_velo_cam2 = np.linalg.inv(calib.T_cam2_velo)
    np.testing.assert_allclose(T_velo_cam2[:3, 3], [0.27, 0.0, -0.08], atol=0.07)
    np.testing.assert_allclose(T_velo_cam2[:3, :3] @ [0, 0, 1.0], [1, 0, 0], atol=0.02)
    # the IMU is ~0.8 m below and ~0.8 m behind the Velodyne
    np.testing.assert_allclose(calib.T_velo_imu[:3, 3], [-0.81, 0.32, -0.80], atol=0.01)


def test_package_files_are_the_real_files_verbatim():
    assert len(CALIB_FILES) == 3
    for name in CALIB_FILES:
        assert (CALIB_DIR / name).read_bytes() == (CALIB_2011_09_26 / name).read_bytes(), name


def test_copy_calibration_refuses_to_replace_different_files(tmp_path):
    copy_calibration(CALIB_DIR, tmp_path, force=False)
    copy_calibration(CALIB_DIR, tmp_path, force=False)  # same bytes: fine
    (tmp_path / CALIB_FILES[0]).write_text("K_00: 1 2 3\n")
    with pytest.raises(DcslamError, match="--force"):
        copy_calibration(CALIB_DIR, tmp_path, force=False)
    copy_calibration(CALIB_DIR, tmp_path, force=True)
    assert (tmp_path / CALIB_FILES[0]).read_bytes() == (CALIB_DIR / CALIB_FILES[0]).read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(CALIB_FILES)  # no temporary files left


def test_copy_calibration_from_a_folder_without_the_files(tmp_path):
    with pytest.raises(DcslamError, match="calib_cam_to_cam.txt not found"):
        copy_calibration(tmp_path / "nowhere", tmp_path / "out", force=False)
