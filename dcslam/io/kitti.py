"""KITTI raw ("sync") and KITTI depth-completion files: readers and writers of the file formats.

Layout under a KITTI root (real, or written by ``dcslam synth``)::

    raw/<date>/calib_cam_to_cam.txt, calib_velo_to_cam.txt, calib_imu_to_velo.txt
    raw/<date>/<date>_drive_<NNNN>_sync/image_02/data/<frame:010d>.png, image_02/timestamps.txt
    raw/<date>/<date>_drive_<NNNN>_sync/oxts/data/<frame:010d>.txt, oxts/timestamps.txt
    raw/<date>/<date>_drive_<NNNN>_sync/velodyne_points/data/<frame:010d>.bin, velodyne_points/timestamps.txt
    depth_completion/{train,val}/<date>_drive_<NNNN>_sync/proj_depth/{velodyne_raw,groundtruth}/image_02/<frame:010d>.png
"""
from __future__ import annotations

from datetime import datetime
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError

DEPTH_SCALE = 256.0  # uint16 depth PNG: metres = value / 256, 0 = no value


def frame_name(frame_id: int, suffix: str) -> str:
    """KITTI file name of a frame: ``0000000005.png``."""
    return f"{int(frame_id):010d}{suffix}"


def read_depth_png(path: Path | str) -> np.ndarray:
    """A KITTI uint16 depth PNG → (H, W) float32 metres (0 = no value). Fails on 8-bit or unreadable files."""
    import cv2

    path = Path(path)
    if not path.exists():
        raise DcslamError(f"depth PNG {path} not found")
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise DcslamError(f"{path}: not a readable PNG (truncated or corrupt?)")
    if image.dtype != np.uint16 or image.ndim != 2:
        raise DcslamError(f"{path}: expected a 16-bit single-channel depth PNG, got {image.dtype} with shape "
                          f"{image.shape}")
    return image.astype(np.float32) / DEPTH_SCALE


def write_depth_png(path: Path | str, depth_m: np.ndarray) -> None:
    """(H, W) metres → KITTI uint16 depth PNG (value = round(256 · metres), clipped to 0..65535)."""
    import cv2

    depth_m = np.asarray(depth_m)
    if depth_m.ndim != 2:
        raise DcslamError(f"depth has shape {depth_m.shape}, expected (H, W)")
    value = np.clip(np.rint(np.nan_to_num(depth_m, nan=0.0) * DEPTH_SCALE), 0, 65535).astype(np.uint16)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), value):
        raise DcslamError(f"could not write {path}")


def read_image(path: Path | str) -> np.ndarray:
    """A KITTI colour PNG → (H, W, 3) uint8 RGB."""
    import cv2

    path = Path(path)
    if not path.exists():
        raise DcslamError(f"image {path} not found")
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise DcslamError(f"{path}: not a readable image (truncated or corrupt?)")
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def write_image(path: Path | str, rgb: np.ndarray) -> None:
    """(H, W, 3) uint8 RGB → PNG."""
    import cv2

    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise DcslamError(f"image has shape {rgb.shape} and dtype {rgb.dtype}, expected (H, W, 3) uint8")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)):
        raise DcslamError(f"could not write {path}")


def read_velodyne(path: Path | str) -> np.ndarray:
    """A Velodyne ``.bin`` scan → (N, 4) float32 (x, y, z in metres in the Velodyne frame, reflectance)."""
    path = Path(path)
    if not path.exists():
        raise DcslamError(f"Velodyne scan {path} not found")
    data = np.fromfile(path, dtype=np.float32)
    if data.size % 4:
        raise DcslamError(f"{path}: {data.size * 4} bytes is not a whole number of (x, y, z, r) float32 points")
    return data.reshape(-1, 4)


def write_velodyne(path: Path | str, points: np.ndarray) -> None:
    """(N, 4) x, y, z, reflectance → Velodyne ``.bin`` (float32, little-endian)."""
    points = np.asarray(points)
    if points.ndim != 2 or points.shape[1] != 4:
        raise DcslamError(f"scan has shape {points.shape}, expected (N, 4)")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    points.astype("<f4").tofile(path)


def read_timestamps(path: Path | str) -> np.ndarray:
    """A KITTI ``timestamps.txt`` (``2011-09-26 13:02:25.964389445`` per line) → (N,) float64 POSIX seconds.

    The nanosecond digits are kept: whole seconds from the date, the fraction parsed separately.
    """
    path = Path(path)
    if not path.exists():
        raise DcslamError(f"timestamps file {path} not found")
    stamps = []
    for number, line in enumerate(path.read_text().splitlines(), 1):
        line = line.strip()
        if not line:
            continue
        try:
            whole, _, fraction = line.partition(".")
            seconds = datetime.strptime(whole, "%Y-%m-%d %H:%M:%S").replace(
                tzinfo=__import__("datetime").timezone.utc).timestamp()
            stamps.append(seconds + (float("0." + fraction) if fraction else 0.0))
        except ValueError:
            raise DcslamError(f"{path}:{number}: expected 'YYYY-MM-DD HH:MM:SS.fffffffff', got {line!r}") from None
    return np.array(stamps, dtype=np.float64)


def write_timestamps(path: Path | str, seconds: np.ndarray) -> None:
    """(N,) POSIX seconds (UTC) → KITTI ``timestamps.txt`` with nanosecond digits."""
    from datetime import timezone

    lines = []
    for s in np.asarray(seconds, dtype=np.float64):
        whole = int(np.floor(s))
        nanos = int(round((s - whole) * 1e9))
        if nanos >= 1_000_000_000:
            whole, nanos = whole + 1, nanos - 1_000_000_000
        lines.append(datetime.fromtimestamp(whole, tz=timezone.utc).strftime("%Y-%m-%d %H:%M:%S") + f".{nanos:09d}")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text("\n".join(lines) + "\n")
