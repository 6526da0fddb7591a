"""Write synthetic drives in the KITTI raw + depth-completion layout (see the KITTI formats of :mod:`dcslam.io`).

Per drive ``2011_09_26_drive_<1000 + index>_sync``::

    raw/2011_09_26/calib_*.txt                                  the real 2011-09-26 calibration, verbatim
    raw/2011_09_26/<drive>/image_02/data/<frame>.png            1242 × 375 RGB, + timestamps.txt
    raw/2011_09_26/<drive>/velodyne_points/data/<frame>.bin     (N, 4) float32 scans, + timestamps{,_start,_end}.txt
    raw/2011_09_26/<drive>/oxts/data/<frame>.txt                30-field packets, + timestamps.txt, dataformat.txt
    depth_completion/train/<drive>/proj_depth/velodyne_raw/image_02/<frame>.png   frames 5 … N − 6, like KITTI
    depth_completion/train/<drive>/proj_depth/groundtruth/image_02/<frame>.png
    depth_completion/train/<drive>/dcslam_exact_synthetic/image_02/<frame>.png   noise-free depth of every pixel
                                                                (a dcslam extension, synthetic only), same frames
    SYNTHETIC, synth_config.json                                a marker for prepare-kitti, and the settings

Each drive is written into hidden temporary folders and renamed when complete, so an interrupted run leaves no
partial drive.
"""
from __future__ import annotations

import contextlib
import os
import shutil
import time
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.io.atomic import write_json_atomic, write_text_atomic
from dcslam.io.kitti import (EXACT_FOLDER, frame_name, write_depth_png, write_image, write_timestamps,
                             write_velodyne)
from dcslam.io.kitti_calib import Calibration, copy_calibration, read_calibration
from dcslam.io.kitti_oxts import OxtsPacket, write_oxts, write_oxts_dataformat
from dcslam.synth.raycast import CameraGrid
from dcslam.synth.street.scene import Scene, build_scene
from dcslam.synth.street.sensors import (GroundTexture, consistent_groundtruth, make_lidar_grid, project_points,
                                         render_camera, scan_lidar, stereo_valid)
from dcslam.synth.street.trajectory import Drive, Motion, oxts_packets
from dcslam.synth.street.trajectory import Path as StreetPath
from dcslam.synth.terrain import Terrain

DATE = "2011_09_26"
CALIB_DIR = Path(__file__).parents[1] / f"calib_{DATE}"  # the real 2011-09-26 calibration (package data, verbatim)


def street_calibration() -> Calibration:
    """The real KITTI 2011-09-26 calibration that synthetic drives are rendered with and written beside."""
    return read_calibration(CALIB_DIR)


GT_WINDOW = 5  # ground truth accumulates the scans of frames i − 5 … i + 5; KITTI annotates frames 5 … N − 6
FIRST_DRIVE_NUMBER = 1000


def drive_name(index: int) -> str:
    """``2011_09_26_drive_<1000 + index>_sync``: numbers that never collide with real KITTI drives."""
    return f"{DATE}_drive_{FIRST_DRIVE_NUMBER + index:04d}_sync"


@dataclass(frozen=True)
class DriveTruth:
    """What the generator knows about one drive: times (N,) in POSIX seconds, ``T_world_cam2`` (N, 4, 4) re-based
    so the first pose is the identity, ``T_world_imu`` (N, 4, 4) in the generator's world, and the scene."""

    name: str
    timestamps: np.ndarray
    T_world_cam2: np.ndarray
    T_world_imu: np.ndarray
    scene: Scene
    oxts: np.ndarray  # (N, 30)


@dataclass(frozen=True)
class DriveReport:
    """One written drive: its name, frames, depth frames, mean densities (fractions of pixels) and seconds taken."""

    name: str
    frames: int
    depth_frames: int
    sparse_density: float
    groundtruth_density: float
    seconds: float


