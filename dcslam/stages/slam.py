"""``dcslam slam``: dense SLAM over drive files, writing per drive ``<out>/<drive>.txt`` (TUM trajectory, readable
by evo), ``<out>/<drive>.kitti.txt`` (the same poses as a KITTI 3x4 pose file, for the odometry devkit),
``<out>/<drive>.ply`` (the map with normals and colours) and ``<out>/<drive>.json`` (frames, points, seconds
per frame, rejected steps, drift against the drive's ground truth, and the configuration that ran), ``<out>`` being
``slam/<layer>/`` by default. The summary's ``settings`` are the requested ones; its ``effective_settings`` the
metric ones as the run used them, after the scene scale (:meth:`dcslam.slam.pipeline.SLAM.effective_settings`: a
room run at the 0.2 m ``voxel_size`` fuses at ~0.04 m).

The configuration extends :class:`dcslam.slam.config.SlamSettings`, so a field added there is an option of
``dcslam slam`` and a configuration-file key with no other edit.
"""
from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.slam.config import SlamSettings
from dcslam.stages.config import option
from dcslam.workspace import Workspace


#: Whether a run on completed depth gets an independent companion on its measured pixels (``--evidence``).
EVIDENCE_USES = ("auto", "none")

#: How SLAM uses a depth layer's per-pixel confidence (``--confidence``).
CONFIDENCE_USES = ("weights", "mask", "ignore")
#: Which points the odometry aligns (``--sources``): the depth input's own, or the measured LiDAR pixels behind it.
SOURCES = ("depth", "measured")


