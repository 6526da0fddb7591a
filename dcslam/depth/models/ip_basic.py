"""IP-Basic (Ku, Harakeh, Waslander, "In Defense of Classical Image Processing: Fast Depth Completion on the CPU",
CRV 2018), written from the paper's description.

Classical image processing on one depth map, no training. Depth is first *inverted* (``d' = max_depth − d`` on
valid pixels, 0 elsewhere) so that morphological dilation, a maximum filter, lets closer surfaces win over farther
ones at object edges. Then:

``fast``: diamond-kernel dilation → full-kernel closing of small holes → fill of empty pixels by a 7×7 dilation →
extension of each column's top value to the top of the image → fill of large holes by a 31×31 dilation → 5×5 median
blur (outliers) → Gaussian or bilateral blur (smoothing) → inversion back to metres.

``multiscale``: the valid depths are split into near / medium / far bins, each dilated separately with a kernel
sized for its range (near surfaces span more pixels), merged with near taking priority, then closing, median blur,
top extension and hole filling with growing kernels (7, 15, 31), blur and inversion.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dcslam.errors import DcslamError

VARIANTS = ("fast", "multiscale")


def full_kernel(size: int) -> np.ndarray:
    """(size, size) uint8 all-ones kernel."""
    return np.ones((size, size), np.uint8)


def cross_kernel(size: int) -> np.ndarray:
    """(size, size) uint8 cross: the middle row and column."""
    kernel = np.zeros((size, size), np.uint8)
    kernel[size // 2, :] = 1
    kernel[:, size // 2] = 1
    return kernel


def diamond_kernel(size: int) -> np.ndarray:
    """(size, size) uint8 diamond: pixels within L1 distance size // 2 of the centre."""
    r = size // 2
    yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
    return (np.abs(yy) + np.abs(xx) <= r).astype(np.uint8)


