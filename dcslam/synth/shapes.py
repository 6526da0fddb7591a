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
        return self.center + (CORNER_SIGNS * self.half) @ self.R_world_obj.T


#: The signs of the 8 corners of a box about its centre, in the order of :meth:`Shape.corners`.
CORNER_SIGNS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)


def corners_in(shapes: list[Shape], T_frame_world: np.ndarray) -> np.ndarray:
    """The bounding-box corners (S, 8, 3) of ``shapes`` in the frame ``T_frame_world`` (4, 4) maps the world to,
    all at once (per shape they are :meth:`Shape.corners` so mapped)."""
    if not shapes:
        return np.zeros((0, 8, 3))
    centers = np.stack([shape.center for shape in shapes]).astype(np.float64)
    halves = np.stack([shape.half for shape in shapes]).astype(np.float64)
    rotations = np.stack([shape.R_world_obj for shape in shapes]).astype(np.float64)
    world = centers[:, None, :] + (CORNER_SIGNS[None] * halves[:, None, :]) @ rotations.transpose(0, 2, 1)
    return world @ T_frame_world[:3, :3].T + T_frame_world[:3, 3]
