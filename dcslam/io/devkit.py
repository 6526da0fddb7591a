"""The KITTI depth-completion devkit's prediction files, as other methods (PENet, CompletionFormer, NLSPN, BP-Net,
LRRU, DySPN) save them and as the devkit's ``evaluate_depth`` reads them.

Each frame is a uint16 single-channel PNG, metres = value / 256, 0 = no depth (the devkit's ``depth_read``:
``png.astype(float) / 256``, ``png == 0`` → invalid). Two layouts:

``drive``   ``<root>/<drive>/proj_depth/<kind>/image_02/<frame:010d>.png`` (the benchmark's per-drive folders)
``index``   ``<root>/<i:010d>.png``, ``i`` the line of a list of ``(drive, frame)`` (the methods' test lists)

A list file holds one frame a line, either ``<drive> <frame>`` or a path that names the drive in one of its folders
and the frame in its file name (``.../2011_09_26_drive_0002_sync/proj_depth/velodyne_raw/image_02/0000000005.png``);
blank lines and lines starting with ``#`` are skipped. dcslam writes ``<drive> <frame:010d>``.
"""
from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from dcslam.constants import MIN_DEPTH_M
from dcslam.errors import DcslamError
from dcslam.io.kitti import DEPTH_SCALE, frame_name, read_depth_png

LAYOUTS = ("drive", "index")
CAMERA = "image_02"
MAX_VALUE = 65535


def drive_png(root: Path | str, drive: str, kind: str, frame_id: int) -> Path:
    """``<root>/<drive>/proj_depth/<kind>/image_02/<frame:010d>.png``."""
    return drive_folder(root, drive, kind) / frame_name(frame_id, ".png")


def drive_folder(root: Path | str, drive: str, kind: str) -> Path:
    """The folder of one drive's PNGs in the per-drive layout."""
    return Path(root) / drive / "proj_depth" / kind / CAMERA


def index_png(root: Path | str, index: int) -> Path:
    """``<root>/<index:010d>.png``."""
    return Path(root) / frame_name(index, ".png")


def read_list(path: Path | str, drives: Iterable[str]) -> list[tuple[str, int]]:
    """The ``(drive, frame)`` of each line of a list file, in order; a line that names none of ``drives`` or no frame
    number, or a frame listed twice, is a :class:`DcslamError` naming the file and line."""
    path = Path(path)
    if not path.is_file():
        raise DcslamError(f"list file {path} not found; pass --list with the ordered (drive, frame) list")
    known = set(drives)
    entries, seen = [], {}
    for number, raw in enumerate(path.read_text(errors="replace").splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        words = line.split()
        if len(words) == 2 and words[1].isdigit():
            drive, frame = words[0], words[1]
        else:
            parts = Path(line).parts
            drive = next((part for part in parts if part in known), None)
            frame = Path(line).stem
        if drive not in known:
            raise DcslamError(f"{path}:{number}: {line!r} names no drive of the workspace (expected '<drive> "
                              f"<frame>' or a path through one of {', '.join(sorted(known)) or 'no drives'})")
        if not frame.isdigit():
            raise DcslamError(f"{path}:{number}: {line!r} has no frame number (expected '<drive> <frame>' or a "
                              "file named <frame:010d>.png)")
        entry = (drive, int(frame))
        if entry in seen:
            raise DcslamError(f"{path}:{number}: frame {entry[1]} of {drive} is listed again (first at line "
                              f"{seen[entry]})")
        seen[entry] = number
        entries.append(entry)
    if not entries:
        raise DcslamError(f"{path}: the list names no frames")
    return entries


def list_text(entries: Iterable[tuple[str, int]]) -> str:
    """A list file's text: ``<drive> <frame:010d>`` a line."""
    return "".join(f"{drive} {int(frame):010d}\n" for drive, frame in entries)


def read_prediction(path: Path | str, height: int, width: int, offset: tuple[int, int] = (0, 0),
                    max_depth_m: float = 120.0) -> np.ndarray:
    """A devkit PNG → (H, W) float32 metres of a drive frame of ``height`` × ``width``, the file's pixels placed at
    ``offset`` (rows, columns: what a crop removed above and left of it) and 0 where it has none.

    Without an offset the file must be ``height`` × ``width``; with one it must fit. A depth below 0.1 m or beyond
    ``max_depth_m`` is refused (no KITTI sensor measures it: a wrong scale or a wrong file)."""
    path = Path(path)
    depth = read_depth_png(path)  # refuses missing, unreadable, 8-bit and multi-channel files
    top, left = offset
    h, w = depth.shape
    if offset == (0, 0) and (h, w) != (height, width):
        raise DcslamError(f"{path}: {h} × {w} pixels, its drive's frames are {height} × {width}; pass --crop "
                          "ROWS,COLUMNS if the method cropped them")
    if top + h > height or left + w > width:
        raise DcslamError(f"{path}: {h} × {w} pixels at offset ({top}, {left}) do not fit its drive's frames of "
                          f"{height} × {width}; check --crop")
    out_of_range = (depth > 0) & ((depth < MIN_DEPTH_M) | (depth > max_depth_m))
    if out_of_range.any():
        values = depth[out_of_range]
        raise DcslamError(f"{path}: {len(values)} pixels hold depths outside {MIN_DEPTH_M:g}-{max_depth_m:g} m "
                          f"({values.min():.3f} to {values.max():.3f} m); expected metres × {DEPTH_SCALE:g} "
                          "(pass --max-depth for a longer-range sensor)")
    placed = np.zeros((height, width), np.float32)
    placed[top:top + h, left:left + w] = depth
    return placed


def encode_prediction(depth_m: np.ndarray) -> bytes:
    """(H, W) metres → the bytes of a devkit PNG: value = round(256 · metres); holes (below 0.1 m, as everywhere
    in dcslam), non-finite depth and depth beyond 65535 / 256 m become 0."""
    import cv2

    depth_m = np.nan_to_num(np.asarray(depth_m, np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    if depth_m.ndim != 2:
        raise DcslamError(f"depth has shape {depth_m.shape}, expected (H, W)")
    value = np.rint(depth_m * DEPTH_SCALE)
    value[(depth_m < MIN_DEPTH_M) | (value > MAX_VALUE)] = 0
    done, encoded = cv2.imencode(".png", value.astype(np.uint16))
    if not done:
        raise DcslamError("could not encode a depth PNG")
    return encoded.tobytes()
