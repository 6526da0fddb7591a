"""Bilateral filter on depth (as cv2.bilateralFilter, optionally ignoring holes)."""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from dcslam.errors import DcslamError
from dcslam.filters.base import check_depth


@dataclass(frozen=True)
class BilateralFilter:
    """Edge-preserving smoothing of depth, with OpenCV's bilateral kernel.

    Weights, as ``cv2.bilateralFilter`` defines them: over a disc of radius ``d // 2`` pixels,
    ``w = exp(-r² / (2 sigma_space²)) · exp(-(Δdepth)² / (2 sigma_color²))`` with Δdepth in metres, image borders
    reflected (OpenCV's ``BORDER_REFLECT_101``).

    Holes (depth 0): with ``ignore_holes=True`` (the default) a pixel without depth stays without depth, and holes
    take no part in the weighted mean of their neighbours, so no depth is smeared into holes and no valid depth is
    pulled towards 0. On an image without holes this equals ``cv2.bilateralFilter`` (up to OpenCV's lookup-table
    approximation of the colour weight). With ``ignore_holes=False`` it *is* ``cv2.bilateralFilter`` on the float32
    image, as the thesis called it: zeros count as depth 0 m, so holes get filled with a mixture of their
    neighbours and edges next to holes are pulled towards 0 (with sigma_color = 80 m the colour term barely
    discriminates). Pixels outside the image are never "holes".
    """

    d: int = 5
    sigma_color: float = 80.0
    sigma_space: float = 80.0
    ignore_holes: bool = True
    name = "bilateral"

    def __post_init__(self):
        if self.d < 1 or self.sigma_color <= 0 or self.sigma_space <= 0:
            raise DcslamError(f"bilateral filter needs d >= 1 and positive sigmas, got d={self.d}, "
                              f"sigma_color={self.sigma_color}, sigma_space={self.sigma_space}")

    def apply(self, depth_m: np.ndarray, K: np.ndarray | None = None) -> np.ndarray:
        """(H, W) → (H, W) float32."""
        depth_m = check_depth(depth_m)
        if not self.ignore_holes:
            import cv2

            return cv2.bilateralFilter(depth_m, self.d, self.sigma_color, self.sigma_space)
        radius = self.d // 2
        height, width = depth_m.shape
        if radius == 0 or min(height, width) <= radius:
            return depth_m.copy()
        padded = np.pad(depth_m.astype(np.float64), radius, mode="reflect")  # = BORDER_REFLECT_101
        centre = depth_m.astype(np.float64)
        total = np.zeros_like(centre)
        weight_sum = np.zeros_like(centre)
        for dy in range(-radius, radius + 1):
            for dx in range(-radius, radius + 1):
                r2 = dx * dx + dy * dy
                if r2 > radius * radius:
                    continue
                shifted = padded[radius + dy:radius + dy + height, radius + dx:radius + dx + width]
                w = np.exp(-r2 / (2 * self.sigma_space ** 2)) * np.exp(-(shifted - centre) ** 2 /
                                                                       (2 * self.sigma_color ** 2))
                w = w * (shifted > 0)
                total += w * shifted
                weight_sum += w
        valid = centre > 0  # the centre's own weight is 1, so weight_sum > 0 wherever the centre is valid
        out = np.zeros_like(centre)
        np.divide(total, weight_sum, out=out, where=valid)
        return out.astype(np.float32)

    def describe(self) -> dict:
        return {"filter": self.name, **asdict(self)}
