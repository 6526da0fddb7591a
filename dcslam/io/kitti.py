"""KITTI raw ("sync") and KITTI depth-completion files: readers and writers of the file formats.

Layout under a KITTI root (real, or written by ``dcslam synth``)::

    raw/<date>/calib_cam_to_cam.txt, calib_velo_to_cam.txt, calib_imu_to_velo.txt
    raw/<date>/<date>_drive_<NNNN>_sync/image_02/data/<frame:010d>.png, image_02/timestamps.txt
    raw/<date>/<date>_drive_<NNNN>_sync/oxts/data/<frame:010d>.txt, oxts/timestamps.txt
    raw/<date>/<date>_drive_<NNNN>_sync/velodyne_points/data/<frame:010d>.bin, velodyne_points/timestamps.txt
    depth_completion/{train,val}/<date>_drive_<NNNN>_sync/proj_depth/{velodyne_raw,groundtruth}/image_02/<frame:010d>.png
    depth_completion/{train,val}/<date>_drive_<NNNN>_sync/dcslam_exact_synthetic/image_02/<frame:010d>.png
        (a dcslam extension written by ``dcslam synth`` only: the noise-free depth of every pixel, uint16 at 1/256 m
        like the other depth PNGs, for the same frames as velodyne_raw)
    SYNTHETIC              (only in generated roots: a marker file written by ``dcslam synth``)

This module holds the per-file formats (depth PNG, image, Velodyne scan, timestamps) and the drive-level reading:
:func:`find_drives` lists drives, :func:`index_drive` checks that their files line up and works out timestamps and
camera-2 poses, :func:`read_drive` yields :class:`dcslam.io.drive.DriveFrame` records. Calibration is in
:mod:`dcslam.io.kitti_calib`, OXTS packets and poses in :mod:`dcslam.io.kitti_oxts` (both re-exported here).

The depth benchmark has depth only for frames 5 .. n-6 of each raw drive; frames are aligned by their number.
Real and generated roots are read by the same code; the only difference recorded is the source.
"""
from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.io import png
from dcslam.io.drive import DriveFrame
from dcslam.io.kitti_calib import CALIB_FILES, Calibration, project_velodyne, read_calibration  # noqa: F401
from dcslam.io.kitti_oxts import OxtsPacket, camera_poses, oxts_to_T_world_imu, read_oxts, rebase, write_oxts  # noqa: F401

DEPTH_SCALE = 256.0  # uint16 depth PNG: metres = value / 256, 0 = no value


def frame_name(frame_id: int, suffix: str) -> str:
    """KITTI file name of a frame: ``0000000005.png``."""
    return f"{int(frame_id):010d}{suffix}"


def read_depth_png(path: Path | str) -> np.ndarray:
    """A KITTI uint16 depth PNG → (H, W) float32 metres (value / 256, 0 = no value); see :mod:`dcslam.io.png`."""
    return png.read_depth_png(path, DEPTH_SCALE)


def write_depth_png(path: Path | str, depth_m: np.ndarray) -> Path:
    """(H, W) metres → KITTI uint16 depth PNG (value = round(256 · metres)); see :mod:`dcslam.io.png`."""
    return png.write_depth_png(path, depth_m, DEPTH_SCALE)


def read_image(path: Path | str) -> np.ndarray:
    """A KITTI colour PNG → (H, W, 3) uint8 RGB; see :mod:`dcslam.io.png`."""
    return png.read_rgb_png(path)


def write_image(path: Path | str, rgb: np.ndarray) -> Path:
    """(H, W, 3) uint8 RGB → PNG (OpenCV's default compression); see :mod:`dcslam.io.png`."""
    return png.write_rgb_png(path, rgb)


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

    Whole seconds come from the date and the fraction is parsed separately, so precision is that of float64 POSIX
    seconds (about 0.2 µs today), not the file's nanoseconds.
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


# --- Drives: finding them under a KITTI root, checking that their files line up, reading their frames -------------

EXACT_FOLDER = "dcslam_exact_synthetic"  # generated drives only: noise-free depth, see the module docstring
SYNTHETIC_MARKER = "SYNTHETIC"  # a file at the root written by `dcslam synth`; its presence makes source "synthetic"
DEPTH_SPLITS = ("train", "val")  # folders of KITTI depth completion
_DRIVE_NAME = re.compile(r"^(\d{4}_\d{2}_\d{2})_drive_(\d{4})_sync$")


