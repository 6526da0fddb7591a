"""16-bit depth PNGs, the one codec for every dataset: metres = value / ``scale``, 0 = no value.

KITTI writes ``scale`` 256 (:data:`dcslam.io.kitti.DEPTH_SCALE`), TUM RGB-D and ICL-NUIM 5000
(:data:`dcslam.io.tum_rgbd.DEPTH_SCALE`).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError


def read_depth_png(path: Path | str, scale: float) -> np.ndarray:
    """A 16-bit single-channel PNG → (H, W) float32 metres (value / ``scale``, 0 = no value).

    Fails on missing, unreadable (truncated, corrupt) and 8-bit or multi-channel files.
    """
    import cv2

    path = Path(path)
    if not path.exists():
        raise DcslamError(f"depth PNG {path} not found")
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise DcslamError(f"{path}: not a readable PNG (truncated or corrupt?)")
    if image.dtype != np.uint16 or image.ndim != 2:
        raise DcslamError(f"{path}: expected a 16-bit single-channel depth PNG (metres = value / {scale:g}), got "
                          f"{image.dtype} with shape {image.shape}")
    return image.astype(np.float32) / np.float32(scale)


def write_depth_png(path: Path | str, depth_m: np.ndarray, scale: float) -> Path:
    """(H, W) metres → 16-bit PNG, value = round(``scale`` · metres). Depth that does not fit (negative, beyond
    65535 / ``scale``: 256 m for KITTI, 13.1 m for TUM) and non-finite depth become 0 (no value)."""
    import cv2

    depth_m = np.asarray(depth_m, dtype=np.float64)
    if depth_m.ndim != 2:
        raise DcslamError(f"depth has shape {depth_m.shape}, expected (H, W)")
    value = np.rint(np.nan_to_num(depth_m, nan=0.0, posinf=0.0, neginf=0.0) * scale)
    value[(value < 0) | (value > 65535)] = 0
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), value.astype(np.uint16)):
        raise DcslamError(f"could not write {path}")
    return Path(path)
