"""Projections of scans into camera 2 and the KITTI-style ground-truth consistency check."""
import numpy as np

from dcslam.synth.street.sensors import (consistent_groundtruth, hdl64_elevations_deg, make_lidar_grid, project_points,
                                         stereo_valid)

K = np.array([[50.0, 0, 20], [0, 50.0, 10], [0, 0, 1]])


def test_projection_keeps_the_nearest_point_per_pixel():
    points = np.array([[0, 0, 10.0], [0.001, 0, 5.0], [0, 0, 20.0], [2.0, 0, 10.0], [0, 0, -3.0]], np.float32)
    depth = project_points(points, K, 40, 20)
    assert depth.shape == (20, 40)
    assert depth[10, 20] == 5.0  # nearest of three on the same pixel
    assert depth[10, 30] == 10.0
    assert np.count_nonzero(depth) == 2  # the point behind the camera is dropped


def test_groundtruth_drops_points_that_disagree_with_the_view():
    true_depth = np.full((20, 40), 8.0, np.float32)
    true_depth[:, 30:] = 0  # sky
    points = np.array([[0, 0, 8.02],     # on the surface: kept
                       [0.16, 0, 8.0],   # on the surface, another pixel: kept
                       [0.8, 0, 16.0],   # behind the surface (seen through it): dropped
                       [4.0, 0, 10.0]],  # where the camera sees sky: dropped
                      np.float32)
    gt = consistent_groundtruth(points, true_depth, K)
    assert np.count_nonzero(gt) == 2
    assert gt[10, 20] == np.float32(8.02) and gt[10, 21] == 8.0
    valid = np.ones((20, 40), bool)
    valid[10, 20] = False
    assert np.count_nonzero(consistent_groundtruth(points, true_depth, K, valid)) == 1


def test_stereo_validity_needs_texture():
    rng = np.random.default_rng(0)
    rgb = np.full((40, 60, 3), 128, np.uint8)
    rgb[:, 30:] = rng.integers(0, 255, (40, 30, 3), dtype=np.uint8)
    valid = stereo_valid(rgb)
    assert not valid[:, :25].any() and valid[:, 35:].all()


def test_lidar_geometry_is_the_hdl64e():
    el = hdl64_elevations_deg()
    assert len(el) == 64 and el[0] == 2.0 and el[-1] == -24.8 and np.all(np.diff(el) < 0)
    grid = make_lidar_grid(0.08)
    assert grid.dirs.shape == (64, 2250, 3)
    np.testing.assert_allclose(np.linalg.norm(grid.dirs, axis=-1), 1, atol=1e-6)
    az = np.degrees(np.arctan2(grid.dirs[..., 1], grid.dirs[..., 0]))
    assert abs(az[1, 0] - az[0, 0] - 0.08) < 1e-4  # neighbouring lasers interleave
    assert abs(az[0, 1] - az[0, 0] - 0.16) < 1e-4
