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
import os
from collections.abc import Callable
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.slam.config import SlamSettings
from dcslam.slam.drive import ConfidenceUse, DriveRun, check_timestamps, run_drive
from dcslam.stages.config import option
from dcslam.workers import OwnLoad, cores_shared
from dcslam.workspace import Workspace


#: Whether a run on completed depth gets an independent companion on its measured pixels (``--evidence``).
EVIDENCE_USES = ("auto", "none")

#: How SLAM uses a depth layer's per-pixel confidence (``--confidence``).
CONFIDENCE_USES = ("weights", "mask", "ignore")
#: Which points the odometry aligns (``--sources``): the depth input's own, or the measured LiDAR pixels behind it.
SOURCES = ("depth", "measured")


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
        "measured LiDAR pixels behind it and flag the run when it ends further from that companion (its height and "
        "tilt corrected by the road it saw) than the companion's own uncertainty allows; none: no companion (the "
        "summary says that no evidence bounds the drift). A sparse input is its own evidence."))
    camera: bool = option(True, help=(
        "Also measure each step again from the drive's colour images (the measured LiDAR depth behind the input "
        "warped from frame to frame) and judge the run by that camera trajectory: suspect when it ends more than "
        "0.5 m from it; when within, its own steps' reasons are overruled (the road's and the companion's stay). Uses "
        "data beyond the depth; one pass (about 0.1-0.2 CPU-s a full-size frame) per drive and measured depth, kept "
        "in <drives>/.camera/ and shared by every input made from that depth. It abstains, and says so, where the "
        "images cannot measure the steps (blank, or unrelated to the depth). --no-camera: the depth's own evidence "
        "alone."))
    record: bool = option(False, help=(
        "Also write a Rerun recording <out>/<drive>.rrd per drive: per frame the camera image, input depth, points, "
        "ICP sources, map and step verdict, and the trajectories; open it with `dcslam view`. Needs rerun-sdk "
        "(pip install 'dcslam[viz]', Python >= 3.11)."))

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

    def confidence_use(self) -> ConfidenceUse:
        return ConfidenceUse(self.confidence, self.min_confidence)

    def settings(self) -> SlamSettings:
        """The SLAM algorithm's own settings (what :func:`dcslam.slam.config.build_slam` takes)."""
        return SlamSettings(**{f.name: getattr(self, f.name) for f in fields(SlamSettings)})


@dataclass
class SlamDriveResult:
    """One drive: its summary (:meth:`dcslam.slam.drive.DriveRun.summary`) and the files written."""

    drive: str
    summary: dict
    written: dict[str, Path]


def run(ws: Workspace, config: SlamStageConfig, *, force: bool = False) -> list[SlamDriveResult]:
    """SLAM over every selected drive; all outputs are checked not to exist (without ``force``) before any work."""
    from dcslam.workspace import drive_file, layer_reference, output_folder, resolve_layer, select_drives

    names = select_drives(ws, config.drive)  # an empty test split is an error, not a run over nothing
    paths = [drive_file(ws, name) for name in names]
    layer = resolve_layer(ws, layer_reference(config.depth, config.run))
    out_dir = config.out if config.out is not None else ws.slam / layer.name
    output_folder(out_dir, "--out")
    from dcslam.device import resolve_device

    resolve_device(config.device)  # a GPU asked for on a CPU-only torch: one line, before any work
    if config.record:
        from dcslam.slam.record import require_rerun

        require_rerun()  # rerun-sdk missing: one line, before any work
    from dcslam.io.lineage import check_layer_folder
    from dcslam.locks import output_lock

    check_layer_folder(layer.folder)  # a layer made from an input that changed since is refused
    # one writer per drive's outputs, taken for every drive before anything is checked or written: the SLAM stages
    # of one layer's drives run side by side (reproduce --jobs, a Slurm array), each writing only its own drive
    with contextlib.ExitStack() as locks:
        for path in sorted(paths):
            locks.enter_context(output_lock(out_dir / path.stem, "SLAM output"))
        return _run_drives(config, layer, paths, out_dir, force)


