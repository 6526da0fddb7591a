import math

import pytest
import torch

from dcslam.geometry.se3 import se3_exp
from dcslam.slam.solvers import DifferentiableLM, GaussNewton, LevenbergMarquardt, Linearization


class _Quadratic:
    """cost(T) = |log-free translation of T - target|^2 on the translation only, with a cost that punishes the first
    full step (as a re-association can) so a solver must retry with more damping."""

    def __init__(self, target, punish_first=False):
        self.target, self.punish_first, self.calls = target, punish_first, 0

    def _r(self, T):
        return T[:3, 3] - self.target

    def linearize(self, T):
        r = self._r(T).double()
        J = torch.zeros(3, 6, dtype=torch.float64, device=T.device)
        J[:, :3] = T[:3, :3].double()
        return Linearization(J.T @ J + 1e-6 * torch.eye(6, dtype=torch.float64, device=T.device), J.T @ r,
                             (r * r).sum(), 100)

    def cost(self, T):
        self.calls += 1
        r = self._r(T).double()
        c = (r * r).sum()
        if self.punish_first and self.calls == 1:
            c = c + 10.0
        return c, 100


@pytest.mark.parametrize("solver", [GaussNewton(), LevenbergMarquardt(), DifferentiableLM()], ids=["gn", "lm", "dlm"])
def test_solvers_reach_a_known_translation(solver):
    target = torch.tensor([0.3, -0.2, 1.1], dtype=torch.float64)
    result = solver.solve(_Quadratic(target), torch.eye(4, dtype=torch.float64), 20)
    assert torch.allclose(result.T[:3, 3], target, atol=1e-4)


@pytest.mark.parametrize("solver", [GaussNewton(), LevenbergMarquardt(), DifferentiableLM()], ids=["gn", "lm", "dlm"])
@pytest.mark.parametrize("punish_first", [False, True], ids=["plain", "first-step-rejected"])
def test_solvers_in_each_dtype_and_on_each_device(solver, punish_first, device, dtype):
    """The pose keeps the dtype and device it starts in (the 6 x 6 systems are solved in float64 there) and reaches
    the target in float32 as in float64, also when the first step must be retried."""
    target = torch.tensor([0.3, -0.2, 1.1], dtype=dtype, device=device)
    T0 = se3_exp(torch.tensor([0.0, 0.0, 0.0, 0.02, -0.01, 0.03], dtype=dtype, device=device))
    result = solver.solve(_Quadratic(target, punish_first), T0, 20)
    assert result.T.dtype == dtype and result.T.device.type == device.type
    assert result.last.H.dtype == torch.float64 and result.last.H.device.type == device.type
    tolerance = 1e-4 if dtype == torch.float64 else 1e-3
    assert torch.allclose(result.T[:3, 3], target, atol=tolerance)
    assert torch.allclose(result.T[:3, :3], T0[:3, :3], atol=tolerance)  # the problem leaves the rotation alone


def test_differentiable_lm_retries_after_a_rejected_step():
    target = torch.tensor([0.0, 0.0, 1.2], dtype=torch.float64)
    problem = _Quadratic(target, punish_first=True)
    result = DifferentiableLM().solve(problem, torch.eye(4, dtype=torch.float64), 20)
    assert problem.calls > 1
    assert math.isclose(float(result.T[2, 3]), 1.2, abs_tol=1e-3)


def test_differentiable_lm_step_is_differentiable():
    target = torch.tensor([0.1, 0.2, 0.3], dtype=torch.float64, requires_grad=True)

    def solve(t):
        return DifferentiableLM().solve(_Quadratic(t), se3_exp(torch.zeros(6, dtype=torch.float64)), 5).T[:3, 3]

    assert torch.autograd.gradcheck(solve, (target,), eps=1e-6, atol=1e-5)
