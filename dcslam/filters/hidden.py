"""Hidden-point removal on the back-projected points (Open3D)."""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from dcslam.errors import DcslamError
from dcslam.filters.base import backproject, check_depth, keep_only


@dataclass(frozen=True)
class HiddenPointFilter:
    """Drop pixels whose back-projected point is hidden from the camera by the surface through the other points
    (Katz et al. 2007, Open3D ``hidden_point_removal`` from the camera centre, radius = ``radius_factor`` × the
    diameter of the points' bounding box). Meant for LiDAR depth projected into the camera, where points seen by
    the LiDAR but occluded for the camera show through foreground objects."""

    radius_factor: float = 100.0
    name = "hidden"

    def __post_init__(self):
        if self.radius_factor <= 0:
            raise DcslamError("hidden-point filter needs radius_factor > 0")

    def apply(self, depth_m: np.ndarray, K: np.ndarray) -> np.ndarray:
        """(H, W), K (3, 3) → (H, W) float32."""
        import open3d as o3d

        depth_m = check_depth(depth_m)
        points, index = backproject(depth_m, K)
        if len(points) < 4:
            return depth_m.copy()
        diameter = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
        if diameter == 0:
            return depth_m.copy()
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        try:
            _, visible = cloud.hidden_point_removal([0.0, 0.0, 0.0], self.radius_factor * diameter)
        except RuntimeError:  # qhull fails on degenerate (e.g. coplanar) point sets: nothing can be hidden there
            return depth_m.copy()
        keep = np.zeros(len(points), bool)
        keep[np.asarray(visible, dtype=np.int64)] = True
        return keep_only(depth_m, index, keep)

    def describe(self) -> dict:
        return {"filter": self.name, **asdict(self)}
