"""The road as a depth-only witness of a SLAM run's vertical drift.

Each frame's road plane is fitted to the points of the depth the run uses (its valid pixels back-projected, whatever
the input: measured, completed or exact) that lie more than ``BELOW_M`` below the camera, ``NEAR_M``-``FAR_M`` ahead
and within ``SIDE_M`` across: RANSAC with a fixed seed, ``TRIES`` hypotheses on at most ``MAX_POINTS`` of them, then
least squares on the inliers (:func:`frame_road`). Per step, the previous frame's plane carried into the frame by the
estimated relative pose should be the frame's own; the smallest motion taking one onto the other is the step's pitch,
roll and height error as the road sees it. Composing the estimated steps with those corrections gives a
road-corrected trajectory, and the vertical distance between it and the estimate estimates the run's vertical error
(:func:`road_drift`; on generated drives within 0.015-0.028 m of the truth, median: docs/slam.md).

The thresholds are metric, for a street seen from a car's roof: a frame with fewer than ``MIN_POINTS`` such
returns or inliers (a room, a crest, a view blocked by a truck) has no road, is skipped and counted; its steps are
taken as estimated.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

BELOW_M, NEAR_M, FAR_M, SIDE_M, INLIER_M = 0.8, 3.0, 30.0, 10.0, 0.08
#: RANSAC's budget: hypotheses, points it scores them on (a fixed-stride subsample), and the fewest points a road
#: needs. 64 hypotheses find a plane holding most points with certainty; 2000 points fit it to ~1 cm.
TRIES, MAX_POINTS, MIN_POINTS = 64, 2000, 30
#: The road's normal is within this angle of the camera's up (a car does not drive up walls).
MAX_TILT_DEG = 25.0
SEED = 0


@dataclass(frozen=True)
class RoadPlane:
    """A road plane n . x + d = 0 in the camera frame (x right, y down, z forward), n unit pointing up (n_y < 0),
    fitted to ``inliers`` points. Shape: normal (3,)."""

    normal: np.ndarray
    offset: float
    inliers: int


def road_candidates(vertex) -> np.ndarray:
    """The returns that may be road: more than BELOW_M below the camera, NEAR_M-FAR_M ahead, within SIDE_M across.
    Shape: vertex (H, W, 3) camera frame, a torch tensor or array (0 where no depth) -> (M, 3) float64."""
    if hasattr(vertex, "detach"):
        import torch

        v = vertex.detach().reshape(-1, 3)
        keep = (v[:, 1] > BELOW_M) & (v[:, 2] > NEAR_M) & (v[:, 2] < FAR_M) & (v[:, 0].abs() < SIDE_M)
        return v[keep].to("cpu", torch.float64).numpy()
    v = np.asarray(vertex, np.float64).reshape(-1, 3)
    return v[(v[:, 1] > BELOW_M) & (v[:, 2] > NEAR_M) & (v[:, 2] < FAR_M) & (np.abs(v[:, 0]) < SIDE_M)]


def fit_road(points: np.ndarray) -> RoadPlane | None:
    """RANSAC plane (normal within MAX_TILT_DEG of up, inliers within INLIER_M) on at most MAX_POINTS of ``points``
    taken at a fixed stride, hypotheses drawn with a fixed seed (the same plane for the same points, on any
    thread), refitted by least squares on its inliers; None with fewer than MIN_POINTS points or inliers.
    Shape: points (M, 3)."""
    if len(points) < MIN_POINTS:
        return None
    p = points[np.linspace(0, len(points) - 1, MAX_POINTS).astype(int)] if len(points) > MAX_POINTS else points
    rng = np.random.default_rng(SEED)
    a, b, c = (p[i] for i in rng.integers(0, len(p), (3, TRIES)))
    n = np.cross(b - a, c - a)
    norm = np.linalg.norm(n, axis=1)
    n = n / np.maximum(norm, 1e-12)[:, None] * np.where(n[:, 1] > 0, -1.0, 1.0)[:, None]
    usable = (norm > 1e-9) & (-n[:, 1] >= np.cos(np.radians(MAX_TILT_DEG)))
    if not usable.any():
        return None
    n, a = n[usable], a[usable]
    inliers = np.abs(p @ n.T - (n * a).sum(1)) < INLIER_M          # (M, hypotheses)
    best = inliers[:, int(np.argmax(inliers.sum(0)))]
    if best.sum() < MIN_POINTS:
        return None
    q = p[best]
    centre = q.mean(0)
    normal = np.linalg.svd(q - centre, full_matrices=False)[2][2]
    normal = normal * (-1 if normal[1] > 0 else 1)
    return RoadPlane(normal, float(-normal @ centre), int(best.sum()))


def frame_road(vertex) -> RoadPlane | None:
    """The road plane of one frame (:func:`road_candidates`, :func:`fit_road`), or None: no road seen."""
    return fit_road(road_candidates(vertex))


def align_planes(n_from: np.ndarray, d_from: float, n_to: np.ndarray, d_to: float) -> np.ndarray:
    """The smallest rigid motion (4, 4) taking plane (n_from, d_from) onto (n_to, d_to): the rotation about
    n_from x n_to, then the shift along n_to."""
    axis = np.cross(n_from, n_to)
    s, c = np.linalg.norm(axis), float(n_from @ n_to)
    R = np.eye(3)
    if s > 1e-12:
        k = axis / s
        Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        R = np.eye(3) + s * Kx + (1 - c) * Kx @ Kx
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, (d_from - d_to) * n_to
    return T


def road_corrected(T_world_cam: np.ndarray, planes: list) -> np.ndarray:
    """The road-corrected trajectory: each estimated step composed with the smallest motion taking the previous
    frame's road plane, carried into the frame by the step, onto the frame's own (its pitch, roll and height error
    as the road sees them); a step is taken as estimated unless both its frames saw the road. The motion along and
    across the road and the heading stay the estimate's. Shape: T_world_cam (N, 4, 4); planes: N RoadPlane or None
    -> (N, 4, 4), starting at the estimate's first pose."""
    T = np.asarray(T_world_cam, np.float64)
    corrected = [T[0]]
    for k in range(1, len(T)):
        rel = np.linalg.solve(T[k], T[k - 1])                      # frame k-1 camera -> frame k camera
        C = np.eye(4)
        before, now = planes[k - 1], planes[k]
        if before is not None and now is not None:
            m = rel[:3, :3] @ before.normal                        # the previous plane, carried into frame k
            C = align_planes(m, before.offset - float(m @ rel[:3, 3]), now.normal, now.offset)
        corrected.append(corrected[-1] @ np.linalg.inv(C @ rel))
    return np.stack(corrected)


def road_drift(T_world_cam: np.ndarray, planes: list, over_m: float = 0.0) -> dict:
    """The road figure of a run: per frame, the vertical distance (along the first frame's camera y, down) of the
    estimated position from the road-corrected one (:func:`road_corrected`), positive when the estimate sank below
    the road. Shape: T_world_cam (N, 4, 4); planes: N RoadPlane or None.

    Returns ``{"drift_m": |final distance|, "vertical": "sank" or "rose", "frames_seen": n, "frames_skipped": n,
    "from_frame": the first frame whose distance exceeds ``over_m`` (None when none does or ``over_m`` is 0)}``.
    """
    T = np.asarray(T_world_cam, np.float64)
    down = T[0, :3, 1]
    gaps = (T[:, :3, 3] - road_corrected(T, planes)[:, :3, 3]) @ down
    over = np.flatnonzero(np.abs(gaps) > over_m) if over_m > 0 else []
    seen = sum(p is not None for p in planes)
    return {"drift_m": round(float(abs(gaps[-1])), 4), "vertical": "sank" if gaps[-1] >= 0 else "rose",
            "frames_seen": seen, "frames_skipped": len(planes) - seen,
            "from_frame": int(over[0]) if len(over) else None}
