"""Builders of small KITTI roots for tests (not a test module; loaded by path from tests that need it).

- :func:`link_real_drive`: the committed real sample as a COMPLETE drive (108 frames): every raw frame's image and
  every depth frame (5..102) are links to the one real frame-5 file, OXTS, calibration and timestamps are the real
  ones. Cheap (links), and the files read are real KITTI bytes.
- :func:`write_tiny_drive`: a small drive (e.g. 14 frames of 32x48 pixels) with the real calibration and the first
  OXTS packets and timestamps of the real drive, random images and depth.
"""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from dcslam.io import kitti

SAMPLE = Path(__file__).parents[1] / "data" / "kitti-sample"
REAL_NAME = "2011_09_26_drive_0001_sync"
REAL_RAW = SAMPLE / "raw" / "2011_09_26" / REAL_NAME
REAL_DEPTH = SAMPLE / "depth_completion" / "train" / REAL_NAME / "proj_depth"
N_REAL = 108


def _link(target: Path, link: Path) -> None:
    link.parent.mkdir(parents=True, exist_ok=True)
    link.symlink_to(target.resolve())


def _calibration(root: Path, date: str = "2011_09_26") -> None:
    for name in kitti.CALIB_FILES:
        if not (root / "raw" / date / name).exists():
            _link(SAMPLE / "raw" / "2011_09_26" / name, root / "raw" / date / name)


def link_real_drive(root: Path) -> Path:
    """Make ``root`` a KITTI root holding the real drive 2011_09_26_drive_0001_sync, complete; returns root."""
    _calibration(root)
    raw = root / "raw" / "2011_09_26" / REAL_NAME
    _link(REAL_RAW / "oxts", raw / "oxts")
    _link(REAL_RAW / "image_02" / "timestamps.txt", raw / "image_02" / "timestamps.txt")
    image = REAL_RAW / "image_02" / "data" / "0000000005.png"
    for i in range(N_REAL):
        _link(image, raw / "image_02" / "data" / kitti.frame_name(i, ".png"))
    depth = root / "depth_completion" / "train" / REAL_NAME / "proj_depth"
    for kind in ("velodyne_raw", "groundtruth"):
        for i in range(5, N_REAL - 5):
            _link(REAL_DEPTH / kind / "image_02" / "0000000005.png", depth / kind / "image_02" /
                  kitti.frame_name(i, ".png"))
    return root


def write_tiny_drive(root: Path, name: str = "2011_09_26_drive_0002_sync", n_frames: int = 14,
                     size: tuple[int, int] = (32, 48), depth_split: str = "train", seed: int = 0) -> Path:
    """Write a small drive under ``root`` (frames 0..n-1, depth for 5..n-6); returns its raw folder."""
    rng = np.random.default_rng(seed)
    date = name[:10]
    _calibration(root, date)
    raw = root / "raw" / date / name
    stamps = kitti.read_timestamps(REAL_RAW / "image_02" / "timestamps.txt")[:n_frames]
    kitti.write_timestamps(raw / "image_02" / "timestamps.txt", stamps)
    kitti.write_timestamps(raw / "oxts" / "timestamps.txt", stamps)
    (raw / "oxts" / "data").mkdir(parents=True, exist_ok=True)
    for i in range(n_frames):
        kitti.write_image(raw / "image_02" / "data" / kitti.frame_name(i, ".png"),
                          rng.integers(0, 256, (*size, 3), dtype=np.uint8))
        shutil.copy(REAL_RAW / "oxts" / "data" / kitti.frame_name(i, ".txt"),
                    raw / "oxts" / "data" / kitti.frame_name(i, ".txt"))
    depth = root / "depth_completion" / depth_split / name / "proj_depth"
    for i in range(5, n_frames - 5):
        dense = rng.uniform(2.0, 80.0, size) * (rng.random(size) < 0.3)
        sparse = dense * (rng.random(size) < 0.3)
        kitti.write_depth_png(depth / "groundtruth" / "image_02" / kitti.frame_name(i, ".png"), dense)
        kitti.write_depth_png(depth / "velodyne_raw" / "image_02" / kitti.frame_name(i, ".png"), sparse)
    return raw
