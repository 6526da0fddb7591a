"""The dcslam drive file (``drives/<drive>.h5``) and depth-layer files (predictions, filtered depth).

Drive file, schema ``dcslam.drive/1``:

============  =========================  ===========================================================
dataset       shape, dtype               meaning
============  =========================  ===========================================================
rgb           (N, H, W, 3) uint8         left colour camera (KITTI ``image_02``), rectified
depth/sparse  (N, H, W) float32          projected LiDAR in metres, 0 = no measurement
depth/dense   (N, H, W) float32          annotated ("ground-truth") depth in metres, 0 = none
T_world_cam   (N, 4, 4) float64          pose of camera 2; world = camera 2 at the first frame
K             (3, 3) float64             intrinsics of rectified camera 2
timestamps    (N,) float64               seconds
frame_ids     (N,) int64                 KITTI frame numbers
============  =========================  ===========================================================

Root attributes: ``schema``, ``source`` (``kitti`` | ``synthetic`` | ``tum``), ``date``, ``drive``, ``split``.
Images are chunked one frame per chunk and compressed, so reading frame i reads only frame i.

Optional depth datasets, (N, H, W) float32 metres, 0 = none, each read as a depth kind of its own:

=================  ==============  ==============================================================================
dataset            kind            meaning
=================  ==============  ==============================================================================
depth/sparse_<B>   ``sparse@<B>``  the scans cut to ``B`` of the 64 lasers (:mod:`dcslam.geometry.lidar_beams`),
                                   projected as ``velodyne_raw`` is; dataset attribute ``beams`` = B
depth/exact        ``exact``       noise-free depth of every pixel (generated drives only); attribute
                                   ``synthetic_only`` = True
=================  ==============  ==============================================================================

With ``depth/sparse_<B>`` datasets the root attribute ``sparse_beams`` lists their beam counts (int array).

Layer file, schema ``dcslam.layer/1``: dataset ``depth`` (N, H, W) float32 metres (0 = none, never NaN) and root
attributes ``schema``, ``drive`` (the drive file's name), ``made_by`` (a run or filter name) and ``config`` (JSON).
Optionally a dataset ``confidence`` (N, H, W) float32 in [0, 1] beside ``depth``: how sure the completer that made
the layer is of each pixel (confidence-aware completers such as ``nconv``); layers without it still read.
"""
from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.io.atomic import WriteSink, atomic_output
from dcslam.io.chunks import FrameReader

DRIVE_SCHEMA = "dcslam.drive/1"
LAYER_SCHEMA = "dcslam.layer/1"
DEPTH_KINDS = ("sparse", "dense")
"""The depth every drive file holds; :func:`depth_dataset` names the optional ones (``sparse@<B>``, ``exact``)."""
EXACT = "exact"


def depth_dataset(kind: str) -> str:
    """The dataset of a depth kind: ``sparse`` → ``depth/sparse``, ``sparse@16`` → ``depth/sparse_16``,
    ``exact`` → ``depth/exact``. Raises :class:`DcslamError` on any other name."""
    if kind in DEPTH_KINDS or kind == EXACT:
        return f"depth/{kind}"
    base, at, beams = kind.partition("@")
    if base == "sparse" and at and beams.isdigit() and int(beams) > 0:
        return f"depth/sparse_{int(beams)}"
    raise DcslamError(f"unknown depth kind {kind!r}; expected sparse, dense, exact or sparse@<beams> (e.g. sparse@16)")


def is_depth_kind(kind: str) -> bool:
    """True when ``kind`` names depth held in drive files (see :func:`depth_dataset`)."""
    try:
        depth_dataset(str(kind))
    except DcslamError:
        return False
    return True


def _beams_of(kind: str) -> int | None:
    base, at, beams = kind.partition("@")
    return int(beams) if at else None


def input_beams(kind: str) -> int | None:
    """LiDAR beams behind a depth kind: 64 for ``sparse`` (KITTI's HDL-64E), B for ``sparse@B``, else None."""
    depth_dataset(kind)
    return 64 if kind == "sparse" else _beams_of(kind)


def check_input_kind(kind: str) -> str:
    """``kind`` if it names depth held in drive files (a network's input or target), else :class:`DcslamError`."""
    depth_dataset(kind)
    return kind
_COMPRESSION = dict(compression="gzip", compression_opts=1, shuffle=True)


