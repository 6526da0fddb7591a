"""Removal of pixels at depth discontinuities."""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from dcslam.errors import DcslamError
from dcslam.filters.base import check_depth


@dataclass(frozen=True)
class DiscontinuityFilter:
    """Drop pixels at depth discontinuities: a valid pixel goes when any valid 8-neighbour differs from it by more
    than ``max_jump_m`` metres, or by more than ``max_relative_jump`` × the nearer of the two depths. Both sides of
    an edge are dropped (mixed "flying" pixels sit on either side)."""

    max_jump_m: float | None = None
    max_relative_jump: float | None = 0.1
    name = "edges"

    def __post_init__(self):
        if self.max_jump_m is None and self.max_relative_jump is None:
            raise DcslamError("discontinuity filter needs max_jump_m or max_relative_jump")
        if any(v is not None and v <= 0 for v in (self.max_jump_m, self.max_relative_jump)):
            raise DcslamError("discontinuity filter thresholds must be positive")

    def apply(self, depth_m: np.ndarray, K: np.ndarray | None = None) -> np.ndarray:
        """(H, W) → (H, W) float32."""
        depth_m = check_depth(depth_m)
        height, width = depth_m.shape
        padded = np.pad(depth_m, 1, mode="constant")  # outside the image counts as "no value"
        edge = np.zeros(depth_m.shape, bool)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                if dx == 0 and dy == 0:
                    continue
                other = padded[1 + dy:1 + dy + height, 1 + dx:1 + dx + width]
                both = (depth_m > 0) & (other > 0)
                jump = np.abs(depth_m - other)
                too_far = np.zeros_like(both)
                if self.max_jump_m is not None:
                    too_far |= jump > self.max_jump_m
                if self.max_relative_jump is not None:
                    too_far |= jump > self.max_relative_jump * np.minimum(depth_m, other)
                edge |= both & too_far
        return np.where(edge, np.float32(0), depth_m)

    def describe(self) -> dict:
        return {"filter": self.name, **asdict(self)}
