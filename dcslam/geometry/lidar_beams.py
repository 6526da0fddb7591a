"""Which laser of a spinning multi-beam LiDAR (HDL-64E: 64 lasers) measured each point, and scans with fewer beams.

Sparser LiDARs are simulated as the depth-completion literature does (the 64/32/16/8-line splits): assign every
point its laser, number the lasers from the top (highest elevation) down, and keep every ``64 / beams``-th laser,
starting with the top one.

Two ways to find a point's laser, tried in this order:

- **scan order** (real KITTI ``.bin`` scans): KITTI stores a revolution laser by laser, each as one sweep of
  azimuth, so the unwrapped azimuth of consecutive points turns once per laser (63.9 turns for 64 lasers). A point's
  laser is the number of whole turns before it, counted from the scan's first point (with a margin of
  :data:`TURN_MARGIN_DEG`, since each sweep starts a little past the previous sweep's last return).
- **elevation** (generated scans, and any scan not in that order): sorted elevation angles split at their
  ``n_lasers - 1`` widest gaps.
"""
from __future__ import annotations

import numpy as np

from dcslam.errors import DcslamError

HDL64_LASERS = 64
BEAM_COUNTS = (64, 32, 16, 8)
TURN_MARGIN_DEG = 10.0


def _check_points(points: np.ndarray) -> np.ndarray:
    points = np.asarray(points)
    if points.ndim != 2 or points.shape[1] not in (3, 4):
        raise DcslamError(f"points have shape {points.shape}, expected (N, 3) or (N, 4)")
    if len(points) and not np.all(np.isfinite(points[:, :3])):
        raise DcslamError("points hold NaN or infinite coordinates")
    return points


def _by_scan_order(xyz: np.ndarray, n_lasers: int) -> np.ndarray | None:
    azimuth = np.degrees(np.arctan2(xyz[:, 1], xyz[:, 0]))
    step = (np.diff(azimuth) + 180.0) % 360.0 - 180.0
    turns = np.concatenate([[0.0], np.cumsum(step)]) + TURN_MARGIN_DEG
    if np.any(step < -90.0) or int(np.ceil(turns[-1] / 360.0)) != n_lasers:
        return None
    return np.floor(turns / 360.0).astype(np.int64)


def _by_elevation(elevation: np.ndarray, n_lasers: int) -> np.ndarray:
    order = np.argsort(elevation)
    gaps = np.diff(elevation[order])
    if np.count_nonzero(gaps > 0) < n_lasers - 1:
        raise DcslamError(f"scan has fewer than {n_lasers} distinct elevation angles; cannot tell its lasers apart")
    cuts = np.sort(np.argpartition(gaps, len(gaps) - (n_lasers - 1))[len(gaps) - (n_lasers - 1):])
    labels = np.zeros(len(elevation), np.int64)
    labels[order[cuts + 1]] = 1
    labels[order] = np.cumsum(labels[order])
    return labels


def laser_ids(points: np.ndarray, n_lasers: int = HDL64_LASERS) -> np.ndarray:
    """The laser of each point, numbered from the highest elevation (0) to the lowest (``n_lasers - 1``).

    Args:
        points: (N, 3) or (N, 4) points (x, y, z[, reflectance]) in the LiDAR frame, in the file's order.
        n_lasers: lasers of the sensor.

    Returns:
        (N,) int64 laser numbers in ``[0, n_lasers)``.
    """
    xyz = _check_points(points)[:, :3].astype(np.float64)
    if len(xyz) < n_lasers:
        raise DcslamError(f"scan has {len(xyz)} points, fewer than its {n_lasers} lasers")
    elevation = np.arctan2(xyz[:, 2], np.hypot(xyz[:, 0], xyz[:, 1]))
    raw = _by_scan_order(xyz, n_lasers)
    if raw is None:
        raw = _by_elevation(elevation, n_lasers)
    median = np.array([np.median(elevation[raw == k]) if np.any(raw == k) else -np.inf for k in range(n_lasers)])
    rank = np.empty(n_lasers, np.int64)
    rank[np.argsort(-median, kind="stable")] = np.arange(n_lasers)
    return rank[raw]


def keep_beams(points: np.ndarray, beams: int, n_lasers: int = HDL64_LASERS) -> np.ndarray:
    """The points of every ``n_lasers / beams``-th laser, counted from the top one: an as-if ``beams``-line scan.

    Args:
        points: (N, 3) or (N, 4) points in the LiDAR frame, in the file's order.
        beams: lasers to keep; must divide ``n_lasers``.

    Returns:
        (M, 3) or (M, 4) the kept points, in their original order (all of them when ``beams == n_lasers``).
    """
    points = _check_points(points)
    if beams < 1 or n_lasers % beams:
        raise DcslamError(f"beams is {beams}; expected a divisor of the sensor's {n_lasers} lasers "
                          f"(e.g. {', '.join(map(str, BEAM_COUNTS))})")
    if beams == n_lasers:
        return points
    return points[laser_ids(points, n_lasers) % (n_lasers // beams) == 0]
