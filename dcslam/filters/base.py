"""What the filters share: the (H, W) depth check, back-projection to points, and dropping pixels."""
from __future__ import annotations

import numpy as np

from dcslam.errors import DcslamError


def check_depth(depth_m: np.ndarray) -> np.ndarray:
    depth_m = np.asarray(depth_m)
    if depth_m.ndim != 2:
        raise DcslamError(f"depth has shape {depth_m.shape}, expected (H, W)")
    return depth_m.astype(np.float32, copy=False)


def backproject(depth_m: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points of the valid pixels in the camera frame.

    Shapes: depth_m (H, W), K (3, 3) → points (M, 3) float64 (x right, y down, z forward) and their flat pixel
    indices (M,) into ``depth_m.ravel()``.
    """
    depth_m = check_depth(depth_m)
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3):
        raise DcslamError(f"K has shape {K.shape}, expected (3, 3)")
    index = np.flatnonzero(depth_m.ravel() > 0)
    v, u = np.divmod(index, depth_m.shape[1])
    z = depth_m.ravel()[index].astype(np.float64)
    x = (u - K[0, 2]) * z / K[0, 0]
    y = (v - K[1, 2]) * z / K[1, 1]
    return np.stack([x, y, z], axis=1), index


def keep_only(depth_m: np.ndarray, index: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """A copy of ``depth_m`` in which the pixels ``index`` (flat) not marked in ``keep`` are set to 0."""
    out = depth_m.copy()
    out.ravel()[index[~keep]] = 0.0
    return out
