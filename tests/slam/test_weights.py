"""Per-pixel weights (a completer's confidence) in SLAM: the frame, ICP (weighted residuals, the pose a
differentiable function of weight and depth, weight 0 no evidence) and fusion (weighted confidences, weight 0 not
fused)."""
import math

import pytest
import torch

from dcslam.errors import DcslamError
from dcslam.geometry.se3 import pose_error, se3_exp
from dcslam.slam.association import view_from_frame
from dcslam.slam.frame import prepare_frame
from dcslam.slam.fusion import PointFusion, surfel_weights
from dcslam.slam.icpslam import ICPSLAM
from dcslam.slam.odometry import ICPOdometry, PointToPlane
from dcslam.slam.pipeline import SLAM, build_map
from dcslam.slam.scene import StreetScene, kitti_K, street_trajectory
from dcslam.slam.solvers import DifferentiableLM

H, W = 64, 208


@pytest.fixture(scope="module")
def street():
    scene, K = StreetScene(0), kitti_K(H, W)
    T = street_trajectory(2, step=0.6)
    depth = [scene.render(T[i], K, H, W).float()[None, None] for i in range(2)]
    return depth, T.float(), K


class TestFrameWeight:
    def test_none_keeps_every_valid_pixel(self, street):
        (d0, _), _, K = street
        plain = prepare_frame(d0, K)
        assert plain.weight is None
        ones = prepare_frame(d0, K, weight=torch.ones(H, W))
        assert torch.equal(plain.valid, ones.valid) and ones.weight.shape == (H, W)

    def test_zero_weight_is_invalid_but_normals_unchanged(self, street):
        (d0, _), _, K = street
        weight = torch.ones(1, 1, H, W)
        weight[..., ::2, :] = 0
        plain, weighted = prepare_frame(d0, K), prepare_frame(d0, K, weight=weight)
        assert not weighted.valid[::2].any()
        assert torch.equal(weighted.valid[1::2], plain.valid[1::2])
        assert torch.equal(weighted.normal, plain.normal)

    @pytest.mark.parametrize("bad", [torch.ones(H, W + 1), torch.ones(2, H, W), torch.full((H, W), 1.5),
                                     torch.full((H, W), -0.1), torch.full((H, W), math.nan)],
                             ids=["width", "batch", "above-1", "negative", "nan"])
    def test_bad_weight(self, street, bad):
        (d0, _), _, K = street
        with pytest.raises(DcslamError, match="weight"):
            prepare_frame(d0, K, weight=bad)

    def test_dtype_follows_depth(self, street):
        (d0, _), _, K = street
        frame = prepare_frame(d0.double(), K, weight=torch.ones(H, W, dtype=torch.float32))
        assert frame.weight.dtype == torch.float64


def _corner(h: int = 10, w: int = 14):
    """Depth of a corner of three slanted planes seen by a small camera (every direction of motion constrained)."""
    K = torch.tensor([[12.0, 0, 6.5], [0, 12.0, 4.5], [0, 0, 1]], dtype=torch.float64)
    v, u = torch.meshgrid(torch.arange(h, dtype=torch.float64), torch.arange(w, dtype=torch.float64), indexing="ij")
    rays = torch.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], torch.ones_like(u)], -1)
    normals = torch.tensor([[0.6, 0.1, -1.0], [-0.7, 0.2, -1.0], [0.1, -0.8, -1.0]], dtype=torch.float64)
    return (3.0 / (rays @ (-normals).T)).min(-1).values[None, None], K, u, v


