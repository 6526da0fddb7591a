"""Depth errors as the KITTI depth-completion devkit computes them (``evaluate_depth.cpp``).

Per image, over the pixels that have ground-truth depth (> 0), after the devkit's ``interpolateBackground`` has
filled the prediction's holes:

* MAE  = mean |d_gt − d|, RMSE = sqrt(mean (d_gt − d)²), reported in millimetres;
* iMAE = mean |1/d_gt − 1/d|, iRMSE = sqrt(mean (1/d_gt − 1/d)²), reported in 1/km.

Over many images, the per-image values are averaged (the devkit's ``statMean``), so every image weighs the same
whatever its number of ground-truth pixels.

By default dcslam departs from the devkit in two ways; ``devkit_exact=True`` scores exactly as the devkit instead
(only the summation is in float64 where the devkit sums in 32-bit floats, a difference of the order of 0.01 %):

* **Holes the interpolation cannot fill are left out.** The devkit's interpolation fills a hole in a row from its
  neighbours and extends the first and last rows with depth up and down, but leaves rows *without any* depth that
  lie between rows with depth (the gaps between LiDAR scan lines of raw sparse depth) at its invalid marker −1 m,
  and then scores the ground truth there against −1 m: an error of d_gt + 1 m, and 1/d_gt + 1 per metre in the
  inverse metrics. That measures nothing about the depth. dcslam leaves those pixels out and ``coverage`` says
  what fraction of the ground-truth pixels was scored. Dense predictions are unaffected; on raw sparse LiDAR input
  it matters: on the committed KITTI frame (drive 0001, frame 5, image_02) 7 of 90,839 ground-truth pixels are
  such holes, and the devkit's iRMSE of the raw scan is 12.45 /km where dcslam's is 8.04 /km (MAE 2261.1 vs
  2260.3 mm). A prediction with no depth at all scores ``inf`` here (the devkit scores it against −1 m).
* **Predicted depths below** :data:`MIN_DEPTH_M` **(0.1 m) are holes, not depths.** No KITTI sensor measures that
  near, and dcslam's SLAM ignores such pixels (``FrameSettings.min_depth``), so a network that outputs them is
  saying nothing — typically a constant ~1 mm wherever no LiDAR input reaches (the top of the image). The devkit
  would score them, and its fill spreads them: a hole next to a 1 mm pixel takes the smaller flanking depth, and
  each ground-truth pixel there adds ~|1/d_gt − 1/0.001| ≈ 10⁶ /km to the inverse errors. (A filter that removes
  the network's ramp from that plateau into the scene, such as ``edges``, opens exactly those holes.)

The devkit reads predictions from uint16 PNGs (depth × 256, 0 = none), so a submitted prediction is rounded to
1/256 m by whoever writes it; both scorings here take the depths as given.
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import asdict, dataclass

import numpy as np

from dcslam.constants import MIN_DEPTH_M
from dcslam.errors import DcslamError

METRICS = ("mae_mm", "rmse_mm", "imae_per_km", "irmse_per_km")
#: The devkit's depth of a pixel it could not interpolate (``DepthImage::setInvalid``), scored as is.
DEVKIT_INVALID_M = -1.0
#: The two departures in one paragraph, for ``--help`` and docs/metrics.md.
DEPARTURES_TEXT = (
    "Depth scores follow the KITTI depth-completion devkit (evaluate_depth.cpp: holes filled by its background "
    "interpolation, errors over ground-truth pixels, mean over images) with two departures: (1) ground-truth pixels "
    "that the interpolation cannot reach (rows without any predicted depth between rows with depth, as between the "
    "scan lines of raw LiDAR) are left out, where the devkit scores them against its invalid marker -1 m, which "
    "says nothing about the depth and inflates the inverse errors (on the committed KITTI frame, raw LiDAR: iRMSE "
    "8.04 vs the devkit's 12.45 /km); the coverage column gives the fraction scored; (2) predicted depths below "
    "0.1 m count as holes, as in dcslam's SLAM, where the devkit would score them (a network's ~1 mm outputs add "
    "~10^6 /km per pixel to iMAE/iRMSE). --devkit-exact scores exactly as the devkit.")


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
    scored; ``coverage`` the fraction of all ground-truth pixels that had a predicted depth after interpolation
    (with ``devkit_exact`` every ground-truth pixel is scored, the others against −1 m, so ``pixels`` is all of
    them while ``coverage`` still says how many had a depth)."""

    mae_mm: float
    rmse_mm: float
    imae_per_km: float
    irmse_per_km: float
    pixels: int
    coverage: float

    def as_dict(self) -> dict:
        return asdict(self)