@dataclass(frozen=True)
class DriveFrame:
    """One frame of a drive. Shapes: rgb (H, W, 3) uint8, sparse and dense (H, W) float32 metres,
    T_world_cam (4, 4) float64; ``extra`` maps optional depth kinds (``sparse@16``, ``exact``) to (H, W) depth."""

    rgb: np.ndarray
    sparse: np.ndarray
    dense: np.ndarray
    T_world_cam: np.ndarray
    timestamp: float
    frame_id: int
    extra: dict[str, np.ndarray] = field(default_factory=dict)


def _check_depth(name: str, frame_id: int, depth: np.ndarray, height: int, width: int) -> None:
    if depth.shape != (height, width):
        raise DcslamError(f"frame {frame_id}: {name} has shape {depth.shape}, expected {(height, width)}")
    if not np.all(np.isfinite(depth)) or np.any(depth < 0):
        raise DcslamError(f"frame {frame_id}: {name} depth must be finite and >= 0 (0 = no value)")


def _check_frame(frame: DriveFrame, height: int, width: int, extra: tuple[str, ...] = ()) -> None:
    expect = {"rgb": ((height, width, 3), np.uint8), "sparse": ((height, width), None),
              "dense": ((height, width), None), "T_world_cam": ((4, 4), None)}
    for name, (shape, dtype) in expect.items():
        value = np.asarray(getattr(frame, name))
        if value.shape != shape:
            raise DcslamError(f"frame {frame.frame_id}: {name} has shape {value.shape}, expected {shape}")
        if dtype is not None and value.dtype != dtype:
            raise DcslamError(f"frame {frame.frame_id}: {name} has dtype {value.dtype}, expected {np.dtype(dtype)}")
    for name in DEPTH_KINDS:
        _check_depth(name, frame.frame_id, np.asarray(getattr(frame, name)), height, width)
    from dcslam.io.validate import check_poses

    check_poses(np.asarray(frame.T_world_cam, np.float64)[None], f"frame {frame.frame_id}: T_world_cam")
    if set(frame.extra) != set(extra):
        raise DcslamError(f"frame {frame.frame_id}: holds depth {sorted(frame.extra)}, the drive file expects "
                          f"{sorted(extra)}")
    for name in extra:
        _check_depth(name, frame.frame_id, np.asarray(frame.extra[name]), height, width)