@dataclass(frozen=True)
class ConfidenceUse:
    """What SLAM does with a layer's confidence: ``mode`` one of :data:`CONFIDENCE_USES`, pixels below ``minimum``
    dropped (weights, mask)."""

    mode: str = "weights"
    minimum: float = 0.0

    def apply(self, depth: np.ndarray, confidence: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
        """(depth with the dropped pixels at 0, per-pixel weight or None). Shape: (H, W) each."""
        if confidence is None or self.mode == "ignore":
            return depth, None
        kept = np.where(confidence >= self.minimum, depth, 0).astype(np.float32)
        return kept, (np.where(kept > 0, confidence, 0).astype(np.float32) if self.mode == "weights" else None)

    def record(self, has_confidence: bool) -> dict:
        """What the summary says was done: ``mode`` is ``none`` for a layer without a confidence."""
        return {"mode": self.mode if has_confidence else "none", "min_confidence": self.minimum,
                "layer_has_confidence": has_confidence}


@dataclass(frozen=True)
class SlamStageConfig(SlamSettings):
    """Options of ``dcslam slam``: the SLAM's settings plus its input, frames, output and device."""

    depth: str = option("dense", help="Depth input: sparse, dense, sparse@<beams> (prepare-kitti --beams), exact "
                                      "(generated drives), predicted (a `dcslam predict` layer), filtered "
                                      "(a `dcslam filter` layer), predicted/<run>, filtered/<name>, or a layer "
                                      "folder or file path.")
    drive: list[str] = option(default_factory=list, help="Drive name (in drives/) or .h5 path; repeatable. "
                                                          "Default: the test drives of splits.json.")
    frames: int = option(0, min=0, help="First N frames of each drive (0 = all; the thesis scored 30).")
    run: str | None = option(None, help="Prediction run (or filter name) for --depth predicted (filtered); "
                                        "default: the most recent.")
    out: Path | None = option(None, help="Output folder (default: slam/<layer>/).")
    device: str = option("cpu", help="torch device, e.g. cpu or cuda.")
    threads: int = option(1, min=0, help="torch CPU threads while SLAM runs (0 = torch's default). One thread is "
                                         "fastest for one SLAM process on a shared machine.")
    strict: bool = option(False, help="Exit 1 when a drive's trajectory is suspect (too many degraded or rejected "
                                      "steps); its outputs are still written.")
    confidence: str = option("weights", choices=CONFIDENCE_USES, help=(
        "When the depth layer has a confidence (nconv predictions): weights (each pixel's confidence weights its "
        "ICP residual and its fusion), mask (pixels below --min-confidence are dropped, the rest count fully) or "
        "ignore. No effect on layers without one."))
    min_confidence: float = option(0.0, min=0.0, max=1.0, help=(
        "Pixels whose confidence is below this are dropped before SLAM (with --confidence weights or mask; needs a "
        "layer with a confidence)."))
    sources: str = option("depth", choices=SOURCES, help=(
        "ICP sources: depth (the --depth input's own points) or measured (only the measured LiDAR pixels behind "
        "it, see --measured, with normals taken from them as sparse SLAM does; the map still fuses --depth)."))
    measured: str | None = option(None, help=(
        "With --sources measured: the drive depth kind whose pixels are the ICP sources, e.g. sparse@16. Default: "
        "the input a layer was predicted from (sparse for dense and exact)."))
    evidence: str = option("auto", choices=EVIDENCE_USES, help=(
        "auto: beside a run on completed depth (dense, exact, a predicted or filtered layer), run SLAM on the "
        "measured LiDAR pixels behind it and flag the run when its trajectory leaves that companion's by more than "
        "the companion's own uncertainty allows; none: no companion (the summary says that no evidence bounds "
        "the drift). A sparse input is its own evidence."))

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.frames < 0:
            raise DcslamError(f"--frames must be >= 0, got {self.frames}")
        if self.threads < 0:
            raise DcslamError(f"--threads must be >= 0, got {self.threads}")
        if self.confidence not in CONFIDENCE_USES:
            raise DcslamError(f"unknown confidence use {self.confidence!r} (choose from {', '.join(CONFIDENCE_USES)})")
        if not 0.0 <= self.min_confidence <= 1.0:
            raise DcslamError(f"--min-confidence must be within [0, 1], got {self.min_confidence}")
        if self.confidence == "ignore" and self.min_confidence > 0:
            raise DcslamError("--min-confidence needs --confidence weights or mask (ignore uses no confidence)")
        if self.evidence not in EVIDENCE_USES:
            raise DcslamError(f"unknown evidence use {self.evidence!r} (choose from {', '.join(EVIDENCE_USES)})")
        if self.confidence == "mask" and self.min_confidence <= 0:
            raise DcslamError("--confidence mask drops the pixels below --min-confidence; give one above 0")
        if self.sources not in SOURCES:
            raise DcslamError(f"unknown ICP sources {self.sources!r} (choose from {', '.join(SOURCES)})")
        if self.measured is not None:
            from dcslam.io.drive import is_depth_kind

            if self.sources != "measured":
                raise DcslamError(f"--measured {self.measured} needs --sources measured")
            if not is_depth_kind(self.measured):
                raise DcslamError(f"--measured {self.measured!r} is not a drive depth kind (e.g. sparse, "
                                  "sparse@16)")

    def confidence_use(self) -> "ConfidenceUse":
        return ConfidenceUse(self.confidence, self.min_confidence)

    def settings(self) -> SlamSettings:
        """The SLAM algorithm's own settings (what :func:`dcslam.slam.config.build_slam` takes)."""
        return SlamSettings(**{f.name: getattr(self, f.name) for f in fields(SlamSettings)})


@dataclass
class SlamDriveResult:
    """One drive: its summary (:meth:`DriveRun.summary`) and the files written."""

    drive: str
    summary: dict
    written: dict[str, Path]


def run(ws: Workspace, config: SlamStageConfig, *, force: bool = False) -> list[SlamDriveResult]:
    """SLAM over every selected drive; all outputs are checked not to exist (without ``force``) before any work."""
    from dcslam.allocator import fix_mmap_threshold
    from dcslam.slam.config import build_slam
    from dcslam.stages.config import to_dict
    from dcslam.workspace import drive_file, layer_reference, output_folder, resolve_layer, select_drives

    names = select_drives(ws, config.drive)  # an empty test split is an error, not a run over nothing
    paths = [drive_file(ws, name) for name in names]
    layer = resolve_layer(ws, layer_reference(config.depth, config.run))
    out_dir = config.out if config.out is not None else ws.slam / layer.name
    output_folder(out_dir, "--out")
    from dcslam.device import resolve_device

    resolve_device(config.device)  # a GPU asked for on a CPU-only torch: one line, before any work
    jobs = []
    for path in paths:
        source = layer.require(path.stem)
        check_outputs(out_dir, path.stem, force)
        if config.min_confidence > 0 and not has_confidence(source):
            raise DcslamError(f"--min-confidence {config.min_confidence}: {source} holds no confidence (only layers "
                              f"predicted by a confidence-aware model such as `dcslam train --model nconv` have one); "
                              f"drop --min-confidence")
        jobs.append((path, source, measured_sources(config, source, path)))
    results = []
    # a fixed mmap threshold keeps a long run's peak memory flat (glibc's own one lets the heap fragment: +16 % peak
    # from frame 200 to 1,000); MALLOC_MMAP_THRESHOLD_ in the environment overrides it (dcslam.allocator)
    fix_mmap_threshold()
    with torch_threads(config.threads):
        for path, source, measured in jobs:
            slam = build_slam(config.settings())
            drive_run = run_drive(path, source, slam, config.frames or None, config.device,
                                  settings={**to_dict(config), "source": str(source)},
                                  confidence=config.confidence_use(), sources_kind=measured)
            drive_run.name = path.stem
            drive_run.evidence = companion_evidence(path, source, drive_run, config, measured)
            written = write_outputs(drive_run, out_dir, force)
            results.append(SlamDriveResult(path.stem, drive_run.summary(), written))
    suspect = [r for r in results if r.summary["health"]["suspect"]]
    if config.strict and suspect:
        raise DcslamError("suspect trajectories (--strict): " + "; ".join(
            f"{r.drive}: {', '.join(r.summary['health']['reasons'])}" for r in suspect)
            + f"; outputs written under {out_dir}")
    return results


def measured_sources(config: SlamStageConfig, source: str | Path, drive_path: Path) -> str | None:
    """The drive depth kind whose pixels are a drive's ICP sources (None: the depth input's own, ``--sources
    depth``), checked to be in the drive before any work."""
    from dcslam.io.drive import DriveFile, measured_kind

    if config.sources != "measured":
        return None
    kind = config.measured or measured_kind(source)
    if kind is None:
        raise DcslamError(f"--sources measured: {source} does not record the LiDAR input it was made from (a layer "
                          "written by another tool); pass --measured KIND, e.g. --measured sparse@16")
    with DriveFile(drive_path) as drive:
        if kind not in drive.kinds:
            drive.depth(kind, 0)  # its one-line error names the kinds the drive holds and how to add one
    return kind


def has_confidence(source: str | Path) -> bool:
    """Whether a depth source (a drive depth kind or a layer file) has a per-pixel confidence."""
    from dcslam.io.drive import is_depth_kind

    if not isinstance(source, Path) and is_depth_kind(str(source)):
        return False
    import h5py

    try:
        with h5py.File(source, "r") as h5:
            return "confidence" in h5
    except OSError as exc:
        raise DcslamError(f"{source} is not a readable HDF5 layer file ({exc})") from None


@contextlib.contextmanager
def torch_threads(threads: int):
    """Run the block with ``threads`` torch CPU threads (0: leave torch's setting), restoring the setting after."""
    import torch

    before = torch.get_num_threads()
    if threads > 0:
        torch.set_num_threads(threads)
    try:
        yield
    finally:
        torch.set_num_threads(before)


@dataclass
class DriveRun:
    """Outputs of one drive. Shape: T_world_cam (N, 4, 4) float64, timestamps (N,), T_gt (N, 4, 4)."""

    name: str
    T_world_cam: np.ndarray
    timestamps: np.ndarray
    T_gt: np.ndarray
    map: object                 # dcslam.slam.pointmap.PointMap
    reports: list               # dcslam.slam.pipeline.StepReport per frame
    seconds: float
    settings: dict = field(default_factory=dict)
    confidence: dict = field(default_factory=dict)  # ConfidenceUse.record() plus the fraction of pixels kept
    effective_settings: dict = field(default_factory=dict)  # SLAM.effective_settings(): after the scene scale
    health_rules: object = None  # the HealthRules the steps were judged by (None: the defaults); the run is too
    sources: dict = field(default_factory=lambda: {"mode": "depth"})  # the ICP sources used: mode, measured kind
    evidence: dict | None = None  # dcslam.slam.evidence.judge / unavailable (None: not asked, as before it existed)

    def __post_init__(self) -> None:
        from dcslam.geometry.rotations import nearest_rotation

        # poses composed in float32 leave SO(3) by ~1e-4 over a drive: written and scored as the nearest rotations
        T = np.array(self.T_world_cam, dtype=np.float64)
        T[:, :3, :3] = nearest_rotation(T[:, :3, :3])
        self.T_world_cam = T

    def summary(self) -> dict:
        import torch

        from dcslam.geometry.se3 import pose_error
        from dcslam.slam.health import summarise

        dt, dr = pose_error(torch.from_numpy(self.T_gt), torch.from_numpy(self.T_world_cam))
        n = len(self.reports)
        health = summarise(self.reports, *([self.health_rules] if self.health_rules is not None else []))
        if self.evidence is not None:
            from dcslam.slam.evidence import merge

            health = merge(health, self.evidence)
        return {
            "drive": self.name, "frames": n, "points": len(self.map),
            "seconds": round(self.seconds, 3), "seconds_per_frame": round(self.seconds / max(n, 1), 4),
            "map_megabytes": round(self.map.nbytes() / 2 ** 20, 2),
            "rejected_steps": [{"frame": r.index, "reason": r.reason} for r in self.reports if not r.accepted],
            "health": health,
            "translation_error_m": {"final": float(dt[-1]), "max": float(dt.max()), "mean": float(dt.mean())},
            "rotation_error_deg": {"final": float(dr[-1]) * 180 / np.pi, "max": float(dr.max()) * 180 / np.pi},
            "confidence": self.confidence,
            "sources": self.sources,
            "settings": self.settings,
            "effective_settings": self.effective_settings,
        }


def run_drive(drive_path: Path, depth_source: str | Path, slam, frames: int | None = None,
              device: str = "cpu", description: str | None = None, settings: dict | None = None,
              confidence: ConfidenceUse = ConfidenceUse(), sources_kind: str | None = None) -> DriveRun:
    """SLAM (a :class:`dcslam.slam.pipeline.SLAM`) over the first ``frames`` frames (all if None) of a drive, with
    depth from ``sparse``, ``dense`` or a layer file, whose confidence (if it has one) is used as ``confidence``
    says. ``sources_kind``: a drive depth kind (e.g. ``sparse@16``) whose pixels the odometry aligns instead of the
    depth's own, against the map fused from the depth (:meth:`~dcslam.slam.pipeline.SLAM.step_frame`'s
    ``source_frame``); None: the depth's own."""
    import torch

    from dcslam.io.drive import DriveFile, load_depth_and_confidence
    from dcslam.progress import Bar
    from dcslam.slam.frame import prepare_frame
    from dcslam.workers import cores_shared

    with DriveFile(drive_path) as drive:
        n = len(drive) if not frames else min(frames, len(drive))
        if n < 1:
            raise DcslamError(f"{drive_path}: no frames")
        check_timestamps(drive.timestamps[:n], str(drive_path))  # before any work, not after it
        depth_all, confidence_all = load_depth_and_confidence(drive, depth_source)
        depth_all = depth_all[:n]
        if confidence_all is not None:
            confidence_all = confidence_all[:n]
        # the depth input already is the measured kind (sparse@16 with --measured sparse@16): its frames serve both
        separate = sources_kind is not None and not (isinstance(depth_source, str) and depth_source == sources_kind)
        sources_all = np.stack([drive.depth(sources_kind, i) for i in range(n)]) if separate else None
        measured = kept = 0
        K = torch.from_numpy(drive.K).float().to(device)
        T_gt = drive.poses[:n]
        slam.T_world_cam0 = torch.from_numpy(T_gt[0]).float()
        slam.reset()
        def prepare(i: int):
            """Frame i made ready for SLAM (it depends on that frame alone), with its measured and kept pixels."""
            depth_np, weight_np = confidence.apply(depth_all[i], None if confidence_all is None
                                                   else confidence_all[i])
            depth = torch.from_numpy(np.ascontiguousarray(depth_np)).to(device)[None, None]
            weight = None if weight_np is None else torch.from_numpy(weight_np).to(device)[None, None]
            rgb = torch.from_numpy(drive.rgb(i)).to(device).permute(2, 0, 1)[None].float() / 255
            frame = prepare_frame(depth, K, rgb, slam.frame_settings, weight)
            source_frame = None
            if sources_all is not None:
                # no weights: the measured pixels are the evidence (a completer's confidence is about its fill)
                sparse = torch.from_numpy(np.ascontiguousarray(sources_all[i])).to(device)[None, None]
                source_frame = prepare_frame(sparse, K, None, slam.frame_settings)
            slam.precompute(frame, source_frame)
            return frame, source_frame, int((depth_all[i] > 0).sum()), int((depth_np > 0).sum())

        start = time.perf_counter()
        # the next frame is read and prepared (normals, colours, ICP sources, surfels) on a second thread while this
        # one is aligned and fused: the same operations on the same values, so the same poses, in less wall time
        # (not in a pool worker: its siblings already keep every core busy, and a second thread only slows them)
        with Bar(description or drive.name, total=n) as bar, prefetcher(not cores_shared()) as submit:
            pending = submit(prepare, 0)
            for i in range(n):
                frame, source_frame, m, k = pending.result()
                measured, kept = measured + m, kept + k
                if i + 1 < n:
                    pending = submit(prepare, i + 1)
                report = slam.step_frame(frame, torch.from_numpy(T_gt[i]).float().to(device),
                                         source_frame=source_frame)
                bar.advance(status=f"{report.points} points" + ("" if report.accepted else " (step rejected)"))
        seconds = time.perf_counter() - start
        poses = slam.trajectory().detach().cpu().double().numpy()
        global_map = slam.mapper.global_map().detach().to("cpu")
        used = {**confidence.record(confidence_all is not None),
                "kept_fraction": round(kept / measured, 4) if measured else 0.0}
        sources = {"mode": "depth"} if sources_kind is None else {"mode": "measured", "kind": sources_kind}
        return DriveRun(drive.name, poses, drive.timestamps[:n].copy(), T_gt.copy(), global_map,
                        list(slam.reports), seconds, dict(settings or {}), used, slam.effective_settings(),
                        slam.health, sources)


def companion_evidence(drive_path: Path, source: str | Path, main: DriveRun, config: SlamStageConfig,
                       sources_kind: str | None = None) -> dict:
    """The evidence verdict of ``main`` (a run over ``source`` on ``drive_path``): :func:`dcslam.slam.evidence.judge`
    against a companion run with the same settings and frames on the measured depth kind behind ``source``
    (:func:`dcslam.io.drive.measured_kind`; with measured ICP sources, ``sources_kind``, the kind they came from, so
    that exact depth aligned by 16-beam points is checked against 16-beam SLAM); ``own`` for a sparse input,
    ``off`` with ``--evidence none``, ``unavailable`` when no measured kind can be named or the drive lacks it."""
    from dcslam.io.drive import DriveFile, is_depth_kind, measured_kind
    from dcslam.slam.config import build_slam
    from dcslam.slam.evidence import judge, unavailable
    from dcslam.slam.health import summarise

    named = None if isinstance(source, Path) else str(source)
    if named is not None and is_depth_kind(named) and measured_kind(named) == named:
        return unavailable(f"{named} is measured depth: its own run is its evidence", "own")
    if config.evidence == "none":
        return unavailable("--evidence none", "off")
    kind = sources_kind or measured_kind(source if named is None or not is_depth_kind(named) else named)
    if kind is None:
        return unavailable(f"{source} does not say which measured depth it was made from")
    with DriveFile(drive_path) as drive:
        has_kind = kind in drive.kinds
    if not has_kind:
        return unavailable(f"{drive_path.name} holds no {kind} depth")
    slam = build_slam(config.settings())
    companion = run_drive(drive_path, kind, slam, config.frames or None, config.device,
                          description=f"{drive_path.stem} companion {kind}")
    verdict = judge(main.T_world_cam, companion.T_world_cam,
                    summarise(companion.reports, *([companion.health_rules] if companion.health_rules else [])),
                    kind)
    final = np.linalg.norm(companion.T_world_cam[-1, :3, 3] - companion.T_gt[-1, :3, 3])
    return {**verdict, "companion_final_error_m": round(float(final), 4),
            "companion_seconds": round(companion.seconds, 3)}


@contextlib.contextmanager
def prefetcher(enabled: bool = True):
    """A one-thread pool for work ahead of the frame loop, as ``submit(fn, *args) -> Future``. The thread runs torch
    with the caller's thread count (a new thread would otherwise get torch's default), so its results are those
    the caller would compute. On leaving, work not yet started is cancelled and the running one waited for.
    Not ``enabled`` (e.g. in a pool worker whose siblings keep the other cores busy): ``submit`` runs the work at
    once, in the caller's thread."""
    import concurrent.futures

    import torch

    if not enabled:
        def submit(fn, *args):
            future = concurrent.futures.Future()
            try:
                future.set_result(fn(*args))
            except BaseException as exc:              # delivered by future.result(), as from the pool
                future.set_exception(exc)
            return future

        yield submit
        return
    pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="dcslam-prefetch",
                                                 initializer=torch.set_num_threads,
                                                 initargs=(torch.get_num_threads(),))
    try:
        yield pool.submit
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def output_paths(out_dir: Path, name: str) -> dict[str, Path]:
    return {"trajectory": out_dir / f"{name}.txt", "kitti_poses": out_dir / f"{name}.kitti.txt",
            "map": out_dir / f"{name}.ply", "summary": out_dir / f"{name}.json"}