def make_drive(seed: int, index: int, frames: int, calib: Calibration) -> tuple[DriveTruth, np.random.Generator]:
    """The trajectory, timestamps, OXTS packets and scene of drive ``index`` of ``seed`` (deterministic)."""
    rng = np.random.default_rng([seed, index])
    dt = np.clip(rng.normal(0.1036, 0.0015, frames), 0.0998, 0.1102)
    t_rel = np.concatenate([[0.0], np.cumsum(dt[:-1])])
    start = datetime(2011, 9, 26, 11, 0, tzinfo=timezone.utc).timestamp() + rng.uniform(0, 4 * 3600)
    motion = Motion.random(rng)
    length = float(motion.arc_length(t_rel[-1] + 1.0))
    drive = Drive(terrain=Terrain.random(rng), path=StreetPath.random(rng, -200.0, length + 250.0), motion=motion)
    scene = build_scene(drive, rng, -130.0, length + 150.0)

    def T_world_imu_of(t):
        return drive.T_world_velo(t) @ calib.T_velo_imu

    T_world_imu = T_world_imu_of(t_rel)
    T_world_cam2 = T_world_imu @ np.linalg.inv(calib.T_cam2_imu)
    T_world_cam2 = np.linalg.inv(T_world_cam2[0]) @ T_world_cam2
    oxts = oxts_packets(T_world_imu_of, t_rel, lat0_deg=49.0 + rng.uniform(0.0, 0.05),
                        lon0_deg=8.38 + rng.uniform(0.0, 0.08), alt0_m=110.0 + rng.uniform(0.0, 10.0), rng=rng)
    return DriveTruth(drive_name(index), start + t_rel, T_world_cam2, T_world_imu, scene, oxts), rng


def _t_rel(truth: DriveTruth) -> np.ndarray:
    return truth.timestamps - truth.timestamps[0]


def write_drive(truth: DriveTruth, rng: np.random.Generator, calib: Calibration, raw_dir: Path, depth_dir: Path,
                lidar_azimuth_step_deg: float = 0.08, on_frame=None) -> DriveReport:
    """Render and write every file of one drive into ``raw_dir`` (the ``<drive>`` folder of ``raw/<date>``) and
    ``depth_dir`` (its ``depth_completion/<split>/<drive>`` folder)."""
    started = time.perf_counter()
    scene = truth.scene
    drive = scene.drive
    t_rel = _t_rel(truth)
    n = len(t_rel)
    width, height = calib.size_rect_02
    camera = CameraGrid(calib.K_cam2, width, height)
    lidar = make_lidar_grid(lidar_azimuth_step_deg)
    ground = GroundTexture(scene)
    T_world_velo = drive.T_world_velo(t_rel)
    T_world_cam = truth.T_world_imu @ np.linalg.inv(calib.T_cam2_imu)
    T_cam_world = np.linalg.inv(T_world_cam)

    for sensor in ("image_02", "oxts", "velodyne_points"):
        write_timestamps(raw_dir / sensor / "timestamps.txt", truth.timestamps)
    write_timestamps(raw_dir / "velodyne_points" / "timestamps_start.txt", truth.timestamps - 0.05)
    write_timestamps(raw_dir / "velodyne_points" / "timestamps_end.txt", truth.timestamps + 0.05)
    write_oxts_dataformat(raw_dir / "oxts" / "dataformat.txt")
    for k, packet in enumerate(truth.oxts):
        write_oxts(raw_dir / "oxts" / "data" / frame_name(k, ".txt"), OxtsPacket.from_values(packet))

    scans_world: dict[int, np.ndarray] = {}
    scans_velo: dict[int, np.ndarray] = {}
    true_depth: dict[int, np.ndarray] = {}
    stereo: dict[int, np.ndarray] = {}
    sparse, dense = [], []
    for k in range(n):
        depth, rgb = render_camera(scene, ground, camera, T_world_cam[k], float(t_rel[k]), rng)
        write_image(raw_dir / "image_02" / "data" / frame_name(k, ".png"), rgb)
        scan = scan_lidar(scene, lidar, T_world_velo[k], float(t_rel[k]), rng)
        write_velodyne(raw_dir / "velodyne_points" / "data" / frame_name(k, ".bin"), scan)
        scans_velo[k] = scan[:, :3]
        scans_world[k] = scan[:, :3].astype(np.float64) @ T_world_velo[k][:3, :3].T + T_world_velo[k][:3, 3]
        true_depth[k] = depth
        stereo[k] = stereo_valid(rgb)
        i = k - GT_WINDOW
        if i >= GT_WINDOW:
            raw_i = project_points(scans_velo[i] @ calib.T_cam2_velo[:3, :3].T.astype(np.float32)
                                   + calib.T_cam2_velo[:3, 3].astype(np.float32), calib.K_cam2, width, height)
            window = np.concatenate([scans_world[j] for j in range(i - GT_WINDOW, i + GT_WINDOW + 1)])
            points_cam = (window @ T_cam_world[i][:3, :3].T + T_cam_world[i][:3, 3]).astype(np.float32)
            gt_i = consistent_groundtruth(points_cam, true_depth[i], calib.K_cam2, stereo[i])
            write_depth_png(depth_dir / "proj_depth" / "velodyne_raw" / "image_02" / frame_name(i, ".png"), raw_i)
            write_depth_png(depth_dir / "proj_depth" / "groundtruth" / "image_02" / frame_name(i, ".png"), gt_i)
            write_depth_png(depth_dir / EXACT_FOLDER / "image_02" / frame_name(i, ".png"), true_depth[i])
            sparse.append(float(np.mean(raw_i > 0)))
            dense.append(float(np.mean(gt_i > 0)))
        for old in [j for j in scans_world if j < k - 2 * GT_WINDOW]:
            del scans_world[old], scans_velo[old]
        for old in [j for j in true_depth if j < k - GT_WINDOW]:
            del true_depth[old], stereo[old]
        if on_frame is not None:
            on_frame()
    return DriveReport(truth.name, n, len(sparse), float(np.mean(sparse)) if sparse else 0.0,
                       float(np.mean(dense)) if dense else 0.0, time.perf_counter() - started)