class DriveWriter:
    """Write a drive file frame by frame, atomically (the file appears under its name only when closed cleanly).
    A write that fails (a full disk, an I/O error) ends in one :class:`DcslamError` line naming the file and the
    reason, with the partial file removed (HDF5 writes through a :class:`~dcslam.io.atomic.WriteSink`, so a failed
    write never leaves a file that cannot be closed).

    >>> with DriveWriter(path, K, height, width, source="synthetic", date="2011_09_26", drive="...") as w:
    ...     for frame in frames:
    ...         w.append(frame)

    ``extra`` names the optional depth kinds (``sparse@16``, ``exact``) every frame brings in ``frame.extra``.
    """

    def __init__(self, path: Path | str, K: np.ndarray, height: int, width: int, *, source: str, date: str,
                 drive: str, split: str = "", force: bool = False, attrs: dict | None = None,
                 extra: tuple[str, ...] = ()):
        from dcslam.io.validate import check_intrinsics

        K = check_intrinsics(K, f"{path}")
        self.path, self.K, self.height, self.width = Path(path), K, int(height), int(width)
        self.attrs = dict(schema=DRIVE_SCHEMA, source=source, date=date, drive=drive, split=split, **(attrs or {}))
        self.force = force
        self.extra = tuple(extra)
        for kind in self.extra:
            if kind in DEPTH_KINDS:
                raise DcslamError(f"{kind} is always written; it is no extra depth kind")
            depth_dataset(kind)
        if len(set(self.extra)) != len(self.extra):
            raise DcslamError(f"extra depth kinds {list(self.extra)} repeat a name")
        beams = sorted((_beams_of(k) for k in self.extra if _beams_of(k)), reverse=True)
        if beams:
            self.attrs["sparse_beams"] = np.array(beams, np.int64)
        self._frames: list[tuple[np.ndarray, float, int]] = []

    def __enter__(self) -> "DriveWriter":
        import h5py

        self._atomic = atomic_output(self.path, force=self.force)
        tmp = self._atomic.__enter__()
        self._h5 = self._sink = None
        try:
            self._sink = WriteSink(tmp)
            self._h5 = h5py.File(self._sink, "w")
            h, w = self.height, self.width
            self._rgb = self._h5.create_dataset("rgb", (0, h, w, 3), np.uint8, maxshape=(None, h, w, 3),
                                                chunks=(1, h, w, 3), **_COMPRESSION)
            self._depth = {kind: self._h5.create_dataset(f"depth/{kind}", (0, h, w), np.float32,
                                                         maxshape=(None, h, w), chunks=(1, h, w), **_COMPRESSION)
                           for kind in DEPTH_KINDS}
            for kind in self.extra:
                dataset = self._h5.create_dataset(depth_dataset(kind), (0, h, w), np.float32, maxshape=(None, h, w),
                                                  chunks=(1, h, w), **_COMPRESSION)
                if _beams_of(kind):
                    dataset.attrs["beams"] = _beams_of(kind)
                else:
                    dataset.attrs["synthetic_only"] = True
                self._depth[kind] = dataset
        except BaseException as exc:
            self._discard()
            self._atomic.__exit__(type(exc), exc, exc.__traceback__)
            raise
        return self

    def _discard(self) -> None:
        """Close the HDF5 file and its sink whatever state a failure left them in (the file is removed next)."""
        for part in (self._h5, self._sink):
            if part is not None:
                try:
                    part.close()
                except Exception:  # noqa: BLE001  (the file is being thrown away; the first error is raised)
                    pass

    def append(self, frame: DriveFrame) -> None:
        _check_frame(frame, self.height, self.width, self.extra)
        n = len(self._frames)
        self._rgb.resize(n + 1, axis=0)
        self._rgb[n] = frame.rgb
        for kind in (*DEPTH_KINDS, *self.extra):
            self._depth[kind].resize(n + 1, axis=0)
            depth = frame.extra[kind] if kind in self.extra else getattr(frame, kind)
            self._depth[kind][n] = np.asarray(depth, dtype=np.float32)
        self._frames.append((np.asarray(frame.T_world_cam, np.float64), float(frame.timestamp), int(frame.frame_id)))
        self._sink.raise_error(self.path)  # stop at the first failed write, not after the whole drive

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            if exc_type is None:
                if not self._frames:
                    raise DcslamError(f"{self.path}: no frames to write")
                self._h5.create_dataset("T_world_cam", data=np.stack([f[0] for f in self._frames]))
                self._h5.create_dataset("K", data=self.K)
                self._h5.create_dataset("timestamps", data=np.array([f[1] for f in self._frames], np.float64))
                self._h5.create_dataset("frame_ids", data=np.array([f[2] for f in self._frames], np.int64))
                for key, value in self.attrs.items():
                    self._h5.attrs[key] = value
            self._h5.close()
            self._sink.close()
            if exc_type is None:
                self._sink.raise_error(self.path)
        except BaseException as error:
            self._discard()
            self._atomic.__exit__(type(error), error, error.__traceback__)
            raise
        self._atomic.__exit__(exc_type, exc, tb)


def _check_dims(path: Path, h5, names: tuple[str, ...], ndim: int) -> None:
    for name in names:
        if h5[name].ndim < ndim:
            raise DcslamError(f"{path}: {name} has shape {h5[name].shape}, expected (N, H, W...)")


def _agreed(path: Path, sizes: dict, what: str):
    """The size most datasets agree on; a :class:`DcslamError` naming the dataset(s) that differ."""
    from collections import Counter

    common, _ = Counter(sizes.values()).most_common(1)[0]
    odd = [f"{name} has {size}" for name, size in sizes.items() if size != common]
    if odd:
        raise DcslamError(f"{path}: {', '.join(odd)} {what} where the other datasets have {common}; remake the "
                          "drive file with `dcslam prepare-kitti --force`")
    return common


