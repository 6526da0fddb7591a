"""Statistical outlier removal on the back-projected points (Open3D)."""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from dcslam.errors import DcslamError
from dcslam.filters.base import backproject, check_depth, keep_only


@dataclass(frozen=True)
class StatisticalOutlierFilter:
    """Drop pixels whose back-projected point is far from its neighbours (Open3D ``remove_statistical_outlier``):
    a point goes when its mean distance to its ``nb_neighbors`` nearest points exceeds the mean of that quantity
    over the image by more than ``std_ratio`` standard deviations."""

    nb_neighbors: int = 20
    std_ratio: float = 2.0
    name = "outlier"

    def __post_init__(self):
        if self.nb_neighbors < 1 or self.std_ratio <= 0:
            raise DcslamError("outlier filter needs nb_neighbors >= 1 and std_ratio > 0")

    def apply(self, depth_m: np.ndarray, K: np.ndarray) -> np.ndarray:
        """(H, W), K (3, 3) → (H, W) float32."""
        import open3d as o3d

        depth_m = check_depth(depth_m)
        points, index = backproject(depth_m, K)
        if len(points) <= self.nb_neighbors:
            return depth_m.copy()
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        _, kept = cloud.remove_statistical_outlier(nb_neighbors=self.nb_neighbors, std_ratio=self.std_ratio)
        keep = np.zeros(len(points), bool)
        keep[np.asarray(kept, dtype=np.int64)] = True
        return keep_only(depth_m, index, keep)

    def describe(self) -> dict:
        return {"filter": self.name, **asdict(self)}
