"""IP-Basic (Ku, Harakeh, Waslander, "In Defense of Classical Image Processing: Fast Depth Completion on the CPU",
CRV 2018): the algorithm of the authors' ``ip_basic/depth_map_utils.py`` (github.com/kujason/ip_basic),
``fill_in_fast`` and ``fill_in_multiscale``, step for step, written anew.

Classical image processing on one depth map, no training. Depth is first *inverted* (``d' = max_depth − d`` where
``d > 0.1`` m) so that morphological dilation, a maximum filter, lets closer surfaces win over farther ones at
object edges. A pixel counts as empty while its inverted value is at most 0.1 (the authors' threshold). Then:

``fast``: 5×5 diamond dilation → 5×5 closing → empty pixels take a 7×7 dilation → *only with* ``extrapolate``: each
column's top value extended to the top of the image, then empty pixels take a 31×31 dilation → 5×5 median blur of
the whole image → bilateral blur (d 5, σ_colour 1.5, σ_space 2) of the whole image, or Gaussian 5×5 blur of the
non-empty pixels → inversion back to metres.

``multiscale``: the valid depths are split into near (≤ 15 m), medium (≤ 30 m) and far bins, each dilated with a cross
kernel sized for its range (7×7 near, 5×5 medium, 3×3 far: near surfaces span more pixels) and merged far to near
(near wins) over the inverted input → 5×5 closing → 5×5 median blur of the non-empty pixels → empty pixels below
each column's top value take a 9×9 dilation → with ``extrapolate`` the top values are extended to the top of the
image, without it the pixels above them stay empty for good → six rounds of 5×5 dilation into the remaining empty
pixels → 5×5 median blur, then Gaussian 5×5 or bilateral (d 5, σ_colour 0.5, σ_space 2) blur, of the non-empty
pixels → inversion.

Departures from the authors' code, none of which changes a KITTI result: inputs of at most 0.1 m are read as "no
depth" (the authors keep them as inverted values), depths beyond ``max_depth`` are clipped to it (the authors
invert them to negative values), and an output pixel whose inverted value is at most 0.1 (depth within 0.1 m of
``max_depth``, or an empty pixel that a blur touched with a vanishing weight) is 0, where the authors return the
inverted value itself as a depth.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dcslam.errors import DcslamError

VARIANTS = ("fast", "multiscale")
BLURS = ("gaussian", "bilateral", "none")
#: Inverted values at most this are empty (the authors' ``> 0.1`` tests in the inverted image).
EMPTY_AT_MOST = 0.1


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


def _check(depth_m: np.ndarray, blur: str) -> np.ndarray:
    depth_m = np.asarray(depth_m)
    if depth_m.ndim != 2:
        raise DcslamError(f"IP-Basic takes one (H, W) depth map, got shape {depth_m.shape}")
    if blur not in BLURS:
        raise DcslamError(f"unknown blur {blur!r}; expected one of {', '.join(BLURS)}")
    return depth_m.astype(np.float32, copy=False)


def _invert(depth_m: np.ndarray, max_depth: float) -> np.ndarray:
    """``max_depth − d`` where ``d > 0.1`` m, 0 elsewhere; a new float32 array."""
    inv = np.subtract(np.float32(max_depth), np.minimum(depth_m, np.float32(max_depth)), dtype=np.float32)
    inv[~(depth_m > EMPTY_AT_MOST)] = 0
    return inv


def _revert(inv: np.ndarray, max_depth: float) -> np.ndarray:
    """Inverted values back to metres; empty pixels (≤ 0.1) become 0."""
    depth = np.subtract(np.float32(max_depth), inv, dtype=np.float32)
    depth[~(inv > EMPTY_AT_MOST)] = 0
    return depth


def _fill(inv: np.ndarray, kernel: np.ndarray, where: np.ndarray | None = None) -> np.ndarray:
    """Empty pixels (and, with ``where``, only those where it is True) take the dilation of ``inv`` by ``kernel``;
    in place, returned."""
    import cv2

    empty = ~(inv > EMPTY_AT_MOST)
    if where is not None:
        empty &= where
    dilated = cv2.dilate(inv, kernel)
    np.copyto(inv, dilated, where=empty)
    return inv


def _top_rows(inv: np.ndarray) -> np.ndarray:
    """(W,) row of each column's topmost non-empty pixel (0 for a column without one, as ``np.argmax``)."""
    return np.argmax(inv > EMPTY_AT_MOST, axis=0)