def check_depth(depth: np.ndarray, source: str, first_frame: int = 0) -> np.ndarray:
    """``depth`` (H, W) or (N, H, W) if every value is finite and >= 0 (0 = no value); else a :class:`DcslamError`
    naming ``source`` and the first bad frame (``first_frame`` is the index of ``depth``'s first frame)."""
    depth = np.asarray(depth)
    if depth.dtype.kind != "f":
        raise DcslamError(f"{source}: depth has dtype {depth.dtype}, expected float32 metres")
    if depth.size and depth.min() >= 0 and depth.max() < np.inf:   # two passes, no temporaries: the common case
        return depth
    bad = ~np.isfinite(depth) | (depth < 0)
    if bad.any():
        frames = bad.reshape(-1, *depth.shape[-2:]).any(axis=(1, 2))
        i = int(np.argmax(frames))
        values = depth.reshape(-1, *depth.shape[-2:])[i][bad.reshape(-1, *depth.shape[-2:])[i]]
        kinds = [k for k, hit in (("NaN", np.isnan(values).any()), ("infinite", np.isinf(values).any()),
                                  ("negative", (values < 0).any())) if hit]
        raise DcslamError(f"{source}: frame {first_frame + i} holds {' and '.join(kinds)} depths ({len(values)} "
                          "pixels); depth must be finite and >= 0 (0 = no value): remake the file")
    return depth


