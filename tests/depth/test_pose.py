"""The pose loss (dcslam.depth.pose): relative pose error, truncated solver, the loss through ICP and its gradient."""
import math

import pytest
import torch

from dcslam.depth.pose import PoseLoss, PoseLossSettings, TruncatedSolver, relative_pose_error
from dcslam.errors import DcslamError
from dcslam.geometry.se3 import se3_exp
from dcslam.slam.fusion import PointFusion
from dcslam.slam.odometry import ICPOdometry
from dcslam.slam.solvers import DifferentiableLM

H, W = 10, 14
K = torch.tensor([[12.0, 0, 6.5], [0, 12.0, 4.5], [0, 0, 1]], dtype=torch.float64)
# a corner of three slanted planes n . x = 3 (fully constrains a pose)
NORMALS = torch.tensor([[-0.6, -0.1, 1.0], [0.7, -0.2, 1.0], [-0.1, 0.8, 1.0]], dtype=torch.float64)


def plane_depth(T_world_cam: torch.Tensor) -> torch.Tensor:
    """(1, 1, H, W) depth of the corner seen from ``T_world_cam``."""
    v, u = torch.meshgrid(torch.arange(H, dtype=torch.float64), torch.arange(W, dtype=torch.float64), indexing="ij")
    rays = torch.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], torch.ones_like(u)], -1)
    R, t = T_world_cam[:3, :3], T_world_cam[:3, 3]
    z = (3.0 - NORMALS @ t) / ((rays @ R.T) @ NORMALS.T)
    return torch.where(z > 0, z, torch.full_like(z, math.inf)).min(-1).values[None, None]


def pair():
    T1 = se3_exp(torch.tensor([0.03, -0.02, 0.05, 0.01, -0.005, 0.008], dtype=torch.float64))
    T = torch.stack([torch.eye(4, dtype=torch.float64), T1])
    return torch.cat([plane_depth(T[0]), plane_depth(T[1])]), T


def small_loss(iterations: int = 4, grad_iterations: int = 0, **settings) -> PoseLoss:
    solver = TruncatedSolver(DifferentiableLM(tolerance=0.0), grad_iterations)
    odometry = ICPOdometry(solver=solver, iterations=iterations, min_inliers=10, min_conditioning=0,
                           coarse_to_fine=(1.0,))
    return PoseLoss(odometry, PointFusion(voxel_size=0.0, keep_graph=True), PoseLossSettings(**settings))


class TestRelativePoseError:
    def test_known_answer(self):
        T_gt = torch.stack([torch.eye(4), torch.eye(4)]).double()
        T_gt[1, 0, 3] = 1.0
        T_est = T_gt.clone()
        T_est[1] = T_gt[1] @ se3_exp(torch.tensor([0.0, 0.3, 0.4, 0.0, 0.0, 0.2], dtype=torch.float64))
        t, r = relative_pose_error(T_est, T_gt)
        assert t.shape == r.shape == (1,)
        assert float(r[0]) == pytest.approx(0.2, abs=1e-9)
        X = torch.linalg.solve(T_gt[1], T_est[1])
        assert float(t[0]) == pytest.approx(float(X[:3, 3].norm()), abs=1e-8)

    def test_zero_error_has_finite_gradient(self):
        T = se3_exp(torch.tensor([[0.1, 0, 0, 0, 0, 0], [0.5, 0.1, 0, 0.1, 0, 0]], dtype=torch.float64))
        T_est = T.clone().requires_grad_()
        t, r = relative_pose_error(T_est, T)
        (t + r).sum().backward()
        assert float(t.abs().max()) < 1e-8 and float(r.abs().max()) < 1e-8
        assert torch.isfinite(T_est.grad).all()

    def test_gradcheck(self):
        T_gt = se3_exp(torch.tensor([[0.0] * 6, [1.0, 0.1, 0.0, 0.0, 0.05, 0.0]], dtype=torch.float64))
        xi = torch.tensor([[0.01, 0.02, -0.01, 0.003, 0.0, 0.01], [0.9, 0.05, 0.1, 0.02, 0.04, -0.01]],
                          dtype=torch.float64, requires_grad=True)
        assert torch.autograd.gradcheck(lambda x: relative_pose_error(se3_exp(x), T_gt), (xi,))

    @pytest.mark.parametrize("shape", [(1, 4, 4), (2, 3, 4), (4, 4)])
    def test_bad_shapes(self, shape):
        with pytest.raises(DcslamError, match="expected"):
            relative_pose_error(torch.zeros(shape), torch.zeros(shape))