def _run_drives(config: SlamStageConfig, layer, paths: list[Path], out_dir: Path,
                force: bool) -> list[SlamDriveResult]:
    """SLAM over the drive files ``paths`` with depth from ``layer``, into ``out_dir`` (its lock held)."""
    from dcslam.allocator import fix_allocator

    jobs = []
    for path in paths:
        source = layer.require(path.stem)
        check_outputs(out_dir, path.stem, force, config.record)
        if config.min_confidence > 0 and not has_confidence(source):
            raise DcslamError(f"--min-confidence {config.min_confidence}: {source} holds no confidence (only layers "
                              f"predicted by a confidence-aware model such as `dcslam train --model nconv` have one); "
                              f"drop --min-confidence")
        jobs.append((path, source, measured_sources(config, source, path)))
    results = []
    # glibc's thresholds fixed and one malloc arena keep a long run's peak memory flat (glibc's own settings let the
    # heap fragment: +16 % peak from frame 200 to 1,000) and stop it faulting the heap's top in again every frame;
    # glibc's MALLOC_* variables in the environment override them (dcslam.allocator)
    fix_allocator()
    from dcslam import interrupt
    from dcslam.io.lineage import made_from

    interrupt.keep(lambda: _kept_line(out_dir, [path.stem for path, _, _ in jobs]))

    with torch_threads(config.threads):
        for path, source, measured in jobs:
            inputs = made_from({"depth": source if isinstance(source, Path) else None}, out_dir)  # as it is read
            results.append(slam_drive(path, source, measured, config, out_dir, force, inputs))
    suspect = [r for r in results if r.summary["health"]["suspect"]]
    if config.strict and suspect:
        raise DcslamError("suspect trajectories (--strict): " + "; ".join(
            f"{r.drive}: {', '.join(r.summary['health']['reasons'])}" for r in suspect)
            + f"; outputs written under {out_dir}")
    return results


def _kept_line(out_dir: Path, drives: list[str]) -> str | None:
    """What an interrupt leaves: the drives whose outputs are committed in ``out_dir`` (None: none of them)."""
    from dcslam.io.atomic import is_committed

    done = [drive for drive in drives if is_committed(out_dir / f"{drive}.done")]
    if not done:
        return None
    return (f"the SLAM outputs of {', '.join(done)} are kept, complete, in {out_dir} (the drive being run left "
            "none that a reader takes); rerun with --drive naming the others, or the same command with --force")


def slam_drive(path: Path, source: str | Path, measured: str | None, config: SlamStageConfig, out_dir: Path,
               force: bool, made_from: dict | None = None) -> SlamDriveResult:
    """One drive: SLAM over it, its companion evidence and its outputs (``made_from``: its inputs' identities,
    :func:`write_outputs`); with ``config.record`` also its recording (:mod:`dcslam.slam.record`), which a
    companion run adds its trajectory to."""
    from dcslam.slam.config import build_slam
    from dcslam.slam.record import drive_recording, recording_path
    from dcslam.stages.config import to_dict

    recording = recording_path(out_dir, path.stem)
    with drive_recording(recording, force) if config.record else contextlib.nullcontext() as recorder:
        companions: list[DriveRun] = []
        with companion_evidence(path, source, config, measured, companions.append) as evidence:  # beside the run
            drive_run = run_drive_file(path, source, build_slam(config.settings()), config.frames or None,
                                       config.device, settings={**to_dict(config), "source": str(source)},
                                       confidence=config.confidence_use(), sources_kind=measured,
                                       on_step=None if recorder is None else recorder.step)
            drive_run.name = path.stem
            drive_run.evidence = evidence(drive_run)
        if config.camera:  # started from the companion's steps where one ran: one camera for every input
            drive_run.camera = camera_evidence(path, source, measured, drive_run,
                                               companions[0].T_world_cam if companions else None)
        written = write_outputs(drive_run, out_dir, force, made_from)
        if recorder is not None:
            recorder.finish(drive_run, companions[0] if companions else None)
    if config.record:
        written["recording"] = recording
    return SlamDriveResult(path.stem, drive_run.summary(), written)