class DriveFile:
    """Read a drive file lazily: ``len(drive)``, ``drive.frame(i)``, ``drive.depth("dense", i)``, ``drive.poses``.

    Use as a context manager, or call :meth:`close`.
    """

    REQUIRED = ("rgb", "depth/sparse", "depth/dense", "T_world_cam", "K", "timestamps", "frame_ids")

    def __init__(self, path: Path | str):
        import h5py

        self.path = Path(path)
        if not self.path.exists():
            raise DcslamError(f"drive file {self.path} not found; run `dcslam prepare-kitti` first")
        try:
            self._h5 = h5py.File(self.path, "r")
        except OSError as exc:
            raise DcslamError(f"{self.path} is not a readable HDF5 drive file ({exc})") from None
        try:
            self._validate()
        except BaseException:
            self._h5.close()
            raise
        self.K = self._h5["K"][()]
        self.poses = self._h5["T_world_cam"][()]
        self.timestamps = self._h5["timestamps"][()]
        self.frame_ids = self._h5["frame_ids"][()]
        self.attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in self._h5.attrs.items()}
        self._readers: dict[str, FrameReader] = {}

    def _validate(self) -> None:
        h5 = self._h5
        schema = h5.attrs.get("schema")
        if schema != DRIVE_SCHEMA:
            raise DcslamError(f"{self.path}: schema is {schema!r}, expected {DRIVE_SCHEMA!r}")
        missing = [name for name in self.REQUIRED if name not in h5]
        if missing:
            raise DcslamError(f"{self.path}: missing dataset(s) {', '.join(missing)}")
        _check_dims(self.path, h5, ("rgb", "depth/sparse", "depth/dense"), 3)
        framed = ("rgb", "depth/sparse", "depth/dense", "T_world_cam", "timestamps", "frame_ids")
        n = _agreed(self.path, {name: h5[name].shape[0] for name in framed}, "frames")
        h, w = _agreed(self.path, {name: h5[name].shape[1:3] for name in framed[:3]}, "rows × columns")
        expect = {"rgb": (n, h, w, 3), "depth/sparse": (n, h, w), "T_world_cam": (n, 4, 4), "K": (3, 3),
                  "timestamps": (n,), "frame_ids": (n,)}
        for name, shape in expect.items():
            if h5[name].shape != shape:
                raise DcslamError(f"{self.path}: {name} has shape {h5[name].shape}, expected {shape}")
        if h5["rgb"].dtype != np.uint8:
            raise DcslamError(f"{self.path}: rgb has dtype {h5['rgb'].dtype}, expected uint8")
        for name in ("depth/sparse", "depth/dense", "T_world_cam", "K", "timestamps"):
            if h5[name].dtype.kind != "f":
                raise DcslamError(f"{self.path}: {name} has dtype {h5[name].dtype}, expected floating point")
        for name in ("T_world_cam", "K", "timestamps"):
            bad = np.flatnonzero(~np.isfinite(h5[name][()]).reshape(len(h5[name]), -1).all(axis=1))
            if len(bad):
                where = "" if name == "K" else f" at frame {bad[0]}" + (f" (and {len(bad) - 1} more)" if len(bad) > 1
                                                                       else "")
                raise DcslamError(f"{self.path}: {name} is not finite{where}; remake the drive file with "
                                  "`dcslam prepare-kitti --force`")
        from dcslam.io.validate import check_intrinsics, check_poses

        fix = "; remake the drive file with `dcslam prepare-kitti --force`"
        for check, name in ((check_intrinsics, "K"), (check_poses, "T_world_cam")):
            try:
                check(h5[name][()], f"{self.path}: {name}")
            except DcslamError as error:
                raise DcslamError(f"{error}{fix}") from None
        declared = sorted(int(b) for b in np.atleast_1d(h5.attrs.get("sparse_beams", [])))
        for kind in self._extra_kinds():
            dataset = h5[depth_dataset(kind)]
            if dataset.shape != (n, h, w):
                raise DcslamError(f"{self.path}: {dataset.name} has shape {dataset.shape}, expected {(n, h, w)}")
            recorded = dataset.attrs.get("beams")
            if _beams_of(kind) is not None and recorded != _beams_of(kind):
                recorded = int(recorded) if isinstance(recorded, (int, np.integer)) else recorded
                raise DcslamError(f"{self.path}: {dataset.name} records beams={recorded!r}, "
                                  f"expected {_beams_of(kind)}; rerun `dcslam prepare-kitti --force`")
        found = sorted(_beams_of(k) for k in self._extra_kinds() if _beams_of(k) is not None)
        if found != declared:
            raise DcslamError(f"{self.path}: attribute sparse_beams is {declared} but the file holds sparse depth "
                              f"of {found} beams; rerun `dcslam prepare-kitti --force`")

    def _extra_kinds(self) -> list[str]:
        group = self._h5["depth"]
        kinds = []
        for name in group:
            if name in DEPTH_KINDS:
                continue
            kind = EXACT if name == EXACT else f"sparse@{name.removeprefix('sparse_')}"
            if not (name == EXACT or name.startswith("sparse_")) or not is_depth_kind(kind):
                raise DcslamError(f"{self.path}: unknown depth dataset depth/{name}")
            kinds.append(kind)
        return kinds

    @property
    def kinds(self) -> tuple[str, ...]:
        """The depth kinds this file holds: ``sparse``, ``dense``, then e.g. ``sparse@16``, ``exact``."""
        return (*DEPTH_KINDS, *self._extra_kinds())

    @property
    def name(self) -> str:
        return self.attrs.get("drive") or self.path.stem

    @property
    def shape(self) -> tuple[int, int, int]:
        """(N, H, W)."""
        return tuple(self._h5["depth/dense"].shape)

    def __len__(self) -> int:
        return self.shape[0]

    def rgb(self, i: int) -> np.ndarray:
        """(H, W, 3) uint8."""
        return self._frame("rgb", i)

    def _frame(self, name: str, i: int) -> np.ndarray:
        """Frame ``i`` of dataset ``name``, as ``self._h5[name][i]`` (:class:`~dcslam.io.chunks.FrameReader`)."""
        if name not in self._readers:
            self._readers[name] = FrameReader(self._h5[name])
        return self._readers[name](i)

    def depth(self, kind: str, i: int) -> np.ndarray:
        """(H, W) float32 metres of ``kind`` (``sparse``, ``dense``, ``sparse@<beams>`` or ``exact``)."""
        name = depth_dataset(kind)
        if name not in self._h5:
            how = ("it is written for generated drives only (`dcslam synth`, then `dcslam prepare-kitti`)"
                   if kind == EXACT else f"rerun `dcslam prepare-kitti --beams {_beams_of(kind)} --force`")
            raise DcslamError(f"{self.path} holds no {kind} depth (it has {', '.join(self.kinds)}); {how}")
        return check_depth(self._frame(name, i), f"{self.path}: {name}", i)

    def frame(self, i: int) -> DriveFrame:
        return DriveFrame(rgb=self.rgb(i), sparse=self.depth("sparse", i), dense=self.depth("dense", i),
                          T_world_cam=self.poses[i], timestamp=float(self.timestamps[i]),
                          frame_id=int(self.frame_ids[i]), extra={k: self.depth(k, i) for k in self._extra_kinds()})

    def __iter__(self) -> Iterator[DriveFrame]:
        for i in range(len(self)):
            yield self.frame(i)

    def close(self) -> None:
        self._h5.close()

    def __enter__(self) -> "DriveFile":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@dataclass
class Layer:
    """A depth layer: ``depth`` (N, H, W) float32 metres (0 = none) with its provenance, optionally the
    completer's ``confidence`` (N, H, W) float32 in [0, 1], and the ``frame_ids`` (N,) of the drive frames it was
    made from (layers written before they were recorded have none)."""

    depth: np.ndarray
    drive: str
    made_by: str
    config: dict = field(default_factory=dict)
    confidence: np.ndarray | None = None
    frame_ids: np.ndarray | None = None


