"""Small analytic drive files for the depth tests: a camera driving down a corridor street (ground plane, two side
walls, an end wall, a box), dense depth by ray casting, sparse depth = every 4th row, half of its pixels."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from dcslam.io.drive import DriveWriter, Frame


def intrinsics(height: int, width: int) -> np.ndarray:
    f = width * 0.55
    return np.array([[f, 0, width / 2 - 0.5], [0, f, height / 2 - 0.5], [0, 0, 1.0]])


def cast_depth(K: np.ndarray, height: int, width: int, cam_z: float, box_x: float = -1.5) -> np.ndarray:
    """(H, W) float32 depth of the scene seen from (0, 0, cam_z), looking down +z."""
    v, u = np.mgrid[0:height, 0:width].astype(np.float64)
    dx = (u - K[0, 2]) / K[0, 0]
    dy = (v - K[1, 2]) / K[1, 1]
    t = np.full((height, width), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for cand in (np.where(dy > 0, 1.6 / dy, np.inf),                  # ground, 1.6 m below the camera
                     np.where(dx > 0, 5.0 / dx, np.inf),                  # right wall
                     np.where(dx < 0, -5.0 / dx, np.inf),                 # left wall
                     np.full_like(dx, 40.0 - cam_z)):                     # end wall at z = 40
            t = np.minimum(t, np.where(cand > 0, cand, np.inf))
        # a box 2 m wide, 1.5 m high, front face at z = 15
        tz = 15.0 - cam_z
        x, y = dx * tz, dy * tz
        hit = (tz > 0) & (x > box_x - 1) & (x < box_x + 1) & (y > 0.1) & (y < 1.6)
        t = np.where(hit & (tz < t), tz, t)
    depth = np.where(np.isfinite(t) & (t < 60), t, 0)
    return depth.astype(np.float32)


def write_drive(path: Path, n: int = 6, height: int = 32, width: int = 64, seed: int = 0, name: str | None = None,
                split: str = "") -> Path:
    rng = np.random.default_rng(seed)
    K = intrinsics(height, width)
    name = name or Path(path).stem
    with DriveWriter(path, K, height, width, source="synthetic", date="2011_09_26", drive=name, split=split) as w:
        for i in range(n):
            cam_z = 0.5 * i
            dense = cast_depth(K, height, width, cam_z, box_x=-1.5 + 0.2 * seed)
            dense[: height // 4] = 0  # no ground truth at the top, as in KITTI
            sparse = np.zeros_like(dense)
            rows = np.arange(height // 4, height, 4)
            keep = rng.random((len(rows), width)) < 0.5
            sparse[rows] = np.where(keep, dense[rows], 0)
            T = np.eye(4)
            T[2, 3] = cam_z
            rgb = np.clip(dense[..., None] * 6, 0, 255).astype(np.uint8).repeat(3, axis=2)
            w.append(Frame(rgb=rgb, sparse=sparse, dense=dense, T_world_cam=T, timestamp=0.1 * i, frame_id=i))
    return Path(path)


def write_workspace(root: Path, height: int = 32, width: int = 64, n: int = 6) -> Path:
    """A workspace with drives/ (train a, b; val c; test d) and splits.json."""
    import json

    drives = root / "drives"
    drives.mkdir(parents=True, exist_ok=True)
    splits = {"train": ["drive_a", "drive_b"], "val": ["drive_c"], "test": ["drive_d"]}
    seed = 0
    for split, names in splits.items():
        for name in names:
            write_drive(drives / f"{name}.h5", n=n, height=height, width=width, seed=seed, name=name, split=split)
            seed += 1
    (drives / "splits.json").write_text(json.dumps(splits))
    return root