def camera_evidence(drive_path: Path, source: str | Path, sources_kind: str | None, run: DriveRun,
                    start: np.ndarray | None = None) -> dict:
    """The camera's verdict on ``run`` (:func:`dcslam.slam.camera.judge_camera`): its steps measured again from the
    drive's images with the measured depth behind ``source`` (``sources_kind`` when the ICP took its sources from
    one; :func:`dcslam.io.drive.measured_kind` else), each started from the trajectory ``start`` (the companion's;
    None: the run's own) where the camera has no step of its own, ``measured_kind`` and ``started_from`` recorded;
    ``unmeasured`` with the reason when no measured kind can be named or the drive lacks it.

    Its steps depend on the drive, the measured kind and ``start`` alone, so they are kept in ``<drives>/.camera/``
    (:func:`camera_steps`) and every input whose companion is the same run shares them."""
    from dcslam.io.drive import DriveFile, measured_kind
    from dcslam.slam.camera import camera_trajectory, judge_camera

    kind = sources_kind or measured_kind(source)
    with DriveFile(drive_path) as drive:
        missing = kind is None or kind not in drive.kinds
    if missing:
        why = f"{source} does not say which measured depth it was made from" if kind is None else \
            f"{drive_path.name} holds no {kind} depth"
        return {"verdict": "unmeasured", "suspect": False, "reason": None, "measured_kind": kind, "note": why}
    T = run.T_world_cam
    steps = camera_steps(drive_path, kind, T if start is None else start)
    return {**judge_camera(T, camera_trajectory(T, steps), steps), "measured_kind": kind,
            "started_from": "run" if start is None else "companion"}


def camera_steps(drive_path: Path, kind: str, start: np.ndarray) -> list:
    """The camera's steps over ``drive_path`` with measured depth ``kind``, started from the trajectory ``start``
    (:func:`dcslam.slam.camera.witness`; (N, 4, 4), from the drive's first frame): read from
    ``<drives>/.camera/<drive>-<state>-<key>.npz`` when an earlier run of this code made them from the same drive
    file, kind and start (``state`` hashes the code and the drive file, the key all four), else measured and kept
    there (atomically; a folder that cannot be written keeps nothing, an unreadable file is measured again). Keeping
    one removes the drive's files of another state (other code, a drive file since rewritten): no run reads them."""
    import hashlib

    from dcslam.io.camera_steps import read_camera_steps, write_camera_steps
    from dcslam.io.drive import DriveFile
    from dcslam.progress import Bar
    from dcslam.slam.camera import CameraStep, witness
    from dcslam.stages.config import code_version

    start = np.ascontiguousarray(start, np.float64)
    stat = drive_path.stat()
    made_from = f"{code_version()}|{drive_path.name}|{stat.st_size}|{stat.st_mtime_ns}"  # the code and the drive file
    key = hashlib.sha256(f"{made_from}|{kind}".encode() + start.tobytes()).hexdigest()[:20]
    state = hashlib.sha256(made_from.encode()).hexdigest()[:8]
    kept = drive_path.parent / ".camera" / f"{drive_path.stem}-{state}-{key}.npz"
    read = read_camera_steps(kept, len(start) - 1)
    if read is not None:
        return [CameraStep(T, covariance, int(n), bool(ok)) for T, covariance, n, ok in zip(*read)]
    with DriveFile(drive_path) as drive, Bar(f"{drive_path.stem} camera {kind}", len(start) - 1) as bar:
        steps = witness(drive, kind, start, progress=bar.advance)[1]
    if steps:  # a cache: a folder that cannot be written keeps nothing
        write_camera_steps(kept, np.stack([s.T for s in steps]), np.stack([s.covariance for s in steps]),
                           np.array([s.returns for s in steps]), np.array([s.measured for s in steps]))
        if kept.exists():
            _forget_other_states(kept.parent, drive_path.stem, state)
    return steps


def _forget_other_states(folder: Path, stem: str, state: str) -> None:
    """Remove the kept camera steps of drive ``stem`` made from another ``state`` (and those named before states
    were), leaving every other drive's and this state's."""
    import glob
    import re

    pattern = re.compile(rf"{re.escape(stem)}-(?:([0-9a-f]{{8}})-)?[0-9a-f]{{20}}\.npz")
    for path in folder.glob(f"{glob.escape(stem)}-*.npz"):
        match = pattern.fullmatch(path.name)
        if match and match.group(1) != state:
            with contextlib.suppress(OSError):  # gone already, or a folder that cannot be written
                path.unlink()


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


def run_drive_file(drive_path: Path, source: str | Path, slam, frames: int | None = None, device: str = "cpu",
                   description: str | None = None, colour: bool = True, **options) -> DriveRun:
    """:func:`dcslam.slam.drive.run_drive` over the first ``frames`` frames (all if None) of the drive file
    ``drive_path`` with depth from ``source`` (a depth kind of the drive or a layer file), read as they are used
    (:func:`dcslam.io.drive_frames.drive_frames`); ``colour`` False: the colour images are not read and the map is
    grey (the poses are the same); ``options``: run_drive's (``sources_kind``: the drive depth kind whose pixels the
    odometry aligns, e.g. ``sparse@16``)."""
    from dcslam.io.drive_frames import drive_frames

    with drive_frames(drive_path, source, frames, options.get("sources_kind"), colour) as drive:
        return run_drive(drive, slam, device, description, **options)


