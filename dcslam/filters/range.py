"""Range filter: keep depth within [min, max] metres."""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from dcslam.errors import DcslamError
from dcslam.filters.base import check_depth


@dataclass(frozen=True)
class RangeFilter:
    """Drop depth nearer than ``min_m`` or farther than ``max_m`` (both bounds kept)."""

    min_m: float = 0.0
    max_m: float = float("inf")
    name = "range"

    def __post_init__(self):
        if not (0 <= self.min_m < self.max_m):
            raise DcslamError(f"range filter needs 0 <= min < max, got min={self.min_m}, max={self.max_m}")

    def apply(self, depth_m: np.ndarray, K: np.ndarray | None = None) -> np.ndarray:
        """(H, W) → (H, W) float32."""
        depth_m = check_depth(depth_m)
        return np.where((depth_m >= self.min_m) & (depth_m <= self.max_m), depth_m, np.float32(0))

    def describe(self) -> dict:
        return {"filter": self.name, **asdict(self)}