def dataset_source(root: Path | str) -> str:
    """``"synthetic"`` if ``root`` holds the ``SYNTHETIC`` marker written by ``dcslam synth``, else ``"kitti"``."""
    return "synthetic" if (Path(root) / SYNTHETIC_MARKER).is_file() else "kitti"


@dataclass(frozen=True)
class RawDrive:
    """Where one drive's files are under a KITTI root. ``depth_dir`` is None when the depth benchmark lacks it;
    ``raw_dir`` may not exist when only its depth was found (see :attr:`has_raw`)."""

    root: Path
    name: str  # e.g. "2011_09_26_drive_0001_sync"
    depth_dir: Path | None
    source: str = "kitti"

    @property
    def date(self) -> str:
        return self.name[:10]

    @property
    def number(self) -> str:
        """The four-digit drive number, e.g. ``"0001"``."""
        return self.name[17:21]

    @property
    def date_dir(self) -> Path:
        return self.root / "raw" / self.date

    @property
    def raw_dir(self) -> Path:
        return self.date_dir / self.name

    @property
    def has_raw(self) -> bool:
        return self.raw_dir.is_dir()

    def image_path(self, frame_id: int) -> Path:
        return self.raw_dir / "image_02" / "data" / frame_name(frame_id, ".png")

    def oxts_path(self, frame_id: int) -> Path:
        return self.raw_dir / "oxts" / "data" / frame_name(frame_id, ".txt")

    def velodyne_path(self, frame_id: int) -> Path:
        return self.raw_dir / "velodyne_points" / "data" / frame_name(frame_id, ".bin")

    def depth_path(self, kind: str, frame_id: int) -> Path:
        """``kind`` is ``"velodyne_raw"`` (sparse) or ``"groundtruth"`` (dense)."""
        if self.depth_dir is None:
            raise DcslamError(f"{self.name}: no depth-completion folder under {self.root / 'depth_completion'}")
        return self.depth_dir / "proj_depth" / kind / "image_02" / frame_name(frame_id, ".png")

    def exact_path(self, frame_id: int) -> Path:
        """The noise-free depth PNG that ``dcslam synth`` writes (generated drives only)."""
        if self.depth_dir is None:
            raise DcslamError(f"{self.name}: no depth-completion folder under {self.root / 'depth_completion'}")
        return self.depth_dir / EXACT_FOLDER / "image_02" / frame_name(frame_id, ".png")

    @property
    def has_exact(self) -> bool:
        return self.depth_dir is not None and (self.depth_dir / EXACT_FOLDER).is_dir()


def find_drives(root: Path | str) -> list[RawDrive]:
    """All drives under a KITTI root that have a raw folder (``raw/<date>/<date>_drive_NNNN_sync``) or a depth
    folder (``depth_completion/{train,val}/<name>``), sorted by name. Nothing is read or checked here."""
    root = Path(root)
    source = dataset_source(root)
    names = {p.name for p in (root / "raw").glob("*/*_drive_*_sync")
             if p.is_dir() and _DRIVE_NAME.match(p.name) and p.parent.name == p.name[:10]}
    depth_dirs: dict[str, Path] = {}
    for split in DEPTH_SPLITS:
        for p in sorted((root / "depth_completion" / split).glob("*_drive_*_sync")):
            if p.is_dir() and _DRIVE_NAME.match(p.name):
                depth_dirs.setdefault(p.name, p)
    return [RawDrive(root, name, depth_dirs.get(name), source) for name in sorted(names | set(depth_dirs))]


def _frame_ids(folder: Path, suffix: str) -> list[int]:
    if not folder.is_dir():
        raise DcslamError(f"folder {folder} not found")
    ids = []
    for p in folder.iterdir():
        if p.suffix == suffix and not p.name.startswith("."):
            if not p.stem.isdigit():
                raise DcslamError(f"{p}: expected a frame file named like {frame_name(0, suffix)}")
            ids.append(int(p.stem))
    return sorted(ids)


def _count_lines(path: Path) -> int:
    if not path.exists():
        raise DcslamError(f"timestamps file {path} not found")
    return sum(1 for line in path.read_text(errors="replace").splitlines() if line.strip())


