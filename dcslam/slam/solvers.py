"""Solvers for small least-squares pose problems: Gauss-Newton, Levenberg-Marquardt and a differentiable LM.

A problem (e.g. :class:`dcslam.slam.odometry.PointToPlane`) gives ``linearize(T) -> Linearization`` (normal
equations of a right-multiplied twist, ``T <- T exp(delta)``) and ``cost(T)``. A solver returns the refined pose.
The 6 x 6 systems are solved in float64 whatever the input dtype.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from dcslam.geometry.se3 import se3_exp


@dataclass
class Linearization:
    """Normal equations at a pose. Shape: H (6, 6) = J^T W J, g (6,) = J^T W r over inliers (W: robust weights,
    1 without a kernel), cost () the problem's objective there; count the inliers, weight their summed weights
    (None: all 1); H_step (6, 6) or None, see :attr:`step_matrix`."""

    H: torch.Tensor
    g: torch.Tensor
    cost: torch.Tensor
    count: int
    weight: float | None = None
    H_step: torch.Tensor | None = None

    @property
    def step_matrix(self) -> torch.Tensor:
        """The matrix the step is solved with: ``H_step`` (H with a prior on unobservable directions) or H."""
        return self.H if self.H_step is None else self.H_step


@dataclass
class SolveResult:
    """Shape: T (4, 4); last: the linearization at the last pose evaluated (for degeneracy checks)."""

    T: torch.Tensor
    iterations: int
    last: Linearization | None


def _retract(T: torch.Tensor, delta: torch.Tensor) -> torch.Tensor:
    return T @ se3_exp(delta.to(T.dtype))


def _solve(H: torch.Tensor, rhs: torch.Tensor) -> torch.Tensor:
    H = H.double()
    jitter = 1e-12 * torch.diagonal(H).sum().clamp_min(1e-30)
    return torch.linalg.solve(H + jitter * torch.eye(6, dtype=H.dtype, device=H.device), rhs.double())


class GaussNewton:
    """Undamped Gauss-Newton: ``delta = -H^-1 g``; stops when the step is below ``tolerance``."""

    def __init__(self, tolerance: float = 1e-5):
        self.tolerance = tolerance

    def solve(self, problem, T: torch.Tensor, iterations: int) -> SolveResult:
        lin = None
        for k in range(iterations):
            lin = problem.linearize(T)
            if lin.count < 6:
                return SolveResult(T, k, lin)
            delta = _solve(lin.step_matrix, -lin.g)
            step = float(delta.detach().abs().max())    # NaN or inf where delta is not finite: one test for both
            if not math.isfinite(step):
                return SolveResult(T, k, lin)
            T = _retract(T, delta)
            if step < self.tolerance:
                return SolveResult(T, k + 1, lin)
        return SolveResult(T, iterations, lin)


class LevenbergMarquardt:
    """Levenberg-Marquardt with Marquardt's diagonal scaling: a step is kept only if the cost drops; the damping
    is divided by ``decrease`` after a kept step and multiplied by ``increase`` after a rejected one."""

    def __init__(self, damping: float = 1e-4, increase: float = 10.0, decrease: float = 10.0,
                 min_damping: float = 1e-9, max_damping: float = 1e6, tolerance: float = 1e-5):
        self.damping, self.increase, self.decrease = damping, increase, decrease
        self.min_damping, self.max_damping, self.tolerance = min_damping, max_damping, tolerance

    def solve(self, problem, T: torch.Tensor, iterations: int) -> SolveResult:
        lam = self.damping
        lin = problem.linearize(T)
        for k in range(iterations):
            if lin.count < 6:
                return SolveResult(T, k, lin)
            H = lin.step_matrix.double()
            delta = _solve(H + lam * torch.diag(torch.diagonal(H)), -lin.g)
            if not bool(torch.isfinite(delta).all()):
                return SolveResult(T, k, lin)
            candidate = _retract(T, delta)
            new_cost, new_count = problem.cost(candidate)
            if new_count >= 6 and float(new_cost) < float(lin.cost):
                T, lam = candidate, max(lam / self.decrease, self.min_damping)
                if float(delta.abs().max()) < self.tolerance:
                    return SolveResult(T, k + 1, lin)
                lin = problem.linearize(T)
            else:
                lam = lam * self.increase
                if lam > self.max_damping:
                    return SolveResult(T, k + 1, lin)
        return SolveResult(T, iterations, lin)


class DifferentiableLM:
    """Levenberg-Marquardt whose accept / reject decision and damping update are smooth, in the spirit of gradSLAM's
    gradLM, so the estimated pose is a differentiable function of the inputs (through H, g and the costs).

    With r = (cost - new_cost) / cost, the step taken is ``s * delta`` with ``s = sigmoid(sharpness (r + margin))``
    (about 1 when the cost does not rise, about 0 when it rises by clearly more than ``margin``), and the damping
    is multiplied by ``factor ** (1 - 2 s)``: divided by ``factor`` after a kept step, multiplied after a rejected
    one, smoothly in between.
    """

    def __init__(self, damping: float = 1e-4, min_damping: float = 1e-6, max_damping: float = 1e2,
                 factor: float = 10.0, sharpness: float = 100.0, margin: float = 0.05, tolerance: float = 1e-5):
        self.damping, self.min_damping, self.max_damping, self.factor = damping, min_damping, max_damping, factor
        self.sharpness, self.margin, self.tolerance = sharpness, margin, tolerance

    def solve(self, problem, T: torch.Tensor, iterations: int) -> SolveResult:
        lam = torch.tensor(self.damping, dtype=torch.float64, device=T.device)
        lin = None
        for k in range(iterations):
            lin = problem.linearize(T)
            if lin.count < 6:
                return SolveResult(T, k, lin)
            H = lin.step_matrix.double()
            delta = _solve(H + lam * torch.diag(torch.diagonal(H)), -lin.g)
            if not bool(torch.isfinite(delta).all()):
                return SolveResult(T, k, lin)
            new_cost, new_count = problem.cost(_retract(T, delta))
            if new_count < 6:
                return SolveResult(T, k, lin)
            rel = (lin.cost.double() - new_cost.double()) / lin.cost.double().clamp_min(1e-30)
            accept = torch.sigmoid(self.sharpness * (rel + self.margin))
            T = _retract(T, accept * delta)
            lam = (lam * self.factor ** (1 - 2 * accept)).clamp(self.min_damping, self.max_damping)
            # Converged only when a kept step is tiny: a rejected step (accept ~ 0) is also tiny but must be
            # retried with more damping (stopping there left every pose at its initial guess).
            kept = float(accept.detach()) > 0.5
            if kept and float((accept * delta).detach().abs().max()) < self.tolerance:
                return SolveResult(T, k + 1, lin)
            if not kept and float(lam.detach()) >= self.max_damping:
                return SolveResult(T, k + 1, lin)
        return SolveResult(T, iterations, lin)
