import pytest
import torch

from dcslam.errors import DcslamError
from dcslam.geometry.se3 import pose_error
from dcslam.slam.config import SlamSettings, build_slam
from dcslam.slam.pipeline import SLAM
from dcslam.slam.scene import StreetScene, kitti_K, lidar_mask, street_trajectory

H, W = 64, 208


def _sparse_drive(frames: int, step: float, seed: int = 2):
    scene, K = StreetScene(seed), kitti_K(H, W)
    T = street_trajectory(frames, step=step)
    mask = lidar_mask(H, W, row_step=4, col_step=4)
    depth = torch.stack([scene.render(T[i], K, H, W) * mask for i in range(frames)]).float()[:, None]
    return depth, K, T


def test_gradicp_follows_a_moving_car_on_sparse_depth():
    """The example of docs/usage.md (differentiable LM + ICP-SLAM map) must track a moving car: LiDAR-like scan
    lines land on the same pixels at the initial guess, so re-associating at each candidate pose made every
    step look worse and the solver stopped at its first rejected step."""
    depth, K, T = _sparse_drive(5, step=1.2)
    slam = build_slam(SlamSettings(odometry="gradicp", mapper="icpslam"))
    poses = slam.run(depth, K)
    dt, _ = pose_error(poses.double(), T)
    travelled = float(poses[-1, :3, 3].norm())
    assert travelled > 0.8 * float(T[-1, :3, 3].norm())
    assert float(dt.max()) < 0.25


def test_metric_settings_follow_the_scene_depth():
    """Voxel sizes and the gate are for streets (median depth ~12 m); a room scales them down, a street not. The
    parts keep their settings; the scale goes with each call and the effective settings say what it came to."""
    K = kitti_K(H, W)
    slam = build_slam(SlamSettings(voxel_size=0.2, source_voxel=0.2, max_distance=0.5, reference_depth=12.0))
    assert slam.scale is None and slam.effective_settings()["scene_scale"] is None
    slam.step(torch.full((1, 1, H, W), 2.4), K)
    effective = slam.effective_settings()
    assert abs(slam.scale - 0.2) < 1e-6 and abs(effective["scene_scale"] - 0.2) < 1e-6
    assert effective["first_frame_median_depth"] == pytest.approx(2.4) and effective["reference_depth"] == 12.0
    assert abs(effective["voxel_size"] - 0.04) < 1e-6 and abs(effective["source_voxel"] - 0.04) < 1e-6
    assert abs(effective["max_distance"] - 0.1) < 1e-6
    assert effective["gates"] == pytest.approx([0.4, 0.2, 0.1])
    assert slam.mapper.voxel_size == 0.2 and slam.odometry.max_distance == 0.5 and slam.odometry.source_voxel == 0.2
    slam.reset()
    assert slam.scale is None
    slam.step(torch.full((1, 1, H, W), 30.0), K)
    assert slam.scale == 1.0 and slam.effective_settings()["voxel_size"] == 0.2
    fixed = build_slam(SlamSettings(reference_depth=0))
    assert fixed.scale == 1.0
    fixed.step(torch.full((1, 1, H, W), 2.4), K)
    assert fixed.scale == 1.0 and fixed.effective_settings()["max_distance"] == 0.5
    adaptive = build_slam(SlamSettings(adaptive_threshold=True))
    adaptive.step(torch.full((1, 1, H, W), 2.4), K)
    assert adaptive.effective_settings()["max_distance"] is None and adaptive.effective_settings()["gates"] is None
    assert build_slam(SlamSettings(odometry="gt")).effective_settings().keys() == {
        "scene_scale", "reference_depth", "first_frame_median_depth", "voxel_size"}


def test_a_room_is_mapped_and_aligned_at_the_scaled_sizes():
    """The scale reaches the parts: a room's map is fused at the scaled voxel (more points than at the street
    voxel) and its ICP sources are thinned at the scaled source voxel, as if those sizes had been asked for."""
    from dcslam.slam.frame import prepare_frame

    scene, K = StreetScene(4), kitti_K(H, W)
    T = street_trajectory(3, step=0.1)
    depth = torch.stack([scene.render(T[i], K, H, W) for i in range(3)]).float()[:, None] * 0.2
    scaled = build_slam(SlamSettings(voxel_size=0.2, source_voxel=0.2, reference_depth=12.0))
    poses = scaled.run(depth, K)
    s = scaled.scale
    assert 0 < s < 1
    asked = build_slam(SlamSettings(voxel_size=0.2 * s, source_voxel=0.2 * s, max_distance=0.5 * s,
                                    reference_depth=0))
    assert torch.equal(asked.run(depth, K), poses) and torch.equal(asked.map.points, scaled.map.points)
    street = build_slam(SlamSettings(voxel_size=0.2, source_voxel=0.2, reference_depth=0))
    street.run(depth, K)
    assert len(scaled.map) > len(street.map)
    frame = prepare_frame(depth[1:2], K, settings=scaled.frame_settings)
    scaled.precompute(frame)                     # the scale is known: the sources are thinned at the scaled voxel
    assert ("icp-sources", 0.2 * s) in frame.cache


