"""KITTI odometry pose files: one pose per line, the first three rows of ``T_world_cam`` as 12 numbers, row-major.

This is the format of the KITTI odometry benchmark (``poses/<sequence>.txt``, read by the devkit's
``evaluate_odometry.cpp`` and by ``evo_ape kitti``): ``r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz``, pose i of the
file being frame i of the sequence (no timestamps; those live in the sequence's ``times.txt``). Poses are
``T_world_cam`` (camera to world, world = the first camera pose in the benchmark's own files) as (N, 4, 4) float64.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.io.atomic import atomic_output
from dcslam.io.text_rows import read_number_rows

FORMAT = "12 numbers per line, the 3x4 matrix [R | t] row-major"
#: Largest accepted ``max |RᵀR − I|`` and ``|det R − 1|``: the benchmark's files print 6 significant digits, which
#: leaves ~1e-6 of round-off (sequence 04: 1.5e-7); anything far above is not a rotation.
ROTATION_TOLERANCE = 1e-4


def check_rotations(T: np.ndarray, where: str) -> None:
    """A :class:`DcslamError` naming ``where`` and the first pose of ``T`` (N, 4, 4) whose rotation is not one."""
    R = T[:, :3, :3]
    orthogonality = np.abs(np.swapaxes(R, 1, 2) @ R - np.eye(3)).max(axis=(1, 2))
    determinant = np.abs(np.linalg.det(R) - 1.0)
    bad = np.flatnonzero((orthogonality > ROTATION_TOLERANCE) | (determinant > ROTATION_TOLERANCE))
    if len(bad):
        i = int(bad[0])
        raise DcslamError(f"{where}: the rotation of pose {i} is not orthonormal with determinant 1 "
                          f"(max |RᵀR − I| = {orthogonality[i]:.2g}, det = {np.linalg.det(R[i]):.6g})")


def write_kitti_poses(path: Path | str, T_world_cam: np.ndarray, force: bool = False) -> Path:
    """Write poses (N, 4, 4) as a KITTI odometry pose file, atomically (refuses to overwrite without ``force``).

    Fails (:class:`DcslamError`) on a wrong shape, non-finite values, a bottom row other than (0, 0, 0, 1) or a
    rotation part that is not a rotation.
    """
    T = np.asarray(T_world_cam, dtype=np.float64)
    if T.ndim != 3 or T.shape[1:] != (4, 4) or len(T) == 0:
        raise DcslamError(f"{path}: poses have shape {T.shape}, expected (N, 4, 4) with N > 0")
    if not np.all(np.isfinite(T)):
        raise DcslamError(f"{path}: refusing to write non-finite poses")
    if np.abs(T[:, 3] - np.array([0.0, 0.0, 0.0, 1.0])).max() > 0:
        raise DcslamError(f"{path}: the bottom row of every pose must be (0, 0, 0, 1)")
    check_rotations(T, str(path))
    rows = T[:, :3, :].reshape(len(T), 12)
    text = "\n".join(" ".join(f"{v:.12e}" for v in row) for row in rows) + "\n"
    with atomic_output(path, force=force) as tmp:
        tmp.write_text(text)
    return Path(path)


def read_kitti_poses(path: Path | str) -> np.ndarray:
    """Read a KITTI odometry pose file → T_world_cam (N, 4, 4) float64.

    Blank lines are skipped. Fails (:class:`DcslamError`) on a missing or empty file, a line without exactly 12
    numbers, non-finite values, or a rotation part that is not orthonormal with determinant 1 (within
    :data:`ROTATION_TOLERANCE`).
    """
    data = read_number_rows(path, 12, FORMAT)
    T = np.tile(np.eye(4), (len(data), 1, 1))
    T[:, :3, :] = data.reshape(-1, 3, 4)
    check_rotations(T, str(path))
    return T