def _check_confidence(confidence: np.ndarray, shape: tuple, where: str) -> None:
    if confidence.shape != shape:
        raise DcslamError(f"{where}confidence has shape {confidence.shape}, expected {shape} like its depth")
    if not np.all(np.isfinite(confidence)) or np.any(confidence < 0) or np.any(confidence > 1):
        raise DcslamError(f"{where}confidence must be finite and within [0, 1]")


def write_layer(path: Path | str, layer: Layer, force: bool = False) -> Path:
    """Write a layer file atomically. Raises :class:`DcslamError` on NaN/negative depth or an existing file, and
    for a failed write (one line naming the file and the reason; the partial file removed)."""
    import h5py

    depth = np.asarray(layer.depth)
    if depth.ndim != 3:
        raise DcslamError(f"layer depth has shape {depth.shape}, expected (N, H, W)")
    if not np.all(np.isfinite(depth)) or np.any(depth < 0):
        raise DcslamError("layer depth must be finite and >= 0 (0 = no value)")
    n, h, w = depth.shape
    confidence = None if layer.confidence is None else np.asarray(layer.confidence)
    if confidence is not None:
        _check_confidence(confidence, depth.shape, "layer ")
    frame_ids = None if layer.frame_ids is None else np.asarray(layer.frame_ids, np.int64)
    if frame_ids is not None and frame_ids.shape != (n,):
        raise DcslamError(f"layer frame_ids have shape {frame_ids.shape}, expected ({n},) like its depth")
    with atomic_output(path, force=force) as tmp, WriteSink(tmp) as sink:
        with h5py.File(sink, "w") as h5:
            h5.create_dataset("depth", data=depth.astype(np.float32), chunks=(1, h, w), **_COMPRESSION)
            if confidence is not None:
                h5.create_dataset("confidence", data=confidence.astype(np.float32), chunks=(1, h, w),
                                  **_COMPRESSION)
            if frame_ids is not None:
                h5.create_dataset("frame_ids", data=frame_ids)
            h5.attrs["schema"] = LAYER_SCHEMA
            h5.attrs["drive"] = layer.drive
            h5.attrs["made_by"] = layer.made_by
            h5.attrs["config"] = json.dumps(layer.config, default=str)
        sink.close()
        sink.raise_error(path)
    return Path(path)


def read_layer(path: Path | str, expect_frames: int | None = None) -> Layer:
    """Read a whole layer file; ``expect_frames`` checks its frame count against its drive's."""
    import h5py

    path = Path(path)
    if not path.exists():
        raise DcslamError(f"layer file {path} not found; run `dcslam predict` or `dcslam filter` first")
    try:
        with h5py.File(path, "r") as h5:
            if h5.attrs.get("schema") != LAYER_SCHEMA or "depth" not in h5:
                raise DcslamError(f"{path}: not a dcslam depth layer (schema {h5.attrs.get('schema')!r})")
            depth = h5["depth"][()]
            confidence = h5["confidence"][()] if "confidence" in h5 else None
            frame_ids = h5["frame_ids"][()] if "frame_ids" in h5 else None
            layer = Layer(depth=depth, drive=str(h5.attrs.get("drive", "")), made_by=str(h5.attrs.get("made_by", "")),
                          config=json.loads(h5.attrs.get("config", "{}")), confidence=confidence,
                          frame_ids=frame_ids)
    except OSError as exc:
        raise DcslamError(f"{path} is not a readable HDF5 layer file ({exc})") from None
    if depth.ndim != 3:
        raise DcslamError(f"{path}: depth has shape {depth.shape}, expected (N, H, W)")
    check_depth(depth, str(path))
    if confidence is not None:
        _check_confidence(confidence, depth.shape, f"{path}: ")
    if frame_ids is not None and np.shape(frame_ids) != (depth.shape[0],):
        raise DcslamError(f"{path}: frame_ids of shape {np.shape(frame_ids)}, expected ({depth.shape[0]},)")
    if expect_frames is not None and depth.shape[0] != expect_frames:
        raise DcslamError(f"{path}: layer has {depth.shape[0]} frames but its drive has {expect_frames}")
    return layer