@dataclass(frozen=True, eq=False)
class DriveIndex:
    """A checked drive: the frames that have depth, with their timestamps and camera-2 poses.

    Attributes:
        drive: where the files are.
        calib: the date's calibration.
        frame_ids: (N,) int64 KITTI numbers of the frames with depth (5 .. n-6 for real KITTI).
        timestamps: (N,) float64 POSIX seconds from ``image_02/timestamps.txt``.
        T_world_cam: (N, 4, 4) float64 poses of camera 2; world = camera 2 at ``frame_ids[0]``, the first frame
            with depth (not raw frame 0), so the first stored pose is the identity.
    """

    drive: RawDrive
    calib: Calibration
    frame_ids: np.ndarray
    timestamps: np.ndarray
    T_world_cam: np.ndarray

    @property
    def K(self) -> np.ndarray:
        """(3, 3) intrinsics of rectified camera 2."""
        return self.calib.K_cam2

    def __len__(self) -> int:
        return len(self.frame_ids)

    def head(self, max_frames: int | None) -> "DriveIndex":
        """The first ``max_frames`` frames (all if None); poses keep their world (the first frame is unchanged)."""
        if max_frames is None:
            return self
        if max_frames < 1:
            raise DcslamError(f"max_frames is {max_frames}, expected at least 1")
        n = int(max_frames)
        return DriveIndex(self.drive, self.calib, self.frame_ids[:n], self.timestamps[:n], self.T_world_cam[:n])


def index_drive(drive: RawDrive) -> DriveIndex:
    """Check that a drive's files line up and read its calibration, timestamps and OXTS poses (not its images).

    Raises :class:`DcslamError` naming the file when: a calibration file is missing or malformed; the image files
    are not frames 0 .. n-1 or their count differs from the lines of ``image_02/timestamps.txt``; the OXTS files
    differ from the image frames (or from ``oxts/timestamps.txt``); an OXTS packet is malformed; the
    ``velodyne_raw`` and ``groundtruth`` frames differ, are empty, or include frames the raw drive lacks.
    """
    if not drive.has_raw:
        raise DcslamError(f"{drive.name}: raw folder {drive.raw_dir} not found")
    if drive.depth_dir is None:
        raise DcslamError(f"{drive.name}: no depth folder depth_completion/{{train,val}}/{drive.name} under "
                          f"{drive.root}")
    calib = read_calibration(drive.date_dir)
    image_dir = drive.raw_dir / "image_02"
    raw_ids = _frame_ids(image_dir / "data", ".png")
    stamps_path = image_dir / "timestamps.txt"
    stamps = read_timestamps(stamps_path)
    if len(stamps) != len(raw_ids):
        raise DcslamError(f"{stamps_path}: {len(stamps)} timestamps but {len(raw_ids)} images in {image_dir / 'data'}")
    if raw_ids != list(range(len(raw_ids))):
        missing = sorted(set(range(len(raw_ids))) - set(raw_ids))
        raise DcslamError(f"{image_dir / 'data'}: images are not frames 0..{len(raw_ids) - 1} "
                          f"(missing {frame_name(missing[0], '.png')})")
    oxts_dir = drive.raw_dir / "oxts"
    oxts_ids = _frame_ids(oxts_dir / "data", ".txt")
    if oxts_ids != raw_ids:
        raise DcslamError(f"{oxts_dir / 'data'}: {len(oxts_ids)} OXTS packets but {len(raw_ids)} images in "
                          f"{image_dir / 'data'}")
    if (oxts_dir / "timestamps.txt").exists() and _count_lines(oxts_dir / "timestamps.txt") != len(raw_ids):
        raise DcslamError(f"{oxts_dir / 'timestamps.txt'}: {_count_lines(oxts_dir / 'timestamps.txt')} lines but "
                          f"{len(raw_ids)} OXTS packets")
    T_world_cam_raw = camera_poses(oxts_to_T_world_imu([read_oxts(drive.oxts_path(i)) for i in raw_ids]), calib)

    kinds = {kind: drive.depth_dir / "proj_depth" / kind / "image_02" for kind in ("velodyne_raw", "groundtruth")}
    sparse_ids, dense_ids = (_frame_ids(folder, ".png") for folder in kinds.values())
    if sparse_ids != dense_ids:
        odd = sorted(set(sparse_ids) ^ set(dense_ids))
        raise DcslamError(f"{drive.depth_dir}: velodyne_raw has {len(sparse_ids)} frames and groundtruth "
                          f"{len(dense_ids)}; they differ at {frame_name(odd[0], '.png')}")
    if not sparse_ids:
        raise DcslamError(f"{kinds['velodyne_raw']}: no depth PNGs")
    if sparse_ids[-1] >= len(raw_ids):
        raise DcslamError(f"{kinds['velodyne_raw']}: depth frame {frame_name(sparse_ids[-1], '.png')} has no raw "
                          f"frame ({drive.raw_dir} has {len(raw_ids)} frames)")
    if drive.has_exact:
        exact_ids = _frame_ids(drive.depth_dir / EXACT_FOLDER / "image_02", ".png")
        if exact_ids != sparse_ids:
            odd = sorted(set(sparse_ids) ^ set(exact_ids))
            raise DcslamError(f"{drive.depth_dir / EXACT_FOLDER}: {len(exact_ids)} frames but velodyne_raw has "
                              f"{len(sparse_ids)}; they differ at {frame_name(odd[0], '.png')}")
    ids = np.array(sparse_ids, dtype=np.int64)
    return DriveIndex(drive, calib, ids, stamps[ids], rebase(T_world_cam_raw[ids]))


