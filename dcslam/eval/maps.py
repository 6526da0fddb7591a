"""Map scores: chamfer distance between a SLAM map and a ground-truth map (point clouds, PLY files).

The chamfer distance is the thesis's (the one it trained with): squared nearest-neighbour distances, averaged over
each cloud, summed over both directions::

    chamfer(A, B) = mean_a min_b ‖a − b‖² + mean_b min_a ‖a − b‖²      (m²)

Beside it: ``accuracy`` = mean distance from the map to the ground truth (m), ``completeness`` = mean distance from
the ground truth to the map (m). Nearest neighbours are exact (:mod:`dcslam.geometry.nearest`, the search the
training loss uses), so millions of points are fine on a CPU.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.geometry.nearest import nearest_indices, squared_distances


@dataclass(frozen=True)
class MapScores:
    chamfer_m2: float
    accuracy_m: float
    completeness_m: float
    map_points: int
    gt_points: int

    def as_dict(self) -> dict:
        return asdict(self)


def _check_points(points: np.ndarray, name: str) -> np.ndarray:
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise DcslamError(f"{name} has shape {points.shape}, expected (N, 3)")
    if len(points) == 0:
        raise DcslamError(f"{name} has no points")
    if not np.all(np.isfinite(points)):
        raise DcslamError(f"{name} has non-finite points")
    return points


def chamfer(map_points: np.ndarray, gt_points: np.ndarray) -> MapScores:
    """Map scores of ``map_points`` (N, 3) against ``gt_points`` (M, 3), metres."""
    map_points = _check_points(map_points, "map")
    gt_points = _check_points(gt_points, "ground-truth map")
    to_gt, to_map = nearest_indices(map_points, gt_points)
    squared_to_gt = squared_distances(map_points, gt_points, to_gt)
    squared_to_map = squared_distances(gt_points, map_points, to_map)
    return MapScores(chamfer_m2=float(squared_to_gt.mean() + squared_to_map.mean()),
                     accuracy_m=float(np.sqrt(squared_to_gt).mean()),
                     completeness_m=float(np.sqrt(squared_to_map).mean()),
                     map_points=len(map_points), gt_points=len(gt_points))


def read_points(path: Path | str) -> np.ndarray:
    """Points (N, 3) float64 of a PLY point-cloud file (read with Open3D; other properties are ignored)."""
    path = Path(path)
    if not path.exists():
        raise DcslamError(f"map file {path} not found; run `dcslam slam` first")
    import open3d as o3d

    cloud = o3d.io.read_point_cloud(str(path), format="ply")
    points = np.asarray(cloud.points)
    if len(points) == 0:
        raise DcslamError(f"{path}: no points read (expected a PLY point cloud with x y z)")
    return _check_points(points, str(path))


def score_map(map_path: Path | str, gt_path: Path | str) -> MapScores:
    """Chamfer scores of a map PLY file against a ground-truth map PLY file."""
    return chamfer(read_points(map_path), read_points(gt_path))