def test_a_prepared_frame_gives_the_step_of_its_depth():
    """step_frame (a frame prepared elsewhere, e.g. on the prefetch thread) is step, bit for bit."""
    from dcslam.slam.frame import prepare_frame

    for mapper in ("pointfusion", "icpslam"):
        depth, K, _ = _sparse_drive(4, step=0.8)
        a, b = build_slam(SlamSettings(mapper=mapper)), build_slam(SlamSettings(mapper=mapper))
        for i in range(len(depth)):
            ra = a.step(depth[i:i + 1], K)
            frame = prepare_frame(depth[i:i + 1], K, settings=b.frame_settings)
            b.precompute(frame)                                      # what the prefetch thread does
            assert frame.cache
            rb = b.step_frame(frame)
            assert torch.equal(ra.T_world_cam, rb.T_world_cam) and ra.iterations == rb.iterations
        assert torch.equal(a.map.points, b.map.points)


@pytest.mark.parametrize("settings", [SlamSettings(), SlamSettings(odometry="gradicp", mapper="icpslam")],
                         ids=["icp-pointfusion", "gradicp-icpslam"])
def test_slam_in_each_dtype_and_on_each_device(device, dtype, settings):
    """The frame loop (odometry against the map, then fusion) tracks a moving car in float32 and float64, on the CPU
    and on a GPU; poses and map stay in the depth's dtype, on its device."""
    depth, K, T = _sparse_drive(4, step=0.8)
    slam = build_slam(settings)
    poses = slam.run(depth.to(device=device, dtype=dtype), K.to(device=device, dtype=dtype))
    assert poses.shape == (4, 4, 4) and poses.dtype == dtype and poses.device.type == device.type
    assert slam.map.points.dtype == dtype and slam.map.points.device.type == device.type
    assert slam.rejected == []
    dt, _ = pose_error(poses.double().cpu(), T)
    assert float(dt.max()) < 0.25


def _open_road(frames: int, step: float):
    """Exact depth of a road with two low kerbs along it and nothing across it: the along-road motion is barely
    constrained (conditioning below hold_below), so each step keeps its prediction along the road."""
    scene, K = StreetScene(0), kitti_K(H, W)
    g = scene.ground_y
    scene.boxes = torch.tensor([[-4.2, g - 0.15, -10, -4.0, g, 200], [4.0, g - 0.15, -10, 4.2, g, 200]],
                               dtype=torch.float64)
    T = street_trajectory(frames, step=step, sway=0.0, yaw_deg=0.0)
    depth = torch.stack([scene.render(T[i], K, H, W) for i in range(frames)]).float()[:, None]
    return depth, K, T


def test_the_first_step_prior_carries_the_car_along_an_open_road():
    """Without a velocity the first step starts at frame 0's pose and, on an open road, stays there: the car is
    seen standing and every later step inherits that. Predicted from the drive's poses, it tracks."""
    depth, K, T = _open_road(3, step=1.5)
    errors = {}
    for name in ("none", "drive-motion"):
        slam = build_slam(SlamSettings(first_step_prior=name))
        dt, _ = pose_error(slam.run(depth, K, T_gt=T.float()).double(), T)
        errors[name] = dt
    assert float(errors["none"][1]) > 1.4 and float(errors["none"][2]) > 2.9
    assert float(errors["drive-motion"].max()) < 0.05


def test_the_first_step_prior_needs_the_drive_poses():
    depth, K, T = _open_road(2, step=1.5)
    slam = build_slam(SlamSettings(first_step_prior="drive-motion"))
    slam.step(depth[:1], K, T_gt=T[0].float())
    with pytest.raises(DcslamError, match="ground-truth poses"):
        slam.step(depth[1:2], K)
    with pytest.raises(DcslamError, match="first-step prior"):
        SLAM(slam.odometry, slam.mapper, first_step_prior="gps")