def test_pose_gradcheck_with_respect_to_weight_and_depth():
    """ICP with the differentiable LM: the aligned pose is a differentiable function of the per-pixel weights and of
    the depth (float64 gradcheck), and the weights do move it."""
    depth0, K, u, v = _corner()
    target = view_from_frame(prepare_frame(depth0, K), torch.eye(4, dtype=torch.float64))
    odometry = ICPOdometry(solver=DifferentiableLM(), iterations=3, min_inliers=10, min_conditioning=0,
                           coarse_to_fine=(1.0,))
    T_init = se3_exp(torch.tensor([0.01, -0.02, 0.01, 0.005, 0.0, -0.004], dtype=torch.float64))

    def pose(depth, weight):
        return odometry.estimate(prepare_frame(depth, K, weight=weight), target, T_init).T_world_cam

    depth = (depth0 * (1 + 0.003 * torch.sin(u + 2 * v))).requires_grad_()
    weight = (0.6 + 0.3 * torch.cos(0.7 * u - v)).requires_grad_()
    assert torch.autograd.gradcheck(pose, (depth, weight), eps=1e-7, atol=1e-5)
    g_weight = torch.autograd.grad(pose(depth, weight)[:3, 3].sum(), weight)[0]
    assert torch.isfinite(g_weight).all() and g_weight.abs().sum() > 0


def _corrupt(depth: torch.Tensor, fraction: float, seed: int = 0):
    """Push a random ``fraction`` of the measured pixels 0.25 m further away (a completer's confident-looking
    mistakes, all biased one way) -> (corrupted depth, mask of corrupted pixels)."""
    g = torch.Generator().manual_seed(seed)
    bad = (torch.rand(depth.shape, generator=g) < fraction) & (depth > 0)
    return torch.where(bad, depth + 0.25, depth), bad


def test_weights_that_distrust_outliers_beat_the_unweighted_solve(street):
    """Known motion: the second frame's depth has biased outliers on 30 % of its pixels. Unweighted ICP is pulled
    off by them; weighting them down (0.02) recovers the motion several times more accurately."""
    (d0, d1), T, K = street
    target = view_from_frame(prepare_frame(d0, K), T[0])
    noisy, bad = _corrupt(d1, 0.3)
    odometry = ICPOdometry()
    plain = odometry.estimate(prepare_frame(noisy, K), target, T[0])
    weight = torch.where(bad, torch.tensor(0.02), torch.tensor(1.0))
    weighted = odometry.estimate(prepare_frame(noisy, K, weight=weight), target, T[0])
    assert plain.accepted and weighted.accepted
    dt_plain, _ = pose_error(plain.T_world_cam.double(), T[1].double())
    dt_weighted, _ = pose_error(weighted.T_world_cam.double(), T[1].double())
    assert float(dt_plain) > 0.03                         # the outliers matter ...
    assert float(dt_weighted) < float(dt_plain) / 3       # ... and the weights take most of it away
    assert float(dt_weighted) < 0.025


def test_zero_weight_pairs_are_no_evidence(street):
    """Pixels of weight 0 are neither sources nor inliers: with most of the frame at weight 0 the step is rejected
    for too few points, as if those pixels had no depth."""
    (d0, d1), T, K = street
    target = view_from_frame(prepare_frame(d0, K), T[0])
    full = ICPOdometry().estimate(prepare_frame(d1, K), target, T[0])
    weight = torch.zeros(H, W)
    weight[30:33, 100:110] = 1.0
    sparse = ICPOdometry().estimate(prepare_frame(d1, K, weight=weight), target, T[0])
    frame = prepare_frame(d1, K, weight=weight)
    assert full.accepted and full.inliers > 1000
    assert not sparse.accepted and sparse.sources == int(frame.valid.sum()) <= 30
    source = torch.randn(50, 3) + torch.tensor([0.0, 0.0, 5.0])
    problem = PointToPlane(source, torch.nn.functional.normalize(torch.randn(50, 3), dim=1),
                           lambda p: (torch.arange(50), p.detach(), torch.tensor([[0.0, 0.0, 1.0]]).expand(50, 3)),
                           1.0, -1.0, weights=torch.cat([torch.zeros(20), torch.ones(30)]))
    assert problem.linearize(torch.eye(4)).count == 30
    with pytest.raises(DcslamError, match="weights"):
        PointToPlane(source, source, None, 1.0, -1.0, weights=torch.ones(49))