def _below_top(inv: np.ndarray) -> np.ndarray:
    """(H, W) mask: False above each column's topmost non-empty pixel, True from it down."""
    return np.arange(inv.shape[0])[:, None] >= _top_rows(inv)[None, :]


def _extend_to_top(inv: np.ndarray) -> np.ndarray:
    """Pixels above each column's topmost non-empty pixel take its value; in place, returned."""
    top = _top_rows(inv)
    above = np.arange(inv.shape[0])[:, None] < top[None, :]
    np.copyto(inv, np.broadcast_to(inv[top, np.arange(inv.shape[1])][None, :], inv.shape), where=above)
    return inv


def complete_fast(depth_m: np.ndarray, max_depth: float = 100.0, extrapolate: bool = True,
                  blur: str = "bilateral") -> np.ndarray:
    """IP-Basic's fast variant (the authors' ``fill_in_fast``).

    Shape:
        depth_m: (H, W) metres, 0 = none → (H, W) float32 metres (0 where nothing was filled: with
        ``extrapolate=False``, typically above the highest LiDAR return)
    """
    import cv2

    inv = _invert(_check(depth_m, blur), max_depth)
    inv = cv2.dilate(inv, diamond_kernel(5))
    inv = cv2.morphologyEx(inv, cv2.MORPH_CLOSE, full_kernel(5))
    inv = _fill(inv, full_kernel(7))
    if extrapolate:
        inv = _fill(_extend_to_top(inv), full_kernel(31))
    inv = cv2.medianBlur(inv, 5)
    if blur == "bilateral":
        inv = cv2.bilateralFilter(inv, 5, 1.5, 2.0)
    elif blur == "gaussian":
        np.copyto(inv, cv2.GaussianBlur(inv, (5, 5), 0), where=inv > EMPTY_AT_MOST)
    return _revert(inv, max_depth)


def complete_multiscale(depth_m: np.ndarray, max_depth: float = 100.0, extrapolate: bool = True,
                        blur: str = "gaussian", bins_m: tuple[float, float] = (15.0, 30.0)) -> np.ndarray:
    """IP-Basic's multi-scale variant (the authors' ``fill_in_multiscale``).

    Shape:
        depth_m: (H, W) metres, 0 = none → (H, W) float32 metres (0 where nothing was filled: with
        ``extrapolate=False``, above the highest depth of each column)
    """
    import cv2

    depth_m = _check(depth_m, blur)
    inv = _invert(depth_m, max_depth)
    near = (depth_m > EMPTY_AT_MOST) & (depth_m <= bins_m[0])
    medium = (depth_m > bins_m[0]) & (depth_m <= bins_m[1])
    far = depth_m > bins_m[1]
    merged = inv.copy()
    for selected, kernel in ((far, cross_kernel(3)), (medium, cross_kernel(5)), (near, cross_kernel(7))):
        dilated = cv2.dilate(np.where(selected, inv, np.float32(0)), kernel)
        np.copyto(merged, dilated, where=dilated > EMPTY_AT_MOST)
    closed = cv2.morphologyEx(merged, cv2.MORPH_CLOSE, full_kernel(5))
    inv = closed.copy()
    np.copyto(inv, cv2.medianBlur(closed, 5), where=closed > EMPTY_AT_MOST)
    inv = _fill(inv, full_kernel(9), where=_below_top(inv))
    if extrapolate:
        inv = _extend_to_top(inv)
        keep = np.ones(inv.shape, bool)
    else:
        keep = _below_top(inv)
    for _ in range(6):
        inv = _fill(inv, full_kernel(5), where=keep)
    valid = (inv > EMPTY_AT_MOST) & keep
    np.copyto(inv, cv2.medianBlur(inv, 5), where=valid)
    if blur == "gaussian":
        np.copyto(inv, cv2.GaussianBlur(inv, (5, 5), 0), where=(inv > EMPTY_AT_MOST) & keep)
    elif blur == "bilateral":
        np.copyto(inv, cv2.bilateralFilter(inv, 5, 0.5, 2.0), where=valid)
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
