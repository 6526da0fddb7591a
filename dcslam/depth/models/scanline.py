"""Scanline completion: per image column, inverse depth interpolated linearly between vertically consecutive LiDAR
returns that lie on one surface; nothing bridged across a depth discontinuity, the rest left empty.

Why inverse depth: a plane ``n . X = c`` seen through a pinhole has ``1 / z = n . K^-1 (u, v, 1) / c``, an affine
function of the pixel coordinates, so along a column (``u`` fixed) it is linear in the row ``v``. Interpolating
``1 / z`` linearly between two returns of one plane reproduces the plane exactly; interpolating ``z`` does not (it
bows the surface, and the normals SLAM computes from it tilt).

The returns of a sparse depth image are its pixels deeper than :data:`dcslam.constants.MIN_DEPTH_M`. Two returns of
a column are *vertically consecutive* when no return lies between them. The empty pixels between them are filled
when both

- the returns are at most ``max_gap_px`` rows apart (a longer gap in a column is a region the LiDAR saw nothing in:
  sky, glass, a surface out of range), and
- their relative depth step ``|z1 - z0| / min(z0, z1)`` is below ``max_relative_step``: the two lie on one surface.
  The default 0.1 is the step :mod:`dcslam.eval.surface` and the normals call a depth edge between neighbours;
  between the returns of consecutive 64-beam lasers the ground at 20 m steps by about 8 %, a car in front of the
  road behind it by far more.

Every other empty pixel stays empty (0): above a column's first return, below its last one, and between returns on
two surfaces. An empty pixel is an honest answer, a bridged one is a flying point.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dcslam.constants import MIN_DEPTH_M
from dcslam.errors import DcslamError

#: Default relative depth step below which two consecutive returns of a column are one surface.
MAX_RELATIVE_STEP = 0.1
#: Default largest row distance between two returns that are bridged (an 8-beam scan's median gap is ~50 rows in
#: a KITTI image, 16 beams ~33, 64 beams ~9).
MAX_GAP_PX = 64


def check_sparse(depth_m, what: str) -> np.ndarray:
    """The (H, W) sparse depth as float64 with every value at most :data:`MIN_DEPTH_M` (or not finite) set to 0."""
    depth = np.asarray(depth_m)
    if depth.ndim != 2:
        raise DcslamError(f"{what} takes one (H, W) depth map, got shape {depth.shape}")
    depth = depth.astype(np.float64)
    depth[~(np.isfinite(depth) & (depth > MIN_DEPTH_M))] = 0
    return depth


def complete_scanline(depth_m: np.ndarray, max_relative_step: float = MAX_RELATIVE_STEP,
                      max_gap_px: int = MAX_GAP_PX) -> np.ndarray:
    """Scanline completion of one sparse depth map (the module's rule).

    Shape:
        depth_m: (H, W) metres, 0 = none → (H, W) float32 metres: the returns unchanged, the pixels between
        consecutive returns of a column on one surface filled, 0 elsewhere
    """
    depth = check_sparse(depth_m, "scanline completion")
    h, w = depth.shape
    valid = depth > 0
    rows = np.arange(h)[:, None]
    above = np.maximum.accumulate(np.where(valid, rows, -1), axis=0)       # row of the return at or above, or -1
    below = np.minimum.accumulate(np.where(valid, rows, h)[::-1], axis=0)[::-1]  # ... at or below, or h
    empty = ~valid & (above >= 0) & (below < h) & (below - above <= max_gap_px)
    r, c = np.nonzero(empty)
    r0, r1 = above[r, c], below[r, c]
    z0, z1 = depth[r0, c], depth[r1, c]
    one_surface = np.abs(z1 - z0) < max_relative_step * np.minimum(z0, z1)
    r, c, r0, r1, z0, z1 = (a[one_surface] for a in (r, c, r0, r1, z0, z1))
    t = (r - r0) / (r1 - r0)
    out = depth.copy()
    out[r, c] = 1.0 / ((1 - t) / z0 + t / z1)
    return out.astype(np.float32)


@dataclass(frozen=True)
class Scanline:
    """Scanline completion as a depth completer: ``Scanline()(sparse)`` → completed, both (H, W) float32 metres."""

    max_relative_step: float = MAX_RELATIVE_STEP
    max_gap_px: int = MAX_GAP_PX

    def __post_init__(self):
        if not self.max_relative_step > 0:
            raise DcslamError(f"scanline max_relative_step is {self.max_relative_step}; expected a number > 0")
        if int(self.max_gap_px) != self.max_gap_px or self.max_gap_px < 2:
            raise DcslamError(f"scanline max_gap_px is {self.max_gap_px}; expected a whole number of rows >= 2")

    @property
    def name(self) -> str:
        return "scanline"

    def __call__(self, sparse_m: np.ndarray) -> np.ndarray:
        return complete_scanline(sparse_m, self.max_relative_step, int(self.max_gap_px))


def scanline() -> Scanline:
    """The ``scanline`` completer of the registry (:data:`dcslam.depth.models.CLASSICAL`)."""
    return Scanline()