class TestTruncatedSolver:
    def test_same_pose_and_shorter_graph(self):
        depth, T = pair()
        full, truncated = small_loss(8, 0), small_loss(8, 2)
        noisy = depth * (1 + 0.01 * torch.rand_like(depth))
        T_full, _ = full.trajectory(noisy, K, T)
        T_trunc, _ = truncated.trajectory(noisy, K, T)
        assert torch.allclose(T_full[1], T_trunc[1], atol=1e-4)
        d = noisy.clone().requires_grad_()
        truncated.trajectory(d, K, T)[0][1, :3, 3].sum().backward()
        assert torch.isfinite(d.grad).all() and float(d.grad.abs().sum()) > 0

    def test_rejects_negative(self):
        with pytest.raises(DcslamError, match="grad_iterations"):
            TruncatedSolver(DifferentiableLM(), -1)


class TestPoseLoss:
    def test_exact_depth_recovers_the_motion(self):
        depth, T = pair()
        loss, details = small_loss(10)(depth, K, T)
        assert details["rejected"] == 0
        assert float(loss) < 0.005  # mm and mrad: normals at the creases of a 10 x 14 image are blurred
        assert details["T_est"].shape == (2, 4, 4)

    def test_wrong_depth_costs_more(self):
        depth, T = pair()
        exact, _ = small_loss(10)(depth, K, T)
        bent = depth.clone()
        bent[1, 0, :, : W // 2] *= 1.05    # half of the second frame 5 % too far
        worse, _ = small_loss(10)(bent, K, T)
        assert float(worse) > 10 * float(exact)

    def test_gradcheck_wrt_depth(self):
        depth, T = pair()
        v, u = torch.meshgrid(torch.arange(H, dtype=torch.float64), torch.arange(W, dtype=torch.float64),
                              indexing="ij")
        noisy = (depth * (1 + 0.01 * torch.sin(u + 2 * v))).requires_grad_()
        loss = small_loss(3, translation_weight=1.0, rotation_weight=2.0)
        assert torch.autograd.gradcheck(lambda d: loss(d, K, T)[0], (noisy,), eps=1e-7, atol=1e-5)
        grad = torch.autograd.grad(loss(noisy, K, T)[0], noisy)[0]
        assert float(grad[0].abs().sum()) > 0 and float(grad[1].abs().sum()) > 0  # map frame and source frame

    def test_gradcheck_wrt_weight(self):
        depth, T = pair()
        v, u = torch.meshgrid(torch.arange(H, dtype=torch.float64), torch.arange(W, dtype=torch.float64),
                              indexing="ij")
        noisy = depth * (1 + 0.01 * torch.sin(u + 2 * v))
        weight = (0.5 + 0.3 * torch.cos(u - v)).expand(2, 1, H, W).clone().requires_grad_()
        loss = small_loss(3)
        assert torch.autograd.gradcheck(lambda w: loss(noisy, K, T, w)[0], (weight,), eps=1e-7, atol=1e-5)
        zero_far = weight.detach().clone()
        zero_far[1, 0, :, W // 2:] = 0  # half of the source frame not trusted: a different pose
        assert float(loss(noisy, K, T, zero_far)[0]) != pytest.approx(float(loss(noisy, K, T, weight)[0]), abs=1e-6)

    def test_source_subsampling(self):
        depth, T = pair()
        loss = small_loss(10, max_sources=40)
        frame = loss._frame(depth[1:2], K, None)
        assert int(loss._sources(frame).valid.sum()) == 40
        value, details = loss(depth, K, T)
        assert details["rejected"] == 0 and float(value) < 0.02

    def test_shapes_checked(self):
        depth, T = pair()
        with pytest.raises(DcslamError, match=">= 2 frames"):
            small_loss()(depth[:1], K, T[:1])
        with pytest.raises(DcslamError, match="weight has shape"):
            small_loss()(depth, K, T, weight=torch.ones(2, 1, H, W + 1, dtype=torch.float64))

    @pytest.mark.parametrize("bad", [dict(translation_weight=-1.0), dict(rotation_weight=float("nan")),
                                     dict(max_sources=-3)])
    def test_bad_settings(self, bad):
        with pytest.raises(DcslamError):
            PoseLossSettings(**bad)
