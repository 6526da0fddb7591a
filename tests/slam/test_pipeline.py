import torch

from dcslam.geometry.se3 import pose_error
from dcslam.slam.config import SlamSettings, build_slam
from dcslam.slam.scene import StreetScene, kitti_K, lidar_mask, street_trajectory

H, W = 64, 208


def _sparse_drive(frames: int, step: float, seed: int = 2):
    scene, K = StreetScene(seed), kitti_K(H, W)
    T = street_trajectory(frames, step=step)
    mask = lidar_mask(H, W, row_step=4, col_step=4)
    depth = torch.stack([scene.render(T[i], K, H, W) * mask for i in range(frames)]).float()[:, None]
    return depth, K, T


def test_gradicp_follows_a_moving_car_on_sparse_depth():
    """The README's example (differentiable LM + ICP-SLAM map) once left every pose at the identity: LiDAR-like
    scan lines land on the same pixels at the initial guess, so re-associating at each candidate pose made every
    step look worse and the solver stopped at its first rejected step."""
    depth, K, T = _sparse_drive(5, step=1.2)
    slam = build_slam(SlamSettings(odometry="gradicp", mapper="icpslam"))
    poses = slam.run(depth, K)
    dt, _ = pose_error(poses.double(), T)
    travelled = float(poses[-1, :3, 3].norm())
    assert travelled > 0.8 * float(T[-1, :3, 3].norm())
    assert float(dt.max()) < 0.25
