"""TUM trajectory files: one pose per line, ``timestamp tx ty tz qx qy qz qw`` (Hamilton quaternion, scalar last).

This is the format evo reads with ``evo_ape tum``. Lines starting with ``#`` and blank lines are ignored.
Poses are ``T_world_cam`` (camera to world) as (N, 4, 4) float64 arrays.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.geometry.rotations import quaternion_to_rotation, rotation_to_quaternion
from dcslam.io.atomic import atomic_output

FORMAT = "'timestamp tx ty tz qx qy qz qw' per line"


def write_tum(path: Path | str, timestamps: np.ndarray, T_world_cam: np.ndarray, force: bool = False) -> Path:
    """Write poses (N, 4, 4) with timestamps (N,) seconds as a TUM file, atomically."""
    timestamps = np.asarray(timestamps, dtype=np.float64)
    T_world_cam = np.asarray(T_world_cam, dtype=np.float64)
    if T_world_cam.ndim != 3 or T_world_cam.shape[1:] != (4, 4) or timestamps.shape != T_world_cam.shape[:1]:
        raise DcslamError(f"expected timestamps (N,) and poses (N, 4, 4), got {timestamps.shape} and "
                          f"{T_world_cam.shape}")
    if not np.all(np.isfinite(T_world_cam)):
        raise DcslamError(f"{path}: refusing to write non-finite poses")
    q = rotation_to_quaternion(T_world_cam[:, :3, :3])
    t = T_world_cam[:, :3, 3]
    lines = ["# timestamp tx ty tz qx qy qz qw"]
    lines += [f"{s:.9f} " + " ".join(f"{v:.12f}" for v in (*ti, *qi)) for s, ti, qi in zip(timestamps, t, q)]
    with atomic_output(path, force=force) as tmp:
        tmp.write_text("\n".join(lines) + "\n")
    return Path(path)


def read_tum(path: Path | str) -> tuple[np.ndarray, np.ndarray]:
    """Read a TUM file → (timestamps (N,), T_world_cam (N, 4, 4)). Fails on malformed lines, non-unit
    quaternions or timestamps that are not strictly increasing."""
    path = Path(path)
    if not path.exists():
        raise DcslamError(f"trajectory file {path} not found")
    if path.is_dir():
        raise DcslamError(f"trajectory file {path} is a folder; pass a TUM trajectory file ({FORMAT})")
    rows = []
    for number, line in enumerate(path.read_text().splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        fields = line.replace(",", " ").split()
        if len(fields) != 8:
            raise DcslamError(f"{path}:{number}: {len(fields)} fields, expected 8 ({FORMAT})")
        try:
            rows.append([float(f) for f in fields])
        except ValueError:
            raise DcslamError(f"{path}:{number}: not a number ({FORMAT})") from None
    if not rows:
        raise DcslamError(f"{path}: no poses ({FORMAT})")
    data = np.array(rows)
    if not np.all(np.isfinite(data)):
        bad = int(np.flatnonzero(~np.isfinite(data).all(axis=1))[0])
        raise DcslamError(f"{path}: pose {bad} holds NaN or infinite values (a failed trajectory); remake the file")
    norms = np.linalg.norm(data[:, 4:], axis=1)
    if np.any(np.abs(norms - 1) > 1e-3):
        bad = int(np.argmax(np.abs(norms - 1)))
        raise DcslamError(f"{path}: quaternion of pose {bad} has norm {norms[bad]:.4f}, expected 1")
    if np.any(np.diff(data[:, 0]) <= 0):
        raise DcslamError(f"{path}: timestamps are not strictly increasing")
    T = np.tile(np.eye(4), (len(data), 1, 1))
    T[:, :3, :3] = quaternion_to_rotation(data[:, 4:])
    T[:, :3, 3] = data[:, 1:4]
    return data[:, 0], T
