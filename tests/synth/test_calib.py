"""The real 2011-09-26 calibration shipped as package data."""
import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.synth.calib import CALIB_DIR, CALIB_FILES, copy_calibration, load_rig

SAMPLE = "/work/shared/kitti-sample/raw/2011_09_26"


def test_rig_is_the_real_kitti_camera_2():
    rig = load_rig()
    assert (rig.width, rig.height) == (1242, 375)
    np.testing.assert_allclose(rig.K_cam2, [[721.5377, 0, 609.5593], [0, 721.5377, 172.854], [0, 0, 1]])
    # camera 2 is ~0.27 m ahead of and ~0.08 m below the Velodyne (x forward, z up there; z forward, y down here)
    T_velo_cam2 = np.linalg.inv(rig.T_cam2_velo)
    np.testing.assert_allclose(T_velo_cam2[:3, 3], [0.27, 0.0, -0.08], atol=0.07)
    np.testing.assert_allclose(T_velo_cam2[:3, :3] @ [0, 0, 1.0], [1, 0, 0], atol=0.02)
    # the IMU is ~0.8 m below and ~0.8 m behind the Velodyne
    np.testing.assert_allclose(rig.T_velo_imu[:3, 3], [-0.81, 0.32, -0.80], atol=0.01)


def test_rig_agrees_with_the_kitti_reader():
    kitti_calib = pytest.importorskip("dcslam.io.kitti_calib")
    calib = kitti_calib.read_calibration(CALIB_DIR)
    rig = load_rig()
    np.testing.assert_allclose(rig.T_cam2_imu, calib.T_cam2_imu, atol=1e-12)
    np.testing.assert_allclose(rig.K_cam2, calib.K_cam2)


def test_package_files_are_the_real_files_verbatim():
    from pathlib import Path

    if not Path(SAMPLE).exists():
        pytest.skip("KITTI sample not on this machine")
    for name in CALIB_FILES:
        assert (CALIB_DIR / name).read_bytes() == (Path(SAMPLE) / name).read_bytes()


def test_copy_calibration_refuses_to_replace_different_files(tmp_path):
    copy_calibration(tmp_path, force=False)
    copy_calibration(tmp_path, force=False)  # same bytes: fine
    (tmp_path / CALIB_FILES[0]).write_text("K_00: 1 2 3\n")
    with pytest.raises(DcslamError, match="--force"):
        copy_calibration(tmp_path, force=False)
    copy_calibration(tmp_path, force=True)
    assert (tmp_path / CALIB_FILES[0]).read_bytes() == (CALIB_DIR / CALIB_FILES[0]).read_bytes()


def test_malformed_calibration_is_an_error(tmp_path):
    for name in CALIB_FILES:
        (tmp_path / name).write_text("calib_time: never\n")
    with pytest.raises(DcslamError, match="calibration"):
        load_rig(tmp_path)