def check_outputs(out_dir: Path, name: str, force: bool) -> None:
    """Fail before any work if an output exists and ``force`` is false."""
    for path in output_paths(out_dir, name).values():
        if path.exists() and not force:
            raise DcslamError(f"{path} exists; pass --force to overwrite it")


def check_timestamps(timestamps: np.ndarray, where: str) -> np.ndarray:
    """``timestamps`` (N,) as float64 seconds, or a :class:`DcslamError` when they are not finite and strictly
    increasing: a trajectory is paired with its reference by time, so invented stamps would pair the wrong poses."""
    t = np.asarray(timestamps, dtype=np.float64)
    if t.ndim != 1:
        raise DcslamError(f"{where}: timestamps of shape {t.shape}, expected (N,)")
    bad = np.flatnonzero(~np.isfinite(t))
    if len(bad):
        raise DcslamError(f"{where}: timestamp of frame {bad[0]} is not finite; rebuild the drive file "
                          "(dcslam prepare-kitti --force)")
    steps = np.flatnonzero(np.diff(t) <= 0)
    if len(steps):
        i = int(steps[0]) + 1
        raise DcslamError(f"{where}: timestamps are not strictly increasing (frame {i} at {t[i]:.6f} s after frame "
                          f"{i - 1} at {t[i - 1]:.6f} s{f', and {len(steps) - 1} more' if len(steps) > 1 else ''}); "
                          "the trajectory could not be paired with its reference by time: fix the source's "
                          "timestamps (image_02/timestamps.txt for KITTI) and rebuild the drive file "
                          "(dcslam prepare-kitti --force)")
    return t


def write_outputs(run: DriveRun, out_dir: Path, force: bool = False) -> dict[str, Path]:
    """Write ``run``'s trajectory (TUM with the drive's own timestamps, and KITTI poses), map and summary; fails
    before writing anything when the timestamps are not strictly increasing (:func:`check_timestamps`)."""
    from dcslam.io.kitti_poses import write_kitti_poses
    from dcslam.io.ply import write_ply
    from dcslam.io.tum import write_tum
    from dcslam.io.atomic import write_json_atomic
    from dcslam.workspace import stage_config

    paths = output_paths(out_dir, run.name)
    check_outputs(out_dir, run.name, force)
    timestamps = check_timestamps(run.timestamps, run.name)
    write_tum(paths["trajectory"], timestamps, run.T_world_cam, force=force)
    write_kitti_poses(paths["kitti_poses"], run.T_world_cam, force=force)
    pm = run.map
    write_ply(paths["map"], pm.points.numpy(), pm.normals.numpy(), pm.colors.clamp(0, 1).numpy(), force=force)
    record = stage_config("slam", run.settings)
    record.update(run.summary())
    write_json_atomic(paths["summary"], record, force=force)
    return paths
