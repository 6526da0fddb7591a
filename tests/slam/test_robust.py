import math

import pytest
import torch

from dcslam.errors import DcslamError
from dcslam.geometry.se3 import se3_exp
from dcslam.slam.association import view_from_frame
from dcslam.slam.frame import prepare_frame
from dcslam.slam.odometry import ICPOdometry
from dcslam.slam.robust import AdaptiveThreshold, GemanMcClure, Quadratic
from dcslam.slam.solvers import DifferentiableLM


class TestGemanMcClure:
    def test_weight_is_rho_derivative_over_r(self):
        r = torch.linspace(-2, 2, 41, dtype=torch.float64).requires_grad_()
        k = GemanMcClure(scale=0.25)
        (grad,) = torch.autograd.grad(k.rho(r, 1.0).sum(), r)
        nonzero = r.detach() != 0
        torch.testing.assert_close(grad[nonzero] / r.detach()[nonzero], k.weight(r.detach(), 1.0)[nonzero])

    def test_known_values(self):
        k = GemanMcClure(scale=1.0)
        assert float(k.weight(torch.tensor(0.0), 2.0)) == 1.0
        assert math.isclose(float(k.weight(torch.tensor(2.0), 2.0)), 0.25)
        assert float(k.rho(torch.tensor(1e6), 1.0)) < 0.5 + 1e-6     # bounded: outliers cannot dominate

    def test_gradcheck(self):
        r = torch.randn(7, dtype=torch.float64).requires_grad_()
        k = GemanMcClure()
        assert torch.autograd.gradcheck(lambda x: (k.rho(x, 0.9), k.weight(x, 0.9)), (r,))

    def test_bad_scale(self):
        with pytest.raises(DcslamError):
            GemanMcClure(scale=0)

    def test_quadratic(self):
        r = torch.tensor([1.0, -2.0])
        assert Quadratic().rho(r, 1.0).tolist() == [0.5, 2.0] and Quadratic().weight(r, 1.0).tolist() == [1, 1]


def test_pose_gradcheck_through_the_robust_kernel():
    """ICP with the Geman-McClure kernel and the differentiable LM: the pose is a differentiable function of depth."""
    h, w = 10, 14
    K = torch.tensor([[12.0, 0, 6.5], [0, 12.0, 4.5], [0, 0, 1]], dtype=torch.float64)
    v, u = torch.meshgrid(torch.arange(h, dtype=torch.float64), torch.arange(w, dtype=torch.float64), indexing="ij")
    rays = torch.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], torch.ones_like(u)], -1)
    normals = torch.tensor([[0.6, 0.1, -1.0], [-0.7, 0.2, -1.0], [0.1, -0.8, -1.0]], dtype=torch.float64)
    depth0 = (3.0 / (rays @ (-normals).T)).min(-1).values[None, None]
    target = view_from_frame(prepare_frame(depth0, K), torch.eye(4, dtype=torch.float64))
    odometry = ICPOdometry(solver=DifferentiableLM(), iterations=3, min_inliers=10, min_conditioning=0,
                           coarse_to_fine=(1.0,), kernel=GemanMcClure(scale=0.5), max_distance=0.3)
    T_init = se3_exp(torch.tensor([0.01, -0.02, 0.01, 0.005, 0.0, -0.004], dtype=torch.float64))

    def pose(depth):
        return odometry.estimate(prepare_frame(depth, K), target, T_init).T_world_cam

    depth = (depth0 * (1 + 0.001 * torch.sin(u + v))).requires_grad_()
    assert torch.autograd.gradcheck(pose, (depth,), eps=1e-7, atol=1e-5)


class TestAdaptiveThreshold:
    def test_initial_then_learned(self):
        a = AdaptiveThreshold(initial=2.0, min_motion=0.1)
        assert a.gate() == 6.0
        last = torch.eye(4, dtype=torch.float64)
        est = se3_exp(torch.tensor([0, 0, 1.0, 0, 0, 0], dtype=torch.float64))
        pred = se3_exp(torch.tensor([0, 0, 0.9, 0, 0, 0], dtype=torch.float64))
        a.update(pred, est, last)
        assert math.isclose(a.sigma(), 0.1, rel_tol=1e-6)
        a.update(est, est, last)                     # a perfect prediction lowers sigma
        assert math.isclose(a.sigma(), math.sqrt(0.01 / 2), rel_tol=1e-6)

    def test_standing_still_is_ignored_and_reset(self):
        a = AdaptiveThreshold(initial=1.0, min_motion=0.1)
        eye = torch.eye(4, dtype=torch.float64)
        a.update(eye, eye, eye)
        assert a.count == 0 and a.gate() == 3.0
        a.update(eye, se3_exp(torch.tensor([0, 0, 1.0, 0, 0, 0], dtype=torch.float64)), eye)
        a.reset()
        assert a.count == 0
