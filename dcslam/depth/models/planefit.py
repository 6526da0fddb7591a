"""Plane-fit completion: each empty pixel takes the local plane through the LiDAR returns around it, fitted in
inverse depth, when those returns lie on one plane; otherwise it stays empty.

For a plane ``n . X = c`` seen through a pinhole, ``1 / z = n . K^-1 (u, v, 1) / c`` is affine in the pixel
coordinates, so a least-squares fit of ``1 / z = a + b (u - u_p) + c (v - v_p)`` to the returns of one plane is
exact, across rows (between beams) and across columns (between the returns of a beam) alike, and at pixel ``p`` the
fill is ``1 / a``. The returns are the pixels deeper than :data:`dcslam.constants.MIN_DEPTH_M`.

Windows, smallest first: half-heights 2, 4, 8, ... up to ``max_half_height`` rows, each ``max(2, half-height //
4)`` columns to either side (tall and narrow: a beam's returns are dense along the row, the beams far apart). An
empty pixel is filled from the first window around it in which

- there are at least ``min_returns`` returns, some in the rows above the pixel, some below, some in the columns to
  its left, some to its right (the fill interpolates between returns, it never extrapolates past them),
- they lie on at least three distinct rows: two beams alone cannot tell one sloped plane from two surfaces a step
  apart (any two lines of returns are coplanar in ``(u, v, 1/z)``); a third one can,
- they span a plane (their rows and columns are not all on one line), and
- the fit's root-mean-square *relative depth* residual ``sqrt(mean(((1/z_fit - 1/z) z)^2))`` is at most
  ``max_relative_rms`` (default 1 %: LiDAR noise is a few centimetres, well under 1 % beyond 5 m, while a window
  that holds returns of two surfaces a depth step apart, or of a curved one, misses by far more). The fit weighs
  each return by ``z^2``, so it minimises that same residual.

Every other pixel stays empty (0): where no window around it holds a single plane's returns on all four sides,
typically at depth edges (no fill ever mixes two surfaces), on curved or cluttered surfaces, and outside the returns.
Sums over windows are differences of integral images, so a frame costs a few array passes per window size.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dcslam.depth.models.scanline import check_sparse
from dcslam.errors import DcslamError

MAX_HALF_HEIGHT = 64
MAX_RELATIVE_RMS = 0.01
MIN_RETURNS = 6


def half_windows(max_half_height: int) -> list[tuple[int, int]]:
    """(half-height, half-width) of the windows tried, smallest first: half-heights 2, 4, ... up to
    ``max_half_height`` (itself included), half-widths ``max(2, half-height // 4)``."""
    sizes, s = [], 2
    while s < max_half_height:
        sizes.append(s)
        s *= 2
    sizes.append(max_half_height)
    return [(s, max(2, s // 4)) for s in sizes]


def _integral(x: np.ndarray) -> np.ndarray:
    """(H + 1, W + 1) float64 integral image: ``out[i, j]`` is the sum of ``x[:i, :j]``."""
    out = np.zeros((x.shape[0] + 1, x.shape[1] + 1))
    np.cumsum(np.cumsum(x, axis=0), axis=1, out=out[1:, 1:])
    return out


def _box(integral: np.ndarray, rows: tuple[int, int], cols: tuple[int, int], at=None) -> np.ndarray:
    """For each pixel (r, c), the sum over rows r + rows[0] .. r + rows[1] and columns c + cols[0] .. c + cols[1]
    (inclusive, clipped to the image; empty ranges sum to 0): (H, W), or (M,) at the pixels ``at = (r, c)``."""
    h, w = integral.shape[0] - 1, integral.shape[1] - 1
    if at is not None:
        r, c = at
        top, bottom = np.clip(r + rows[0], 0, h), np.clip(r + rows[1] + 1, 0, h)
        left, right = np.clip(c + cols[0], 0, w), np.clip(c + cols[1] + 1, 0, w)
        return integral[bottom, right] - integral[top, right] - integral[bottom, left] + integral[top, left]
    # the whole image by slices: an integral image padded with its edge values is the clipped lookup
    pr, pc = max(-rows[0], rows[1] + 1, 0), max(-cols[0], cols[1] + 1, 0)
    padded = np.pad(integral, ((pr, pr), (pc, pc)), mode="edge")

    def corner(dr: int, dc: int) -> np.ndarray:
        return padded[pr + dr:pr + dr + h, pc + dc:pc + dc + w]

    top, bottom, left, right = rows[0], rows[1] + 1, cols[0], cols[1] + 1
    return corner(bottom, right) - corner(top, right) - corner(bottom, left) + corner(top, left)


def complete_planefit(depth_m: np.ndarray, max_half_height: int = MAX_HALF_HEIGHT,
                      max_relative_rms: float = MAX_RELATIVE_RMS, min_returns: int = MIN_RETURNS) -> np.ndarray:
    """Plane-fit completion of one sparse depth map (the module's rule).

    Shape:
        depth_m: (H, W) metres, 0 = none → (H, W) float32 metres: the returns unchanged, the empty pixels with an
        accepted plane filled, 0 elsewhere
    """
    depth = check_sparse(depth_m, "plane-fit completion")
    h, w = depth.shape
    valid = depth > 0
    out = depth.copy()
    if not valid.any():
        return out.astype(np.float32)
    z0 = float(np.median(depth[valid]))
    y = np.where(valid, 1.0 / np.where(valid, depth, 1.0), 0.0) * z0   # inverse depth in units of 1 / z0
    wt = np.where(valid, (depth / z0) ** 2, 0.0)                       # z^2 weights, in units of z0^2
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    u -= w / 2                                                          # coordinates about the centre: smaller sums
    v -= h / 2
    count = _integral(valid.astype(np.float64))
    moments = {name: _integral(x) for name, x in (("w", wt), ("wu", wt * u), ("wv", wt * v), ("wuu", wt * u * u),
                                                  ("wuv", wt * u * v), ("wvv", wt * v * v), ("wy", wt * y),
                                                  ("wuy", wt * u * y), ("wvy", wt * v * y), ("wyy", wt * y * y))}
    todo = ~valid
    for sh, sw in half_windows(max_half_height):
        if not todo.any():
            break
        rows, cols = (-sh, sh), (-sw, sw)
        n = _box(count, rows, cols)
        sides = (_box(count, (-sh, -1), cols), _box(count, (1, sh), cols),
                 _box(count, rows, (-sw, -1)), _box(count, rows, (1, sw)))
        occupied = _integral((_box(count, (0, 0), cols) > 0).astype(np.float64))  # rows with a return near c
        lines = _box(occupied, rows, (0, 0))
        candidate = todo & (n >= min_returns) & (lines >= 3) & np.logical_and.reduce([s > 0 for s in sides])
        if not candidate.any():
            continue
        idx = np.nonzero(candidate)
        S = {name: _box(m, rows, cols, idx) for name, m in moments.items()}
        mu, mv, my = S["wu"] / S["w"], S["wv"] / S["w"], S["wy"] / S["w"]  # weighted means
        cuu = S["wuu"] - S["w"] * mu * mu
        cuv = S["wuv"] - S["w"] * mu * mv
        cvv = S["wvv"] - S["w"] * mv * mv
        cuy = S["wuy"] - S["w"] * mu * my
        cvy = S["wvy"] - S["w"] * mv * my
        cyy = S["wyy"] - S["w"] * my * my
        det = cuu * cvv - cuv * cuv
        spans = det > 1e-9 * np.maximum(cuu * cvv, 1e-300)   # the returns are not all on one line
        safe = np.where(spans, det, 1.0)
        b_u = (cvv * cuy - cuv * cvy) / safe                   # slopes of 1/z along u and v
        b_v = (cuu * cvy - cuv * cuy) / safe
        rss = np.maximum(cyy - b_u * cuy - b_v * cvy, 0.0)     # weighted residual: sum of relative errors squared
        rms = np.sqrt(rss / n[idx])
        fit = my + b_u * (u[idx] - mu) + b_v * (v[idx] - mv)    # 1/z at the pixel, in units of 1 / z0
        accept = spans & (rms <= max_relative_rms) & (fit > 0)
        r, c = idx[0][accept], idx[1][accept]
        out[r, c] = z0 / fit[accept]
        todo[r, c] = False
    return out.astype(np.float32)


@dataclass(frozen=True)
class PlaneFit:
    """Plane-fit completion as a depth completer: ``PlaneFit()(sparse)`` → completed, both (H, W) float32 metres."""

    max_half_height: int = MAX_HALF_HEIGHT
    max_relative_rms: float = MAX_RELATIVE_RMS
    min_returns: int = MIN_RETURNS

    def __post_init__(self):
        if int(self.max_half_height) != self.max_half_height or self.max_half_height < 2:
            raise DcslamError(f"planefit max_half_height is {self.max_half_height}; expected a whole number >= 2")
        if not self.max_relative_rms >= 0:
            raise DcslamError(f"planefit max_relative_rms is {self.max_relative_rms}; expected a number >= 0")
        if int(self.min_returns) != self.min_returns or self.min_returns < 4:
            raise DcslamError(f"planefit min_returns is {self.min_returns}; expected a whole number >= 4 (three "
                              "returns fit any plane exactly: one surface needs a fourth to show)")

    @property
    def name(self) -> str:
        return "planefit"

    def __call__(self, sparse_m: np.ndarray) -> np.ndarray:
        return complete_planefit(sparse_m, int(self.max_half_height), self.max_relative_rms, int(self.min_returns))


def planefit() -> PlaneFit:
    """The ``planefit`` completer of the registry (:data:`dcslam.depth.models.CLASSICAL`)."""
    return PlaneFit()
