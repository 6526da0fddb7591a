"""The true motion of synthetic drives and the OXTS packets that describe it."""
import numpy as np
import pytest

from dcslam.geometry.rotations import rpy_from_rotation
from dcslam.io.kitti_calib import copy_calibration, read_calibration
from dcslam.io.kitti_oxts import OxtsPacket, camera_poses, oxts_to_T_world_imu, read_oxts, write_oxts
from dcslam.synth.street.generate import CALIB_DIR, make_drive, street_calibration
from dcslam.synth.street.trajectory import LIDAR_HEIGHT_M


@pytest.fixture(scope="module")
def rig():
    return street_calibration()


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_speed_is_kitti_like_and_smooth(rig, seed):
    truth, _ = make_drive(seed, 0, 120, rig)
    step = np.linalg.norm(np.diff(truth.T_world_cam2[:, :3, 3], axis=0), axis=1)
    assert step.min() >= 0.5 and step.max() <= 1.5
    dt = np.diff(truth.timestamps)
    assert dt.min() >= 0.0998 - 1e-6 and dt.max() <= 0.1102 + 1e-6  # POSIX seconds hold ~0.2 µs
    speed = step / dt
    assert np.abs(np.diff(speed)).max() < 0.5  # m/s change per frame: < 5 m/s²


@pytest.mark.parametrize("seed", [0, 5])
def test_lidar_is_mounted_1_73_m_above_the_ground_with_small_pitch_and_roll(rig, seed):
    truth, _ = make_drive(seed, 1, 60, rig)
    drive = truth.scene.drive
    T_world_velo = drive.T_world_velo(truth.timestamps - truth.timestamps[0])
    p = T_world_velo[:, :3, 3]
    np.testing.assert_allclose(p[:, 2] - drive.terrain.height(p[:, 0], p[:, 1]), LIDAR_HEIGHT_M, atol=1e-9)
    roll, pitch, _ = rpy_from_rotation(truth.T_world_imu[:, :3, :3])
    assert np.abs(roll).max() < np.deg2rad(3) and np.abs(pitch).max() < np.deg2rad(3)
    assert np.abs(pitch).max() > np.deg2rad(0.05)  # the terrain is not flat


def test_oxts_packets_are_consistent_with_the_motion(rig):
    truth, _ = make_drive(7, 0, 40, rig)
    oxts = truth.oxts
    assert oxts.shape == (40, 30)
    lines = [OxtsPacket.from_values(p).to_line() for p in oxts]
    assert all(len(line.split()) == 30 for line in lines)
    assert lines[0].split()[25:] == ["4", "8", "6", "6", "6"]
    # forward speed ≈ displacement / time, no sideways speed, gravity in the vertical specific force
    step = np.linalg.norm(np.diff(truth.T_world_imu[:, :3, 3], axis=0), axis=1) / np.diff(truth.timestamps)
    np.testing.assert_allclose((oxts[1:, 8] + oxts[:-1, 8]) / 2, step, rtol=0.02)
    assert np.abs(oxts[:, 9]).max() < 0.5
    np.testing.assert_allclose(oxts[:, 13], 9.81, atol=0.5)
    np.testing.assert_allclose(np.hypot(oxts[:, 6], oxts[:, 7]), np.hypot(oxts[:, 8], oxts[:, 9]), rtol=1e-9)
    # the yaw rate matches the heading change
    yaw = np.unwrap(oxts[:, 5])
    np.testing.assert_allclose((oxts[1:, 19] + oxts[:-1, 19]) / 2, np.diff(yaw) / np.diff(truth.timestamps),
                               atol=0.02)


def test_oxts_round_trip_through_the_kitti_reader(rig, tmp_path):
    """Poses read back by dcslam.io's OXTS reader and calibration chain equal the generator's truth."""
    truth, _ = make_drive(11, 2, 50, rig)
    for k, packet in enumerate(truth.oxts):
        write_oxts(tmp_path / f"{k}.txt", OxtsPacket.from_values(packet))
    packets = [read_oxts(tmp_path / f"{k}.txt") for k in range(len(truth.oxts))]
    copy_calibration(CALIB_DIR, tmp_path, force=False)
    calib = read_calibration(tmp_path)
    T_read = camera_poses(oxts_to_T_world_imu(packets), calib)
    T_true = truth.T_world_cam2
    assert np.abs(T_read[:, :3, 3] - T_true[:, :3, 3]).max() < 1e-3
    R_err = np.transpose(T_read[:, :3, :3], (0, 2, 1)) @ T_true[:, :3, :3]
    angle = np.arccos(np.clip((np.trace(R_err, axis1=1, axis2=2) - 1) / 2, -1, 1))
    assert angle.max() < 1e-5
    assert np.linalg.norm(T_true[-1, :3, 3]) > 20  # it did drive somewhere