def sparse_from_scan(drive: RawDrive, calib: Calibration, frame_id: int, beams: tuple[int, ...],
                     image_size: tuple[int, int]) -> dict[str, np.ndarray]:
    """``{"sparse@<B>": (H, W) float32}``: the frame's Velodyne scan cut to ``B`` of its 64 lasers
    (:func:`dcslam.geometry.lidar_beams.keep_beams`) and projected into camera 2 as ``velodyne_raw`` is."""
    from dcslam.geometry.lidar_beams import keep_beams

    path = drive.velodyne_path(frame_id)
    if not path.exists():
        raise DcslamError(f"{path} not found: sparse depth of fewer beams is made from the raw Velodyne scans "
                          f"(velodyne_points/data/*.bin); add them or drop --beams")
    scan = read_velodyne(path)
    try:
        return {f"sparse@{b}": project_velodyne(keep_beams(scan, b), calib, image_size) for b in beams}
    except DcslamError as exc:
        raise DcslamError(f"{path}: {exc}") from None


def read_drive(index: DriveIndex, beams: tuple[int, ...] = ()) -> Iterator[DriveFrame]:
    """The frames of a checked drive, read lazily: image, sparse and dense depth, pose, timestamp, frame number,
    and for each beam count in ``beams`` the sparse depth of that many lasers (``frame.extra["sparse@<B>"]``), and
    on generated drives the noise-free depth (``frame.extra["exact"]``).

    Raises :class:`DcslamError` naming the file on an unreadable image, an 8-bit or truncated depth PNG, sizes
    that differ between a frame's image and its depth, or (with ``beams``) a missing or malformed Velodyne scan.
    """
    drive = index.drive
    for i, frame_id in enumerate(index.frame_ids):
        rgb = read_image(drive.image_path(frame_id))
        sparse = read_depth_png(drive.depth_path("velodyne_raw", frame_id))
        dense = read_depth_png(drive.depth_path("groundtruth", frame_id))
        for kind, depth in (("velodyne_raw", sparse), ("groundtruth", dense)):
            if depth.shape != rgb.shape[:2]:
                raise DcslamError(f"{drive.depth_path(kind, frame_id)}: depth is {depth.shape[1]}x{depth.shape[0]} "
                                  f"but image {drive.image_path(frame_id).name} is {rgb.shape[1]}x{rgb.shape[0]}")
        extra = sparse_from_scan(drive, index.calib, frame_id, beams, rgb.shape[:2]) if beams else {}
        if drive.has_exact:
            extra["exact"] = read_depth_png(drive.exact_path(frame_id))
            if extra["exact"].shape != rgb.shape[:2]:
                raise DcslamError(f"{drive.exact_path(frame_id)}: depth is {extra['exact'].shape[1]}x"
                                  f"{extra['exact'].shape[0]} but image {drive.image_path(frame_id).name} is "
                                  f"{rgb.shape[1]}x{rgb.shape[0]}")
        yield DriveFrame(rgb=rgb, sparse=sparse, dense=dense, T_world_cam=index.T_world_cam[i],
                         timestamp=float(index.timestamps[i]), frame_id=int(frame_id), extra=extra)
