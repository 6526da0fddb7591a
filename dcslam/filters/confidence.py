"""Confidence filter: keep the depth of pixels whose completer was at least ``min`` sure of it, and/or only the most
confident fraction ``keep`` of each frame's pixels (a threshold that follows whatever scale a model's confidence has:
a briefly trained nconv is rarely above 0.5 anywhere)."""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from dcslam.errors import DcslamError
from dcslam.filters.base import check_depth


@dataclass(frozen=True)
class ConfidenceFilter:
    """Drop depth whose confidence (of a confidence-aware completer's layer, e.g. ``nconv``) is below ``min``, and
    keep at most the fraction ``keep`` of the frame's pixels with depth: those of the highest confidence (ties at the
    cut are kept)."""

    min: float = 0.5
    keep: float = 1.0
    name = "confidence"
    needs_confidence = True

    def __post_init__(self):
        if not 0 <= self.min <= 1:
            raise DcslamError(f"confidence filter needs 0 <= min <= 1, got min={self.min}")
        if not 0 < self.keep <= 1:
            raise DcslamError(f"confidence filter needs 0 < keep <= 1, got keep={self.keep}")

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
        ok = confidence >= self.min
        has = depth_m > 0
        if self.keep < 1 and has.any():
            cut = np.quantile(confidence[has], 1 - self.keep)
            ok &= confidence >= cut
        return np.where(ok, depth_m, np.float32(0))

    def describe(self) -> dict:
        return {"filter": self.name, **asdict(self)}
