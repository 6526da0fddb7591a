"""Checks of the values that make a camera or a pose meaningful, made where a file is read: a calibration or drive
file whose intrinsics or poses hold no camera is refused there, in one line naming the file, instead of failing
deep inside a solver (or running on with NaN)."""
from __future__ import annotations

import numpy as np

from dcslam.errors import DcslamError


def check_intrinsics(K: np.ndarray, where: str) -> np.ndarray:
    """``K`` (3, 3) float64 if it is a camera's intrinsic matrix: finite, ``fx`` and ``fy`` non-zero (``fy`` may be
    negative, as ICL-NUIM's), no skew between rows, last row ``0 0 1``; else a :class:`DcslamError` naming
    ``where``."""
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3):
        raise DcslamError(f"{where}: intrinsic matrix K has shape {K.shape}, expected (3, 3)")
    if not np.isfinite(K).all():
        raise DcslamError(f"{where}: intrinsic matrix K holds non-finite values ({_row_major(K)})")
    if K[0, 0] == 0 or K[1, 1] == 0 or K[1, 0] != 0 or not np.array_equal(K[2], [0.0, 0.0, 1.0]):
        raise DcslamError(f"{where}: K = [{_row_major(K)}] is not a camera's intrinsic matrix (expected fx, fy != 0, "
                          "row 2 = 0 fy cy, row 3 = 0 0 1)")
    return K


def check_poses(T: np.ndarray, where: str) -> np.ndarray:
    """``T`` (N, 4, 4) float64 if every pose is finite, its bottom row ``0 0 0 1`` and its rotation orthonormal with
    determinant 1 (within :data:`dcslam.io.kitti_poses.ROTATION_TOLERANCE`); else a :class:`DcslamError` naming
    ``where`` and the first bad pose."""
    from dcslam.io.kitti_poses import check_rotations

    T = np.asarray(T, dtype=np.float64)
    if T.ndim != 3 or T.shape[1:] != (4, 4):
        raise DcslamError(f"{where}: poses of shape {T.shape}, expected (N, 4, 4)")
    bad = np.flatnonzero(~np.isfinite(T).reshape(len(T), -1).all(axis=1))
    if len(bad):
        raise DcslamError(f"{where}: pose {bad[0]} is not finite")
    bad = np.flatnonzero(np.abs(T[:, 3] - [0.0, 0.0, 0.0, 1.0]).max(axis=1) > 0)
    if len(bad):
        raise DcslamError(f"{where}: pose {bad[0]} has bottom row {T[bad[0], 3].tolist()}, expected [0, 0, 0, 1]")
    check_rotations(T, where)
    return T


def _row_major(K: np.ndarray) -> str:
    return " ".join(f"{v:g}" for v in K.ravel())