def test_source_voxels_keep_the_weights_of_the_kept_pixels(street):
    """With voxel subsampling of the source, the weights still follow their pixels: weighting down the outliers
    helps as much as without subsampling."""
    (d0, d1), T, K = street
    target = view_from_frame(prepare_frame(d0, K), T[0])
    noisy, bad = _corrupt(d1, 0.3, seed=1)
    odometry = ICPOdometry(source_voxel=0.1)
    plain = odometry.estimate(prepare_frame(noisy, K), target, T[0])
    weight = torch.where(bad, torch.tensor(0.02), torch.tensor(1.0))
    weighted = odometry.estimate(prepare_frame(noisy, K, weight=weight), target, T[0])
    dt_plain, _ = pose_error(plain.T_world_cam.double(), T[1].double())
    dt_weighted, _ = pose_error(weighted.T_world_cam.double(), T[1].double())
    assert float(dt_weighted) < float(dt_plain) / 3


class TestFusionWeights:
    def test_pointfusion_confidence_is_scaled_and_zero_weight_not_fused(self, street):
        (d0, _), T, K = street
        weight = torch.full((H, W), 0.5)
        weight[:, : W // 2] = 0
        frame = prepare_frame(d0, K, weight=weight)
        pm = PointFusion(voxel_size=0).integrate(frame, T[0])
        pixels = torch.nonzero(frame.valid.reshape(-1)).squeeze(1)
        assert len(pm) == len(pixels) and bool((pixels % W >= W // 2).all())
        expected = 0.5 * surfel_weights(frame, pixels, PointFusion().sigma)
        assert torch.allclose(torch.sort(pm.confidence).values, torch.sort(expected).values)

    def test_icpslam_average_is_weighted(self):
        """Two frames seeing a wall at 4 m and 5 m from the same pose, with weights 1 and 0.25: the fused wall lies
        at (4 + 0.25 * 5) / 1.25 = 4.2 m."""
        K = torch.tensor([[8.0, 0, 3.5], [0, 8.0, 3.5], [0, 0, 1]])
        mapper = ICPSLAM(voxel_size=100.0)
        near, far = torch.full((1, 1, 8, 8), 4.0), torch.full((1, 1, 8, 8), 5.0)
        mapper.integrate(prepare_frame(near, K, weight=torch.ones(8, 8)), torch.eye(4))
        pm = mapper.integrate(prepare_frame(far, K, weight=torch.full((8, 8), 0.25)), torch.eye(4))
        assert len(pm) > 0 and torch.allclose(pm.points[:, 2], torch.tensor(4.2), atol=1e-4)

    def test_build_map_gradient_reaches_weight(self):
        scene, K = StreetScene(2), kitti_K(32, 96)
        T = street_trajectory(2, step=0.5).float()
        depth = torch.stack([scene.render(T[i], K, 32, 96) for i in range(2)]).float()[:, None]
        weight = torch.full_like(depth, 0.7).requires_grad_()
        pm = build_map(depth * (1 + 0.01 * torch.rand_like(depth)), K, T, mapper=PointFusion(voxel_size=0.3,
                                                                                               keep_graph=True),
                       weight=weight)
        pm.points[:, 2].sum().backward()
        assert torch.isfinite(weight.grad).all() and weight.grad.abs().sum() > 0
        with pytest.raises(DcslamError, match="weight"):
            build_map(depth, K, T, weight=weight[:1])


def test_slam_run_takes_weights(street):
    (d0, d1), T, K = street
    depth = torch.cat([d0, d1])
    slam = SLAM(ICPOdometry(), PointFusion(voxel_size=0.2), T_world_cam0=T[0])
    poses = slam.run(depth, K, weight=torch.ones_like(depth))
    dt, _ = pose_error(poses[1].double(), T[1].double())
    assert float(dt) < 0.05
    with pytest.raises(DcslamError, match="weight"):
        slam.run(depth, K, weight=torch.ones(1, 1, H, W))