def read_layer_for(drive: "DriveFile", path: Path | str) -> Layer:
    """Read the layer file ``path`` for ``drive``, refused (:class:`DcslamError`) when it was made for another
    drive: its ``drive`` attribute names another drive, or its frame count, image size or frame ids differ from the
    drive's (a layer of another drive saved under this drive's name would otherwise be scored or mapped)."""
    layer = read_layer(path)
    names = {drive.name, drive.path.name, drive.path.stem}
    fix = "run `dcslam predict` or `dcslam filter` for this drive (--force)"
    if layer.drive and layer.drive not in names:
        raise DcslamError(f"{path}: a layer of drive {layer.drive!r}, not of {drive.name!r} ({drive.path}); {fix}")
    if layer.depth.shape[0] != len(drive):
        raise DcslamError(f"{path}: layer has {layer.depth.shape[0]} frames but its drive has {len(drive)} "
                          f"({drive.path}); {fix}")
    if layer.depth.shape[1:] != drive.shape[1:]:
        raise DcslamError(f"{path}: layer frames are {layer.depth.shape[1:]}, drive frames are {drive.shape[1:]} "
                          f"({drive.path}); {fix}")
    if layer.frame_ids is not None and not np.array_equal(layer.frame_ids, drive.frame_ids):
        i = int(np.flatnonzero(np.asarray(layer.frame_ids) != drive.frame_ids)[0])
        raise DcslamError(f"{path}: layer frame {i} is KITTI frame {int(layer.frame_ids[i])}, its drive's "
                          f"{int(drive.frame_ids[i])} ({drive.path}); {fix}")
    return layer


def load_depth(drive: DriveFile, source: str | Path) -> np.ndarray:
    """All depth frames (N, H, W) float32 of a drive from a depth kind it holds (``sparse``, ``dense``,
    ``sparse@<beams>``, ``exact``) or a layer file path."""
    return load_depth_and_confidence(drive, source)[0]


def load_depth_and_confidence(drive: DriveFile, source: str | Path) -> tuple[np.ndarray, np.ndarray | None]:
    """As :func:`load_depth`, with the layer's per-pixel confidence (N, H, W) when it has one (a drive's own depth
    kinds have none): the layer file is read once."""
    if not isinstance(source, Path) and is_depth_kind(str(source)):
        return np.stack([drive.depth(str(source), i) for i in range(len(drive))]), None
    layer = read_layer_for(drive, source)
    return layer.depth, layer.confidence


def measured_kind(source: str | Path) -> str | None:
    """The drive's depth kind that holds the pixels a LiDAR measured behind a depth source: a sparse kind is its
    own; ``dense`` and ``exact`` (not measured by the LiDAR frame by frame) have the drive's own ``sparse``; a
    layer file the input it was predicted from (``dcslam predict`` records it), followed through the layers a
    filter was made from; None when a layer does not say (a layer written by another tool).

    Used wherever SLAM needs evidence that does not come from a completion (its ICP sources or an independent
    odometry): the measured pixels of a completed frame are those of this kind.
    """
    seen = set()
    while True:
        if not isinstance(source, Path) and is_depth_kind(str(source)):
            kind = str(source)
            return "sparse" if kind in ("dense", EXACT) else kind
        path = Path(source)
        if path in seen or not path.is_file():
            return None
        seen.add(path)
        config = read_layer(path).config
        if config.get("input") and is_depth_kind(str(config["input"])):
            source = str(config["input"])
            continue
        parent = config.get("source")
        if not parent:
            return None
        parent = Path(parent)
        if not parent.is_file() and config.get("source_layer"):
            # a moved workspace: the filtered layer's source by its name, beside this layer's folder
            parent = path.parent.parent.parent / "predictions" / str(config["source_layer"]) / path.name
        source = parent


def list_drives(drives_dir: Path | str) -> list[Path]:
    """Drive files in a folder, sorted by name."""
    return sorted(p for p in Path(drives_dir).glob("*.h5") if not p.name.startswith("."))


def read_splits(path: Path | str) -> dict[str, list[str]]:
    """``splits.json``: ``{"train": [...], "val": [...], "test": [...]}`` of drive names."""
    path = Path(path)
    if not path.exists():
        raise DcslamError(f"{path} not found; run `dcslam prepare-kitti` first")
    try:
        splits = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise DcslamError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(splits, dict) or not all(isinstance(splits.get(k), list) for k in ("train", "val", "test")):
        raise DcslamError(f'{path}: expected {{"train": [...], "val": [...], "test": [...]}} of drive names')
    return splits