def depth_errors(pred_m: np.ndarray, gt_m: np.ndarray, interpolate: bool = True,
                 devkit_exact: bool = False) -> DepthErrors | None:
    """Errors of one predicted depth image against ground truth; ``None`` when ``gt_m`` has no depth at all.

    Shapes: pred_m (H, W), gt_m (H, W), metres, 0 = none. By default predicted depths below :data:`MIN_DEPTH_M`
    count as none and ground-truth pixels left without a prediction are not scored (the module's two departures);
    ``interpolate=False`` also skips the devkit's interpolation and scores only the pixels where the prediction has
    depth. ``devkit_exact=True`` scores exactly as the devkit: every depth > 0 is a depth, every ground-truth pixel
    is scored, those the interpolation left empty against −1 m (it always interpolates, as the devkit).
    """
    pred_m, gt_m = np.asarray(pred_m), np.asarray(gt_m)
    if pred_m.shape != gt_m.shape or pred_m.ndim != 2:
        raise DcslamError(f"prediction {pred_m.shape} and ground truth {gt_m.shape} must both be (H, W)")
    if devkit_exact and not interpolate:
        raise DcslamError("devkit-exact scoring always interpolates the prediction, as the devkit does; "
                          "drop one of the two options")
    has_gt = gt_m > 0
    if not has_gt.any():
        return None
    pred_m = np.where(pred_m > 0 if devkit_exact else pred_m >= MIN_DEPTH_M, pred_m, 0)
    if interpolate:
        pred_m = interpolate_background(pred_m)
    filled = has_gt & (pred_m > 0)
    coverage = int(filled.sum()) / int(has_gt.sum())
    if devkit_exact:
        pred_m = np.where(pred_m > 0, pred_m, DEVKIT_INVALID_M)
    scored = has_gt if devkit_exact else filled
    pixels = int(scored.sum())
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


def score_frames(pred_m: np.ndarray, gt_m: np.ndarray, interpolate: bool = True,
                 devkit_exact: bool = False) -> list[DepthErrors | None]:
    """Per-image errors of a stack (options as :func:`depth_errors`). Shapes: pred_m (N, H, W), gt_m (N, H, W)."""
    pred_m, gt_m = np.asarray(pred_m), np.asarray(gt_m)
    if pred_m.shape != gt_m.shape or pred_m.ndim != 3:
        raise DcslamError(f"predictions {pred_m.shape} and ground truth {gt_m.shape} must both be (N, H, W) "
                          "with the same N, H, W")
    return [depth_errors(p, g, interpolate, devkit_exact) for p, g in zip(pred_m, gt_m)]


def score_drive(drive_path, source, interpolate: bool = True, devkit_exact: bool = False,
                target: str = "dense") -> list[DepthErrors | None]:
    """Per-frame errors of a depth source (a depth kind of the drive, e.g. ``sparse`` or ``sparse@16``, or a layer
    file) against the drive's depth of kind ``target`` (``dense``, or ``exact`` on generated drives; options as
    :func:`depth_errors`).

    Fails (:class:`DcslamError`) when a layer's frame count or image size does not match its drive.
    """
    from dcslam.io.drive import DriveFile, load_depth

    with DriveFile(drive_path) as drive:
        pred = load_depth(drive, source)
        gt = load_depth(drive, target)
    return score_frames(pred, gt, interpolate, devkit_exact)
