"""The solids both generators build scenes from (street and indoor): oriented boxes, cylinders and ellipsoids."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

BOX, CYLINDER, ELLIPSOID = 0, 1, 2


@dataclass(frozen=True)
class Shape:
    """One solid: ``kind`` (BOX, CYLINDER along local z, ELLIPSOID), pose ``R_world_obj`` (3, 3) and ``center``
    (3,), ``half`` (3,) half extents (cylinder: radius, radius, half height; ellipsoid: radii), material and colour."""

    kind: int
    R_world_obj: np.ndarray
    center: np.ndarray
    half: np.ndarray
    material: int
    color: np.ndarray

    @property
    def radius(self) -> float:
        return float(np.linalg.norm(self.half))

    def corners(self) -> np.ndarray:
        """The 8 corners (8, 3) in the world of the shape's oriented bounding box."""
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
        return self.center + (signs * self.half) @ self.R_world_obj.T
