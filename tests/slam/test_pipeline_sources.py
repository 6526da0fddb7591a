"""SLAM.step_frame's ``source_frame``: the odometry aligns its points while the map fuses the frame."""
import pytest
import torch

from dcslam.errors import DcslamError
from dcslam.slam.config import SlamSettings, build_slam
from dcslam.slam.frame import prepare_frame
from dcslam.slam.scene import StreetScene, kitti_K, lidar_mask, street_trajectory

H, W = 64, 208


def test_the_odometry_aligns_the_source_frame_and_the_map_fuses_the_frame():
    scene, K, T = StreetScene(2), kitti_K(H, W), street_trajectory(3, step=0.8)
    mask = lidar_mask(H, W, row_step=4, col_step=4)
    slam = build_slam(SlamSettings())
    for i in range(3):
        exact = scene.render(T[i], K, H, W).float()[None, None]
        frame = prepare_frame(exact, K, None, slam.frame_settings)
        sparse = prepare_frame(exact * mask, K, None, slam.frame_settings)
        slam.precompute(frame, sparse)
        report = slam.step_frame(frame, source_frame=sparse)
        if i:   # the evidence is the measured pixels', not the frame's
            assert report.accepted and report.sources == slam.odometry.sources(sparse, slam.scale)[0]
            assert report.sources < slam.odometry.sources(frame, slam.scale)[0]
    assert float((slam.trajectory()[-1, :3, 3] - T[-1, :3, 3].float()).norm()) < 0.05
    assert len(slam.map) > int(sparse.valid.sum())                     # the map fuses the exact frames
    with pytest.raises(DcslamError, match="not the same camera"):
        slam.step_frame(frame, source_frame=prepare_frame(torch.ones(1, 1, H // 2, W), K))
