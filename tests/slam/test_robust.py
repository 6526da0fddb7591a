import importlib.util
import math
from pathlib import Path

import pytest
import torch

from dcslam.errors import DcslamError
from dcslam.geometry.se3 import se3_exp
from dcslam.slam.robust import AdaptiveThreshold, GemanMcClure, Quadratic


_spec = importlib.util.spec_from_file_location("slam_fixtures", Path(__file__).with_name("slam_fixtures.py"))
slam_fixtures = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(slam_fixtures)


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
    slam_fixtures.pose_gradcheck(kernel=GemanMcClure(scale=0.5), max_distance=0.3)


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
