"""A drive's frames as SLAM takes them, read one at a time as they are used: the depth input (a depth kind of the
drive file or a layer file), its confidence, the colour image and the measured depth whose pixels are the ICP
sources. A run over the first N frames reads N frames, not the whole drive; a layer is checked against its drive
before the first frame (as :func:`dcslam.io.drive.read_layer_for`) and each frame's values as it is read."""
from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.io.chunks import FrameReader
from dcslam.io.drive import LAYER_SCHEMA, DriveFile, check_depth, is_depth_kind


@dataclass(frozen=True)
class DepthFrame:
    """One frame. Shapes: depth (H, W) float32 metres (0 = none), rgb (H, W, 3) uint8 or None (not read),
    confidence (H, W) in [0, 1] or None (the layer has none), sources (H, W) float32 metres or None (the depth serves
    as ICP sources)."""

    depth: np.ndarray
    rgb: np.ndarray | None
    confidence: np.ndarray | None = None
    sources: np.ndarray | None = None


@dataclass
class DriveFrames:
    """The first N frames of a drive: ``where`` (the file, for messages), ``name``, ``K`` (3, 3), the ground-truth
    ``T_world_cam`` (N, 4, 4), ``timestamps`` (N,), whether the depth has a ``confidence``, and ``frames``: an
    iterator of N :class:`DepthFrame`, each read when it is taken (one pass; valid while the file is open)."""

    where: str
    name: str
    K: np.ndarray
    T_world_cam: np.ndarray
    timestamps: np.ndarray
    has_confidence: bool
    frames: Iterator[DepthFrame]

    def __len__(self) -> int:
        return len(self.T_world_cam)


@contextlib.contextmanager
def drive_frames(path: Path | str, source: str | Path, frames: int | None = None,
                 sources_kind: str | None = None, colour: bool = True) -> Iterator[DriveFrames]:
    """The first ``frames`` frames (all if None) of the drive file ``path`` with depth from ``source`` (a depth kind
    the drive holds, e.g. ``dense`` or ``sparse@16``, or a layer file), and with ``sources_kind`` (a depth kind) the
    measured depth whose pixels are the ICP sources (None in each frame when ``source`` is that same kind).
    ``colour`` False: the frames' ``rgb`` is None, not read (a run whose map nobody sees: inflating a colour image
    is a tenth of a sparse frame's CPU)."""
    with DriveFile(path) as drive, contextlib.ExitStack() as stack:
        n = len(drive) if not frames else min(frames, len(drive))
        if n < 1:
            raise DcslamError(f"{path}: no frames")
        is_kind = not isinstance(source, Path) and is_depth_kind(str(source))
        if is_kind:
            depth_at, confidence_at = (lambda i: drive.depth(str(source), i)), None
        else:
            depth_at, confidence_at = stack.enter_context(layer_frames(drive, source))
        separate = sources_kind is not None and not (isinstance(source, str) and source == sources_kind)
        for kind in ([str(source)] if is_kind else []) + ([sources_kind] if separate else []):
            if kind not in drive.kinds:
                drive.depth(kind, 0)  # before any frame: its one-line error names the kinds the drive holds

        def read() -> Iterator[DepthFrame]:
            for i in range(n):
                yield DepthFrame(depth_at(i), drive.rgb(i) if colour else None,
                                 None if confidence_at is None else confidence_at(i),
                                 drive.depth(sources_kind, i) if separate else None)

        yield DriveFrames(str(path), drive.name, drive.K, drive.poses[:n].copy(), drive.timestamps[:n].copy(),
                          confidence_at is not None, read())


@contextlib.contextmanager
def layer_frames(drive: DriveFile, path: Path | str):
    """``(depth_at, confidence_at)`` of the layer file ``path`` of ``drive``: functions of a frame index returning
    (H, W) float32 (``confidence_at`` None for a layer without one). The layer is refused, as by
    :func:`dcslam.io.drive.read_layer_for`, when it is not a layer or was made for another drive; each frame's depth
    is checked (finite, >= 0) and its confidence (within [0, 1]) as it is read."""
    import h5py

    path = Path(path)
    if not path.exists():
        raise DcslamError(f"layer file {path} not found; run `dcslam predict` or `dcslam filter` first")
    try:
        h5 = h5py.File(path, "r")
    except OSError as exc:
        raise DcslamError(f"{path} is not a readable HDF5 layer file ({exc})") from None
    try:
        check_layer(h5, path, drive)
        depth = FrameReader(h5["depth"])
        confidence = FrameReader(h5["confidence"]) if "confidence" in h5 else None
        yield (lambda i: check_depth(depth(i), str(path), i)), (
            None if confidence is None else (lambda i: _confidence(confidence(i), path, i)))
    finally:
        h5.close()


def check_layer(h5, path: Path, drive: DriveFile) -> None:
    """A :class:`DcslamError` when the open layer file ``h5`` is no layer of ``drive`` (its shapes, drive name and
    frame ids), read without its frames."""
    if h5.attrs.get("schema") != LAYER_SCHEMA or "depth" not in h5:
        raise DcslamError(f"{path}: not a dcslam depth layer (schema {h5.attrs.get('schema')!r})")
    shape = h5["depth"].shape
    if len(shape) != 3:
        raise DcslamError(f"{path}: depth has shape {shape}, expected (N, H, W)")
    if "confidence" in h5 and h5["confidence"].shape != shape:
        raise DcslamError(f"{path}: confidence has shape {h5['confidence'].shape}, expected {shape} like its depth")
    frame_ids = h5["frame_ids"][()] if "frame_ids" in h5 else None
    if frame_ids is not None and np.shape(frame_ids) != (shape[0],):
        raise DcslamError(f"{path}: frame_ids of shape {np.shape(frame_ids)}, expected ({shape[0]},)")
    made_for = str(h5.attrs.get("drive", ""))
    fix = "run `dcslam predict` or `dcslam filter` for this drive (--force)"
    if made_for and made_for not in {drive.name, drive.path.name, drive.path.stem}:
        raise DcslamError(f"{path}: a layer of drive {made_for!r}, not of {drive.name!r} ({drive.path}); {fix}")
    if shape[0] != len(drive):
        raise DcslamError(f"{path}: layer has {shape[0]} frames but its drive has {len(drive)} ({drive.path}); {fix}")
    if shape[1:] != drive.shape[1:]:
        raise DcslamError(f"{path}: layer frames are {shape[1:]}, drive frames are {drive.shape[1:]} "
                          f"({drive.path}); {fix}")
    if frame_ids is not None and not np.array_equal(frame_ids, drive.frame_ids):
        i = int(np.flatnonzero(np.asarray(frame_ids) != drive.frame_ids)[0])
        raise DcslamError(f"{path}: layer frame {i} is KITTI frame {int(frame_ids[i])}, its drive's "
                          f"{int(drive.frame_ids[i])} ({drive.path}); {fix}")


def _confidence(values: np.ndarray, path: Path, i: int) -> np.ndarray:
    if not np.all(np.isfinite(values)) or np.any(values < 0) or np.any(values > 1):
        raise DcslamError(f"{path}: confidence of frame {i} must be finite and within [0, 1]")
    return values
