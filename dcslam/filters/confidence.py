"""Confidence filter: keep the depth of pixels whose completer was at least ``min`` sure of it."""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from dcslam.errors import DcslamError
from dcslam.filters.base import check_depth


@dataclass(frozen=True)
class ConfidenceFilter:
    """Drop depth whose confidence (of a confidence-aware completer's layer, e.g. ``nconv``) is below ``min``."""

    min: float = 0.5
    name = "confidence"
    needs_confidence = True

    def __post_init__(self):
        if not 0 <= self.min <= 1:
            raise DcslamError(f"confidence filter needs 0 <= min <= 1, got min={self.min}")

    def apply(self, depth_m: np.ndarray, K: np.ndarray | None = None,
              confidence: np.ndarray | None = None) -> np.ndarray:
        """(H, W) depth and (H, W) confidence → (H, W) float32."""
        depth_m = check_depth(depth_m)
        if confidence is None:
            raise DcslamError("the confidence filter needs a layer with confidence (predicted by a "
                              "confidence-aware model such as nconv)")
        confidence = np.asarray(confidence)
        if confidence.shape != depth_m.shape:
            raise DcslamError(f"confidence has shape {confidence.shape}, expected {depth_m.shape} like its depth")
        return np.where(confidence >= self.min, depth_m, np.float32(0))

    def describe(self) -> dict:
        return {"filter": self.name, **asdict(self)}