@contextlib.contextmanager
def companion_evidence(drive_path: Path, source: str | Path, config: SlamStageConfig,
                       sources_kind: str | None = None, keep: Callable[[DriveRun], None] | None = None):
    """A function of ``main`` (the run over ``source`` on ``drive_path``) giving its evidence verdict:
    :func:`dcslam.slam.drive.companion_verdict` against a companion run with the same settings and frames on the
    measured depth kind behind ``source`` (:func:`dcslam.io.drive.measured_kind`; with measured ICP sources,
    ``sources_kind``, the kind they came from, so that exact depth aligned by 16-beam points is checked against
    16-beam SLAM), the companion run (without its map) handed to ``keep`` when given; ``own`` for a sparse input,
    ``off`` with ``--evidence none``, ``unavailable`` when no measured kind can be named or the drive lacks it.

    The companion depends on the drive alone, so it starts on entering the block, in a spawned worker process when
    a core is free (:func:`companion_beside`), and runs while the block runs the main one: its wall time hides on
    the other core (else it runs after the main one, in this process). Its torch thread count is the caller's, so
    its poses are those it would compute here."""
    from dcslam.io.drive import DriveFile, is_depth_kind, measured_kind
    from dcslam.slam.drive import companion_verdict
    from dcslam.slam.evidence import unavailable

    named = None if isinstance(source, Path) else str(source)
    if named is not None and is_depth_kind(named) and measured_kind(named) == named:
        yield lambda main: unavailable(f"{named} is measured depth: its own run is its evidence", "own")
        return
    if config.evidence == "none":
        yield lambda main: unavailable("--evidence none", "off")
        return
    kind = sources_kind or measured_kind(source if named is None or not is_depth_kind(named) else named)
    if kind is None:
        yield lambda main: unavailable(f"{source} does not say which measured depth it was made from")
        return
    with DriveFile(drive_path) as drive:
        has_kind = kind in drive.kinds
        frames, height, width = drive.shape
    if not has_kind:
        yield lambda main: unavailable(f"{drive_path.name} holds no {kind} depth")
        return
    import torch

    args = (drive_path, kind, config, torch.get_num_threads(), f"{drive_path.stem} companion {kind}")

    measured = named is not None and is_depth_kind(named)    # dense or exact depth: not a completion

    def verdict(main: DriveRun, companion: DriveRun) -> dict:
        if keep is not None:
            keep(companion)
        return companion_verdict(main, companion, kind, measured=measured)

    if not companion_beside(config, min(config.frames or frames, frames) * height * width):
        yield lambda main: verdict(main, companion_run(*args))
        return
    from dcslam.workers import process_pool

    with process_pool(1, 1) as pool:
        companion = pool.submit(companion_run, *args, progress=False)
        yield lambda main: verdict(main, _companion_result(companion, args))


def _companion_result(companion, args: tuple) -> DriveRun:
    """The companion run of a worker (``companion``: its future), or, where the worker died (killed for memory, or a
    calling script without a ``__main__`` guard ran itself again in it), the same run made here (``args``:
    :func:`companion_run`'s), with one line saying so: its verdict is the same either way."""
    from concurrent.futures.process import BrokenProcessPool

    try:
        return companion.result()
    except BrokenProcessPool:
        import sys

        sys.stderr.write(f"note: the companion worker of {Path(args[0]).name} stopped; running the companion in this "
                         "process\n")
        return companion_run(*args)


#: Pixels (frames x height x width) a companion run must cover before it goes to a worker process of its own: the
#: worker (its start: importing torch and dcslam) costs 0.9-1.6 CPU-seconds more, on the core the main run's
#: prefetch thread also uses, so a shorter companion ends later beside the main run than after it (measured on a
#: quiet machine, docs/benchmarks.md "The companion check beside the main run": even at 60 full-size frames).
BESIDE_MIN_PIXELS = 60 * 375 * 1242

#: This command's share of the load average since the module was loaded (its start): what its earlier drives put
#: there is no other process's work.
OWN_LOAD = OwnLoad()


