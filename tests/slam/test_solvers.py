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


class _TwoTargets:
    """A translation problem whose pairs switch with the pose: left of x = 0 they pull the pose to +a, right of it
    to -a (two sets of pairs, each pulling to the other's side): Gauss-Newton goes to and fro."""

    def __init__(self, a: float):
        self.a, self.calls = a, 0

    def linearize(self, T):
        self.calls += 1
        target = torch.tensor([self.a if float(T[0, 3]) < 0 else -self.a, 0.0, 0.0], dtype=torch.float64)
        r = T[:3, 3].double() - target
        J = torch.zeros(3, 6, dtype=torch.float64)
        J[:, :3] = torch.eye(3, dtype=torch.float64)
        return Linearization(J.T @ J + 1e-6 * torch.eye(6, dtype=torch.float64), J.T @ r, (r * r).sum(), 100)


def test_gauss_newton_stops_when_a_step_undoes_the_last_half_way_between():
    """From x = -0.1 the first step goes to +0.3, the second to -0.3, the third would go back to +0.3, undoing the
    second: the solve ends at 0 (half-way) after 3 linearisations; with the rule off (bounce 0) it takes all 20."""
    problem = _TwoTargets(0.3)
    T0 = torch.eye(4, dtype=torch.float64)
    T0[0, 3] = -0.1
    result = GaussNewton().solve(problem, T0, 20)
    assert result.iterations == 3 and problem.calls == 3
    assert abs(float(result.T[0, 3])) < 1e-5 and torch.allclose(result.T[:3, :3], T0[:3, :3])
    off = _TwoTargets(0.3)
    assert GaussNewton(bounce=0.0).solve(off, T0, 20).iterations == 20 and off.calls == 20


def test_gauss_newton_converging_steps_are_not_bounces():
    """Steps that shrink (a problem that converges) never end the solve early: the target is reached."""
    target = torch.tensor([0.3, -0.2, 1.1], dtype=torch.float64)
    problem = _Quadratic(target)
    result = GaussNewton().solve(problem, torch.eye(4, dtype=torch.float64), 20)
    assert torch.allclose(result.T[:3, 3], target, atol=1e-9)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_one_pose_update_matches_the_tensor_formulas(dtype):
    """A solver's pose update T exp(delta) outside autograd (float64 arithmetic, rounded once) against T @ se3_exp
    in float64, over steps from 1e-7 (the Taylor branch) to about 1: within 1e-14 of the float64 product in float64,
    and in float32 within 2^-20 (an ulp of entries of 8 to 16, the largest the random poses reach)."""
    from dcslam.slam.solvers import _retract

    g = torch.Generator().manual_seed(5)
    for k in range(300):
        scale = 10.0 ** (-7 + 7 * k / 300)
        delta = torch.randn(6, generator=g, dtype=torch.float64) * scale
        T = se3_exp(torch.randn(6, generator=g, dtype=torch.float64) * 3).to(dtype)
        ours = _retract(T, delta)
        theirs = T.double() @ se3_exp(delta)
        assert ours.dtype == dtype and ours.shape == (4, 4)
        if dtype == torch.float64:
            assert torch.allclose(ours, theirs, rtol=0, atol=1e-14)
        else:
            assert torch.allclose(ours.double(), theirs, rtol=0, atol=2.0 ** -20)
        assert torch.equal(ours[3], torch.tensor([0, 0, 0, 1], dtype=dtype))


def test_pose_update_with_a_gradient_stays_on_the_tensor_path():
    from dcslam.slam.solvers import _retract

    delta = torch.tensor([0.1, 0.0, 0.0, 0.0, 0.2, 0.0], dtype=torch.float64, requires_grad=True)
    out = _retract(torch.eye(4, dtype=torch.float64), delta)
    out[0, 3].backward()
    assert delta.grad is not None and float(delta.grad.abs().sum()) > 0