def _remove_leftovers(*folders: Path) -> None:
    """Remove the temporary drive folders an interrupted run left (``.<drive>.tmp-<pid>``)."""
    for folder in folders:
        for tmp in folder.glob(f".{DATE}_drive_*_sync.tmp-*") if folder.is_dir() else ():
            shutil.rmtree(tmp, ignore_errors=True)


def _generated_drives(out_root: Path, date_dir: Path) -> set[str]:
    """Names of the generated drives (numbers from 1000, never real KITTI's) already under ``out_root``."""
    folders = [date_dir, *(out_root / "depth_completion" / s for s in ("train", "val"))]
    return {p.name for f in folders if f.is_dir() for p in f.glob(f"{DATE}_drive_1[0-9][0-9][0-9]_sync")}


def foreign_entries(out_root: Path) -> list[Path]:
    """What ``out_root`` holds that ``dcslam synth`` does not write (real KITTI drives, other dates, any other
    file): the generated drives, the calibration of :data:`DATE`, the marker, the settings and hidden temporary
    names are its own. Empty when ``out_root`` does not exist."""
    from dcslam.io.kitti_calib import CALIB_FILES

    if not out_root.is_dir():
        return []
    generated = f"{DATE}_drive_1[0-9][0-9][0-9]_sync"
    own = {"raw": {DATE: {*CALIB_FILES, generated}}, "depth_completion": {"train": {generated}, "val": {generated}},
           "SYNTHETIC": None, "synth_config.json": None}

    def walk(folder: Path, allowed) -> list[Path]:
        found = []
        for entry in sorted(folder.iterdir()):
            if entry.name.startswith("."):
                continue
            if isinstance(allowed, dict) and entry.name in allowed:
                rule = allowed[entry.name]  # a folder's own rules (dict or set of names), or None for a file
                if rule is not None and entry.is_dir():
                    found += walk(entry, rule)
                elif (rule is None) == entry.is_dir():
                    found.append(entry)
            elif isinstance(allowed, set) and (entry.name in allowed or entry.match(generated)):
                continue
            else:
                found.append(entry)
        return found

    return walk(out_root, own)


def _listing(paths: list[Path], limit: int = 3) -> str:
    shown = ", ".join(str(p) for p in paths[:limit])
    return shown + (f" and {len(paths) - limit} more" if len(paths) > limit else "")


def _occupied(path: Path) -> bool:
    return path.exists() and (not path.is_dir() or any(path.iterdir()))


def _write_one(seed: int, index: int, frames: int, name: str, date_dir: Path, depth_root: Path,
               lidar_azimuth_step_deg: float, on_frame=None) -> DriveReport:
    """Write drive ``index`` of ``seed`` into temporary folders, then move them to their names."""
    calib = street_calibration()
    truth, rng = make_drive(seed, index, frames, calib)
    raw_tmp = date_dir / f".{name}.tmp-{os.getpid()}"
    depth_tmp = depth_root / f".{name}.tmp-{os.getpid()}"
    try:
        for tmp in (raw_tmp, depth_tmp):
            shutil.rmtree(tmp, ignore_errors=True)
            tmp.mkdir(parents=True)
        report = write_drive(truth, rng, calib, raw_tmp, depth_tmp, lidar_azimuth_step_deg, on_frame)
        for tmp, final in ((raw_tmp, date_dir / name), (depth_tmp, depth_root / name)):
            if final.exists():
                shutil.rmtree(final)
            os.replace(tmp, final)
        return report
    finally:
        for tmp in (raw_tmp, depth_tmp):
            with contextlib.suppress(FileNotFoundError):
                shutil.rmtree(tmp)


