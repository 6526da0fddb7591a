"""Robust ICP in the spirit of KISS-ICP (Vizzo et al., RA-L 2023): a Geman-McClure kernel instead of hard residual
gates, and a correspondence threshold adapted from how far the constant-velocity prediction was off.

Both are smooth where the hard gates were not: a residual's weight falls continuously to ~0 as it grows, so the pose
stays a differentiable function of the depth (almost everywhere: the association gate, far out in the kernel's tail,
is the one remaining switch).
"""
from __future__ import annotations

import math

import torch

from dcslam.errors import DcslamError
from dcslam.geometry.motion import relative_motion


class GemanMcClure:
    """rho(r) = s^2 r^2 / (2 (s^2 + r^2)), weight w(r) = rho'(r) / r = s^4 / (s^2 + r^2)^2 (1 at r = 0, 1/4 at
    r = s): iteratively reweighted least squares with this weight minimises sum rho(r).

    The scale ``s`` is ``scale`` times the problem's correspondence gate (KISS-ICP: gate 3 sigma, kernel sigma / 3,
    i.e. ``scale = 1/9``).

    Shape: r (M,) -> (M,).
    """

    def __init__(self, scale: float = 1 / 9):
        if not scale > 0:
            raise DcslamError(f"kernel scale must be > 0, got {scale}")
        self.scale = scale

    def rho(self, r: torch.Tensor, gate: float) -> torch.Tensor:
        s2 = (self.scale * gate) ** 2
        r2 = r * r
        return s2 * r2 / (2 * (s2 + r2))

    def weight(self, r: torch.Tensor, gate: float) -> torch.Tensor:
        s2 = (self.scale * gate) ** 2
        return s2 * s2 / (s2 + r * r) ** 2


class Quadratic:
    """Plain least squares: rho(r) = r^2 / 2, weight 1 (hard gates only). Shape: r (M,) -> (M,)."""

    def rho(self, r: torch.Tensor, gate: float) -> torch.Tensor:
        return 0.5 * r * r

    def weight(self, r: torch.Tensor, gate: float) -> torch.Tensor:
        return torch.ones_like(r)


class AdaptiveThreshold:
    """KISS-ICP's correspondence threshold: 3 sigma, where sigma^2 is the mean squared *model error* (how far each
    estimate ended from its constant-velocity prediction, rotation converted to metres at ``max_range``) over the
    steps that moved more than ``min_motion`` metres; ``initial`` sigma until one such step is seen, and never below
    ``min_sigma``.

    Call :meth:`gate` before a step and :meth:`update` after it; :meth:`reset` at the start of a sequence.
    Shape: T_pred, T_est, T_last (4, 4).
    """

    def __init__(self, initial: float = 2.0, min_motion: float = 0.1, max_range: float = 80.0,
                 min_sigma: float = 0.05):
        self.initial, self.min_motion, self.max_range, self.min_sigma = initial, min_motion, max_range, min_sigma
        self.reset()

    def reset(self) -> None:
        self.sum_squares, self.count = 0.0, 0

    def sigma(self) -> float:
        if self.count == 0:
            return self.initial
        return max(math.sqrt(self.sum_squares / self.count), self.min_sigma)

    def gate(self) -> float:
        return 3.0 * self.sigma()

    def _metres(self, T_a: torch.Tensor, T_b: torch.Tensor) -> float:
        """The motion T_a^-1 T_b in metres: its translation plus the chord its rotation sweeps at ``max_range``."""
        metres, radians = relative_motion(T_a.detach(), T_b.detach())
        return float(metres) + 2 * self.max_range * math.sin(float(radians) / 2)

    def update(self, T_pred: torch.Tensor, T_est: torch.Tensor, T_last: torch.Tensor) -> None:
        """Record one accepted step: estimate ``T_est``, its prediction ``T_pred``, the previous pose ``T_last``."""
        if self._metres(T_last, T_est) < self.min_motion:
            return
        error = self._metres(T_pred, T_est)
        self.sum_squares += error * error
        self.count += 1
