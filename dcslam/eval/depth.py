"""Depth errors as the KITTI depth-completion devkit computes them (``evaluate_depth.cpp``).

Per image, over the pixels that have ground-truth depth (> 0), after the devkit's ``interpolateBackground`` has
filled the prediction's holes:

* MAE  = mean |d_gt − d|, RMSE = sqrt(mean (d_gt − d)²), reported in millimetres;
* iMAE = mean |1/d_gt − 1/d|, iRMSE = sqrt(mean (1/d_gt − 1/d)²), reported in 1/km.

Over many images, the per-image values are averaged (the devkit's ``statMean``), so every image weighs the same
whatever its number of ground-truth pixels.

Two departures:

* Holes that the interpolation cannot fill (rows without any depth lying between rows with depth — the gaps between
  LiDAR scan lines of raw sparse depth) are scored by the devkit against its invalid marker −1 m, which is
  meaningless; here they are left out, and ``coverage`` says what fraction of the ground-truth pixels was scored.
  A prediction with no depth at all scores ``inf``. Dense predictions are unaffected.
* Predicted depths below :data:`MIN_DEPTH_M` (0.1 m) are holes, not depths. No KITTI sensor measures that near, and
  dcslam's SLAM ignores such pixels (``FrameSettings.min_depth``), so a network that outputs them is saying
  nothing — typically a constant ~1 mm wherever no LiDAR input reaches (the top of the image). The devkit would
  score them, and its fill spreads them: a hole next to a 1 mm pixel takes the smaller flanking depth, and each
  ground-truth pixel there adds ~|1/d_gt − 1/0.001| ≈ 10⁶ /km to the inverse errors. (A filter that removes the
  network's ramp from that plateau into the scene, such as ``edges``, opens exactly those holes.)
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import asdict, dataclass

import numpy as np

from dcslam.constants import MIN_DEPTH_M
from dcslam.errors import DcslamError

METRICS = ("mae_mm", "rmse_mm", "imae_per_km", "irmse_per_km")


def interpolate_background(depth_m: np.ndarray) -> np.ndarray:
    """Fill holes (0) of a predicted depth image the way the KITTI devkit does before scoring.

    Row by row: a hole between two valid pixels takes the smaller, i.e. nearer, of the two depths (the devkit's
    ``std::min``, whatever the function's name says); holes before the first / after the last valid pixel of a row
    take that pixel's depth. Then column by column, rows above the first / below the last row with any depth take
    that row's depth. Rows without depth that lie between rows with depth stay 0 (the devkit leaves them invalid,
    at −1).

    Shapes: depth_m (H, W) → (H, W) float32 (a new array).
    """
    depth_m = np.asarray(depth_m, dtype=np.float32)
    if depth_m.ndim != 2:
        raise DcslamError(f"depth has shape {depth_m.shape}, expected (H, W)")
    height, width = depth_m.shape
    out = depth_m.copy()
    valid = out > 0
    cols = np.arange(width)
    # previous / next valid column of every pixel (-1 / width when none)
    prev_col = np.maximum.accumulate(np.where(valid, cols, -1), axis=1)
    next_col = np.flip(np.minimum.accumulate(np.flip(np.where(valid, cols, width), axis=1), axis=1), axis=1)
    rows = np.arange(height)[:, None]
    has_prev, has_next = prev_col >= 0, next_col < width
    prev_val = out[rows, np.clip(prev_col, 0, width - 1)]
    next_val = out[rows, np.clip(next_col, 0, width - 1)]
    fill = np.where(has_prev & has_next, np.minimum(prev_val, next_val), np.where(has_prev, prev_val, next_val))
    holes = ~valid & (has_prev | has_next)
    out[holes] = fill[holes]
    filled_rows = np.flatnonzero(valid.any(axis=1))
    if len(filled_rows):
        out[:filled_rows[0]] = out[filled_rows[0]]
        out[filled_rows[-1] + 1:] = out[filled_rows[-1]]
    return out


@dataclass(frozen=True)
class DepthErrors:
    """Errors of one image (or the mean over images): millimetres and 1/km; ``pixels`` the ground-truth pixels
    scored, ``coverage`` their fraction of all ground-truth pixels."""

    mae_mm: float
    rmse_mm: float
    imae_per_km: float
    irmse_per_km: float
    pixels: int
    coverage: float

    def as_dict(self) -> dict:
        return asdict(self)


def depth_errors(pred_m: np.ndarray, gt_m: np.ndarray, interpolate: bool = True) -> DepthErrors | None:
    """Errors of one predicted depth image against ground truth; ``None`` when ``gt_m`` has no depth at all.

    Shapes: pred_m (H, W), gt_m (H, W), metres, 0 = none; predicted depths below :data:`MIN_DEPTH_M` count as
    none. ``interpolate=False`` skips the devkit's interpolation and scores only the pixels where the prediction
    has depth.
    """
    pred_m, gt_m = np.asarray(pred_m), np.asarray(gt_m)
    if pred_m.shape != gt_m.shape or pred_m.ndim != 2:
        raise DcslamError(f"prediction {pred_m.shape} and ground truth {gt_m.shape} must both be (H, W)")
    has_gt = gt_m > 0
    if not has_gt.any():
        return None
    pred_m = np.where(pred_m >= MIN_DEPTH_M, pred_m, 0)
    if interpolate:
        pred_m = interpolate_background(pred_m)
    scored = has_gt & (pred_m > 0)
    pixels = int(scored.sum())
    coverage = pixels / int(has_gt.sum())
    if pixels == 0:
        return DepthErrors(mae_mm=math.inf, rmse_mm=math.inf, imae_per_km=math.inf, irmse_per_km=math.inf,
                           pixels=0, coverage=0.0)
    gt = gt_m[scored].astype(np.float64)
    pred = pred_m[scored].astype(np.float64)
    err = np.abs(gt - pred)
    inv_err = np.abs(1.0 / gt - 1.0 / pred)
    return DepthErrors(mae_mm=1000.0 * float(err.mean()), rmse_mm=1000.0 * float(np.sqrt((err ** 2).mean())),
                       imae_per_km=1000.0 * float(inv_err.mean()),
                       irmse_per_km=1000.0 * float(np.sqrt((inv_err ** 2).mean())), pixels=pixels, coverage=coverage)

def mean_errors(errors: Iterable[DepthErrors | None]) -> DepthErrors:
    """The devkit's mean over images (images without ground truth skipped); ``pixels`` is the total."""
    errors = [e for e in errors if e is not None]
    if not errors:
        raise DcslamError("no image with ground-truth depth to score")
    mean = {m: float(np.mean([getattr(e, m) for e in errors])) for m in METRICS}
    return DepthErrors(**mean, pixels=int(sum(e.pixels for e in errors)),
                       coverage=float(np.mean([e.coverage for e in errors])))


def score_frames(pred_m: np.ndarray, gt_m: np.ndarray, interpolate: bool = True) -> list[DepthErrors | None]:
    """Per-image errors of a stack. Shapes: pred_m (N, H, W), gt_m (N, H, W)."""
    pred_m, gt_m = np.asarray(pred_m), np.asarray(gt_m)
    if pred_m.shape != gt_m.shape or pred_m.ndim != 3:
        raise DcslamError(f"predictions {pred_m.shape} and ground truth {gt_m.shape} must both be (N, H, W) "
                          "with the same N, H, W")
    return [depth_errors(p, g, interpolate) for p, g in zip(pred_m, gt_m)]


def score_drive(drive_path, source, interpolate: bool = True) -> list[DepthErrors | None]:
    """Per-frame errors of a depth source (``sparse``, ``dense`` or a layer file) against the drive's dense depth.

    Fails (:class:`DcslamError`) when a layer's frame count or image size does not match its drive.
    """
    from dcslam.io.drive import DriveFile, load_depth

    with DriveFile(drive_path) as drive:
        pred = load_depth(drive, source)
        gt = load_depth(drive, "dense")
    return score_frames(pred, gt, interpolate)