def generate(out_root: Path | str, drives: int = 6, frames: int = 60, seed: int = 0, force: bool = False,
             lidar_azimuth_step_deg: float = 0.08, on_frame=None, jobs: int = 1) -> list[DriveReport]:
    """Generate ``drives`` synthetic drives of ``frames`` raw frames each under the KITTI root ``out_root``.

    Refuses (:class:`DcslamError`) to replace a drive folder that exists and is not empty unless ``force``; with
    ``force``, generated drives of an earlier run beyond ``drives`` are removed, so the root holds this run's only.
    ``SYNTHETIC`` and ``synth_config.json`` are written once every drive is complete (removed first), and
    temporary folders of an interrupted run are removed.
    ``on_frame`` is called after each frame (progress; with ``jobs`` > 1, ``frames`` times as each drive completes).
    ``jobs`` > 1 writes that many drives at once in worker processes: each drive follows from (seed, drive index)
    alone, so the files are the same for any ``jobs``. Returns one :class:`DriveReport` per drive.
    """
    if drives < 1:
        raise DcslamError(f"--drives must be at least 1, got {drives}")
    if frames < 1:
        raise DcslamError(f"--frames must be at least 1, got {frames}")
    if not 0.01 <= lidar_azimuth_step_deg <= 1.0:
        raise DcslamError(f"LiDAR azimuth step {lidar_azimuth_step_deg}° is outside 0.01–1°")
    out_root = Path(out_root)
    date_dir = out_root / "raw" / DATE
    depth_root = out_root / "depth_completion" / "train"
    names = [drive_name(i) for i in range(drives)]
    _remove_leftovers(date_dir, depth_root)
    stale = _generated_drives(out_root, date_dir) - set(names)
    if not force:
        _check_free(out_root, [p for name in names for p in (date_dir / name, depth_root / name)], stale)
    copy_calibration(CALIB_DIR, date_dir, force)
    from dcslam.workspace import stage_config

    # the marker and settings are written last: until then nothing claims drives that are not all there
    for claim in (out_root / "SYNTHETIC", out_root / "synth_config.json"):
        claim.unlink(missing_ok=True)
    for name in sorted(stale):  # drives of an earlier, larger run (reached only with force)
        for folder in (date_dir / name, *(out_root / "depth_completion" / s / name for s in ("train", "val"))):
            shutil.rmtree(folder, ignore_errors=True)
    settings = {"out": out_root, "drives": drives, "frames": frames, "seed": seed,
                "lidar_azimuth_step_deg": lidar_azimuth_step_deg, "groundtruth_window": GT_WINDOW}
    work = [(seed, index, frames, name, date_dir, depth_root, lidar_azimuth_step_deg)
            for index, name in enumerate(names)]
    reports = _write_drives(work, frames, jobs, on_frame)
    write_json_atomic(out_root / "synth_config.json", stage_config("synth", settings))
    write_text_atomic(out_root / "SYNTHETIC", f"generated by dcslam synth, seed {seed}, {drives} drives of "
                                              f"{frames} frames ({', '.join(names)})\n")
    return reports


def _check_free(out_root: Path, folders: list[Path], stale: set[str]) -> None:
    """Without ``force``: refuse a root holding data ``dcslam synth`` did not write, drive ``folders`` that are
    occupied, or generated drives of an earlier run (``stale``)."""
    foreign = foreign_entries(out_root)
    if foreign:  # e.g. real KITTI: generated drives beside it would be read as one dataset
        raise DcslamError(f"{out_root} holds data dcslam synth did not write ({_listing(foreign)}); choose "
                          "another --out, or pass --force to write the generated drives beside it")
    taken = [p for p in folders if _occupied(p)]
    if taken:
        raise DcslamError(f"{taken[0]} exists; pass --force to replace it")
    if stale:
        raise DcslamError(f"{out_root} holds generated drives of an earlier run ({', '.join(sorted(stale))}); "
                          "pass --force to replace them, or choose another --out")


def _write_drives(work: list[tuple], frames: int, jobs: int, on_frame) -> list[DriveReport]:
    """:func:`_write_one` of each argument tuple of ``work``, in order; with ``jobs`` > 1 in worker processes."""
    if jobs <= 1 or len(work) == 1:
        return [_write_one(*args, on_frame=on_frame) for args in work]
    from dcslam.workers import process_pool

    with process_pool(jobs, len(work)) as pool:
        futures = [pool.submit(_write_one, *args) for args in work]
        reports = []
        for future in futures:  # in drive order; each drive's frames counted as it completes
            reports.append(future.result())
            for _ in range(frames if on_frame is not None else 0):
                on_frame()
    return reports