def _fill_empty(inv: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """Empty pixels (0) take the maximum (closest) inverted depth within ``kernel``; valid pixels are kept."""
    import cv2

    dilated = cv2.dilate(inv, kernel)
    np.copyto(dilated, inv, where=inv > 0)
    return dilated


def _extend_to_top(inv: np.ndarray) -> np.ndarray:
    """Pixels above each column's topmost valid pixel take that pixel's value (columns with none stay empty)."""
    top = np.argmax(inv > 0, axis=0)  # 0 for a column with no valid pixel: nothing above it changes
    out = inv.copy()
    reach = int(top.max()) if top.size else 0
    if reach:
        top_value = inv[top, np.arange(inv.shape[1])]
        np.copyto(out[:reach], top_value[None, :], where=np.arange(reach)[:, None] < top[None, :])
    return out


def _blur_valid(inv: np.ndarray, blur: str) -> np.ndarray:
    import cv2

    if blur not in ("gaussian", "bilateral", "none"):
        raise DcslamError(f"unknown blur {blur!r}; expected gaussian, bilateral or none")
    # Smoothed values on valid pixels only, the others kept: OpenCV's masked copy into the filter's output (the same
    # values as np.where, without its full-frame temporaries; a uint8 mask is what cv2 copies fastest with).
    inv = np.ascontiguousarray(inv, dtype=np.float32)
    invalid = cv2.bitwise_not(cv2.compare(inv, 0, cv2.CMP_GT))
    smoothed = cv2.copyTo(inv, invalid, cv2.medianBlur(inv, 5))
    if blur == "none":
        return smoothed
    inv = smoothed
    smoothed = cv2.GaussianBlur(inv, (5, 5), 0) if blur == "gaussian" else cv2.bilateralFilter(inv, 5, 1.5, 2.0)
    return cv2.copyTo(inv, invalid, smoothed)


def _check(depth_m: np.ndarray) -> np.ndarray:
    depth_m = np.asarray(depth_m)
    if depth_m.ndim != 2:
        raise DcslamError(f"IP-Basic takes one (H, W) depth map, got shape {depth_m.shape}")
    return depth_m.astype(np.float32, copy=False)


def _invert(depth_m: np.ndarray, max_depth: float) -> np.ndarray:
    # float32 throughout, in place: (max_depth - min(d, max_depth)) + 1e-3 on valid pixels, 0 elsewhere.
    inv = np.minimum(depth_m, np.float32(max_depth))
    np.subtract(np.float32(max_depth), inv, out=inv)
    inv += np.float32(1e-3)
    inv[~(depth_m > 0)] = 0
    return inv


def _revert(inv: np.ndarray, max_depth: float) -> np.ndarray:
    depth = np.subtract(np.float32(max_depth + 1e-3), inv, dtype=np.float32)
    depth[~(inv > 0)] = 0
    np.maximum(depth, 0, out=depth)
    return depth


def complete_fast(depth_m: np.ndarray, max_depth: float = 100.0, extrapolate: bool = True,
                  blur: str = "bilateral") -> np.ndarray:
    """IP-Basic's fast variant.

    Shape:
        depth_m: (H, W) metres, 0 = none → (H, W) float32 metres (0 only where nothing could be filled)
    """
    import cv2

    inv = _invert(_check(depth_m), max_depth)
    inv = cv2.dilate(inv, diamond_kernel(5))
    inv = cv2.morphologyEx(inv, cv2.MORPH_CLOSE, full_kernel(5))
    inv = _fill_empty(inv, full_kernel(7))
    if extrapolate:
        inv = _extend_to_top(inv)
    inv = _fill_empty(inv, full_kernel(31))
    inv = _blur_valid(inv, blur)
    return _revert(inv, max_depth)


def complete_multiscale(depth_m: np.ndarray, max_depth: float = 100.0, extrapolate: bool = True,
                        blur: str = "gaussian", bins_m: tuple[float, float] = (15.0, 30.0)) -> np.ndarray:
    """IP-Basic's multi-scale variant.

    Shape:
        depth_m: (H, W) metres, 0 = none → (H, W) float32 metres
    """
    import cv2

    depth_m = _check(depth_m)
    inv = _invert(depth_m, max_depth)
    near = (depth_m > 0) & (depth_m <= bins_m[0])
    medium = (depth_m > bins_m[0]) & (depth_m <= bins_m[1])
    far = depth_m > bins_m[1]
    dilated = {}
    for name, selected, kernel in (("far", far, diamond_kernel(5)), ("medium", medium, diamond_kernel(7)),
                                   ("near", near, diamond_kernel(9))):
        dilated[name] = cv2.dilate(np.where(selected, inv, np.float32(0)), kernel)
    merged = dilated["far"]
    np.copyto(merged, dilated["medium"], where=dilated["medium"] > 0)
    np.copyto(merged, dilated["near"], where=dilated["near"] > 0)
    inv = cv2.morphologyEx(merged, cv2.MORPH_CLOSE, full_kernel(5))
    smoothed = cv2.medianBlur(inv, 5)
    np.copyto(smoothed, inv, where=~(inv > 0))
    inv = smoothed
    if extrapolate:
        inv = _extend_to_top(inv)
    for size in (7, 15, 31):
        inv = _fill_empty(inv, full_kernel(size))
    inv = _blur_valid(inv, blur)
    return _revert(inv, max_depth)


@dataclass(frozen=True)
class IPBasic:
    """IP-Basic as a depth completer: ``IPBasic("fast")(sparse)`` → dense, both (H, W) float32 metres."""

    variant: str = "fast"
    max_depth: float = 100.0
    extrapolate: bool = True
    blur: str | None = None

    def __post_init__(self):
        if self.variant not in VARIANTS:
            raise DcslamError(f"unknown IP-Basic variant {self.variant!r}; expected one of {', '.join(VARIANTS)}")

    @property
    def name(self) -> str:
        return f"ip-basic-{self.variant}"

    def __call__(self, sparse_m: np.ndarray) -> np.ndarray:
        if self.variant == "fast":
            return complete_fast(sparse_m, self.max_depth, self.extrapolate, self.blur or "bilateral")
        return complete_multiscale(sparse_m, self.max_depth, self.extrapolate, self.blur or "gaussian")


def fast() -> IPBasic:
    """The ``ip-basic-fast`` completer of the registry (:data:`dcslam.depth.models.CLASSICAL`)."""
    return IPBasic("fast")


def multiscale() -> IPBasic:
    """The ``ip-basic-multiscale`` completer of the registry (:data:`dcslam.depth.models.CLASSICAL`)."""
    return IPBasic("multiscale")
