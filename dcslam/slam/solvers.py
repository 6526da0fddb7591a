"""Solvers for small least-squares pose problems: Gauss-Newton, Levenberg-Marquardt and a differentiable LM.

A problem (e.g. :class:`dcslam.slam.odometry.PointToPlane`) gives ``linearize(T) -> Linearization`` (normal
equations of a right-multiplied twist, ``T <- T exp(delta)``) and ``cost(T)``. A solver returns the refined pose.
The 6 x 6 systems are solved in float64 whatever the input dtype.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from dcslam.geometry.se3 import _SMALL, se3_exp


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
    """``T exp(delta)``. One CPU pose outside autograd (every step of a SLAM run): in float64 Python arithmetic,
    rounded once to T's dtype, as a dozen tensor calls of one element each cost 20 times the sums."""
    if (T.shape == (4, 4) and delta.shape == (6,) and T.device.type == "cpu" and delta.device.type == "cpu"
            and not (torch.is_grad_enabled() and (T.requires_grad or delta.requires_grad))):
        return torch.tensor(_times_exp(T.tolist(), delta.tolist()), dtype=T.dtype)
    return T @ se3_exp(delta.to(T.dtype))


def _times_exp(T: list, xi: list) -> list:
    """T (4 x 4 rows) times se3_exp(xi) (:func:`dcslam.geometry.se3.se3_exp`'s formulas, its Taylor series below
    the same angle), in float64: 4 x 4 rows."""
    v0, v1, v2, x, y, z = xi
    theta2 = x * x + y * y + z * z
    if theta2 < _SMALL:
        A = 1 - theta2 / 6 + theta2 ** 2 / 120
        B = 0.5 - theta2 / 24 + theta2 ** 2 / 720
        C = 1.0 / 6 - theta2 / 120 + theta2 ** 2 / 5040
    else:
        t = math.sqrt(theta2)
        sin = math.sin(t)
        A, B, C = sin / t, (1 - math.cos(t)) / theta2, (t - sin) / (theta2 * t)
    W = ((0.0, -z, y), (z, 0.0, -x), (-y, x, 0.0))
    w = (x, y, z)
    WW = [[w[i] * w[j] - (theta2 if i == j else 0.0) for j in range(3)] for i in range(3)]   # w w^T - |w|^2 I
    R = [[(i == j) + A * W[i][j] + B * WW[i][j] for j in range(3)] for i in range(3)]
    V = [[(i == j) + B * W[i][j] + C * WW[i][j] for j in range(3)] for i in range(3)]
    tr = [V[i][0] * v0 + V[i][1] * v1 + V[i][2] * v2 for i in range(3)]
    out = []
    for row in T:
        a, b, c, d = row
        out.append([a * R[0][j] + b * R[1][j] + c * R[2][j] for j in range(3)]
                   + [a * tr[0] + b * tr[1] + c * tr[2] + d])
    return out


def _solve(H: torch.Tensor, rhs: torch.Tensor) -> torch.Tensor:
    H = H.double()
    jitter = 1e-12 * torch.diagonal(H).sum().clamp_min(1e-30)
    return torch.linalg.solve(H + jitter * torch.eye(6, dtype=H.dtype, device=H.device), rhs.double())


class GaussNewton:
    """Undamped Gauss-Newton: ``delta = -H^-1 g``; stops when the step is below ``tolerance``, or when a step undoes
    the one before it (their sum under ``bounce`` times the step: two sets of pairs, each pulling the pose to the
    other's, so the iterations would go to and fro until the last; the solve ends half-way between the two poses).
    """

    def __init__(self, tolerance: float = 1e-5, bounce: float = 0.1):
        self.tolerance, self.bounce = tolerance, bounce

    def solve(self, problem, T: torch.Tensor, iterations: int) -> SolveResult:
        lin = previous = None
        for k in range(iterations):
            lin = problem.linearize(T)
            if lin.count < 6:
                return SolveResult(T, k, lin)
            delta = _solve(lin.step_matrix, -lin.g)
            step = float(delta.detach().abs().max())    # NaN or inf where delta is not finite: one test for both
            if not math.isfinite(step):
                return SolveResult(T, k, lin)
            if previous is not None and float((delta.detach() + previous).abs().max()) < self.bounce * step:
                return SolveResult(_retract(T, delta / 2), k + 1, lin)
            T, previous = _retract(T, delta), delta.detach()
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