def companion_beside(config: SlamStageConfig, pixels: int) -> bool:
    """Whether the companion run over ``pixels`` (frames x height x width) goes to a second process beside the main
    run: on the CPU, when this process is no pool worker whose siblings keep every core busy
    (:func:`dcslam.workers.cores_shared`), a core is free besides the main run's torch threads (the load average
    of the last minute, less this command's own share of it (:data:`OWN_LOAD`), below ``cores - threads - 0.5``:
    on a busy machine the worker only competes, measured 25 s serial against 31-36 s beside at load 5.5 on 2 cores)
    and the run is long enough to pay for the worker's start (:data:`BESIDE_MIN_PIXELS`)."""
    import torch

    threads = config.threads or torch.get_num_threads()
    others = max(0.0, os.getloadavg()[0] - OWN_LOAD.read())
    free = (os.cpu_count() or 1) - threads - others
    return config.device == "cpu" and not cores_shared() and free > 0.5 and pixels >= BESIDE_MIN_PIXELS


def companion_run(drive_path: Path, kind: str, config: SlamStageConfig, threads: int, description: str,
                  progress: bool = True) -> DriveRun:
    """The companion SLAM run over the measured depth ``kind`` of a drive, with ``threads`` torch threads (those of
    the main run); ``progress``: its progress bar (off in a worker beside the main run's bar)."""
    import torch

    from dcslam.slam.config import build_slam

    if not progress:
        os.environ["DCSLAM_PROGRESS"] = "0"
    torch.set_num_threads(threads)
    # only its poses and steps are judged and recorded: no colour read, no map carried back from a worker
    run = run_drive_file(drive_path, kind, build_slam(config.settings()), config.frames or None, config.device,
                         description=description, colour=False)
    run.map = None
    return run


def output_paths(out_dir: Path, name: str) -> dict[str, Path]:
    """A drive's SLAM outputs; ``done`` is the marker that commits them (written last,
    :class:`dcslam.io.atomic.CommittedSet`): readers take only a committed set."""
    return {"trajectory": out_dir / f"{name}.txt", "kitti_poses": out_dir / f"{name}.kitti.txt",
            "map": out_dir / f"{name}.ply", "summary": out_dir / f"{name}.json", "done": out_dir / f"{name}.done"}


def check_outputs(out_dir: Path, name: str, force: bool, record: bool = False) -> None:
    """Fail before any work if an output (with ``record``, the recording too) exists and ``force`` is false."""
    from dcslam.slam.record import recording_path

    for path in [*output_paths(out_dir, name).values(), *([recording_path(out_dir, name)] if record else [])]:
        if path.exists() and not force:
            raise DcslamError(f"{path} exists; pass --force to overwrite it")


def write_outputs(run: DriveRun, out_dir: Path, force: bool = False, made_from: dict | None = None) -> dict[str, Path]:
    """Write ``run``'s trajectory (TUM with the drive's own timestamps, and KITTI poses), map and summary as one
    committed set (``<drive>.done`` written last: a failed write leaves none of them for a reader to take); fails
    before writing anything when the timestamps are not strictly increasing (:func:`check_timestamps`).
    ``made_from``: the identities of the inputs (:func:`dcslam.io.lineage.made_from`), kept in the summary."""
    from dcslam.io.atomic import CommittedSet, write_json_atomic
    from dcslam.io.kitti_poses import write_kitti_poses
    from dcslam.io.lineage import MADE_FROM
    from dcslam.io.ply import write_ply
    from dcslam.io.tum import write_tum
    from dcslam.workspace import stage_config

    paths = output_paths(out_dir, run.name)
    check_outputs(out_dir, run.name, force)
    timestamps = check_timestamps(run.timestamps, run.name)
    record = stage_config("slam", run.settings)
    record.update(run.summary())
    if made_from:
        record[MADE_FROM] = made_from
    out_dir.mkdir(parents=True, exist_ok=True)
    with CommittedSet(paths["done"]) as files:
        write_tum(files.stage(paths["trajectory"]), timestamps, run.T_world_cam, force=True)
        write_kitti_poses(files.stage(paths["kitti_poses"]), run.T_world_cam, force=True)
        pm = run.map
        write_ply(files.stage(paths["map"]), pm.points.numpy(), pm.normals.numpy(), pm.colors.numpy(),   # clipped there
                  force=True)
        write_json_atomic(files.stage(paths["summary"]), record, force=True)
    return paths
