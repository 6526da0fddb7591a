"""PNG images, one codec each for every dataset: 16-bit depth (metres = value / ``scale``, 0 = no value) and 8-bit
colour (RGB in memory, BGR on disk as OpenCV writes it).

KITTI writes depth at ``scale`` 256 (:data:`dcslam.io.kitti.DEPTH_SCALE`), TUM RGB-D and ICL-NUIM at 5000
(:data:`dcslam.io.tum_rgbd.DEPTH_SCALE`).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.io.atomic import write_bytes_atomic


def _imread(path: Path, what: str, kind: str) -> np.ndarray:
    """The file's pixels as stored (OpenCV, unchanged), or a :class:`DcslamError` naming ``what`` was missing or
    unreadable."""
    import cv2

    if not path.exists():
        raise DcslamError(f"{what} {path} not found")
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise DcslamError(f"{path}: not a readable {kind} (truncated or corrupt?)")
    return image


def read_depth_png(path: Path | str, scale: float) -> np.ndarray:
    """A 16-bit single-channel PNG → (H, W) float32 metres (value / ``scale``, 0 = no value).

    Fails on missing, unreadable (truncated, corrupt) and 8-bit or multi-channel files.
    """
    path = Path(path)
    image = _imread(path, "depth PNG", "PNG")
    if image.dtype != np.uint16 or image.ndim != 2:
        raise DcslamError(f"{path}: expected a 16-bit single-channel depth PNG (metres = value / {scale:g}), got "
                          f"{image.dtype} with shape {image.shape}")
    return image.astype(np.float32) / np.float32(scale)


def _write_png(path: Path | str, image: np.ndarray, params: list[int]) -> Path:
    """Encode ``image`` as PNG in memory, then write the bytes atomically: ``cv2.imwrite`` only returns False (and
    libpng prints to stderr), where a file write names the reason ("no space left on device")."""
    import cv2

    ok, encoded = cv2.imencode(".png", image, params)
    if not ok:
        raise DcslamError(f"could not encode {path} as PNG (image of shape {image.shape}, {image.dtype})")
    return write_bytes_atomic(path, encoded.tobytes())


def write_depth_png(path: Path | str, depth_m: np.ndarray, scale: float) -> Path:
    """(H, W) metres → 16-bit PNG, value = round(``scale`` · metres). Depth that does not fit (negative, beyond
    65535 / ``scale``: 256 m for KITTI, 13.1 m for TUM) and non-finite depth become 0 (no value). Written
    atomically; a failed write is one :class:`DcslamError` line naming the file and the reason."""
    depth_m = np.asarray(depth_m, dtype=np.float64)
    if depth_m.ndim != 2:
        raise DcslamError(f"depth has shape {depth_m.shape}, expected (H, W)")
    value = np.rint(np.nan_to_num(depth_m, nan=0.0, posinf=0.0, neginf=0.0) * scale)
    value[(value < 0) | (value > 65535)] = 0
    return _write_png(path, value.astype(np.uint16), [])


def read_rgb_png(path: Path | str) -> np.ndarray:
    """An 8-bit colour (or grey, or RGBA) image → (H, W, 3) uint8 RGB. Fails on missing, unreadable and 16-bit files."""
    import cv2

    path = Path(path)
    image = _imread(path, "colour image", "image")
    if image.dtype != np.uint8:
        raise DcslamError(f"{path}: expected an 8-bit colour image, got {image.dtype} with shape {image.shape}")
    if image.ndim == 2:
        return np.repeat(image[..., None], 3, axis=2)
    if image.ndim == 3 and image.shape[2] in (3, 4):
        return cv2.cvtColor(image[..., :3], cv2.COLOR_BGR2RGB)
    raise DcslamError(f"{path}: expected an 8-bit colour image, got shape {image.shape}")


def write_rgb_png(path: Path | str, rgb: np.ndarray, compression: int | None = None) -> Path:
    """(H, W, 3) uint8 RGB → PNG; ``compression`` 0-9 (default OpenCV's, 1 is fast) changes the bytes, not the
    pixels. Written atomically; a failed write is one :class:`DcslamError` line naming the file and the reason."""
    import cv2

    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise DcslamError(f"image has shape {rgb.shape} and dtype {rgb.dtype}, expected (H, W, 3) uint8")
    params = [] if compression is None else [cv2.IMWRITE_PNG_COMPRESSION, int(compression)]
    return _write_png(path, cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), params)
