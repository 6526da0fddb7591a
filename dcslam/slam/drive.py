"""SLAM over a drive: frames in, trajectory, map and summary out.

:func:`run_drive` takes a drive's frames as an iterable (:class:`dcslam.io.drive_frames.DriveFrames`, read one at a
time) and prepares the next frame on a second thread while the current one is aligned and fused
(:func:`prefetcher`); :class:`DriveRun` holds what came out and its summary; :func:`companion_verdict` judges a run
against a companion run on the measured depth behind it. No files are read or written here: the ``dcslam slam``
stage (:mod:`dcslam.stages.slam`) opens the frames and writes the outputs.
"""
from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from dcslam.errors import DcslamError

if TYPE_CHECKING:
    from dcslam.io.drive_frames import DepthFrame, DriveFrames


@dataclass(frozen=True)
class ConfidenceUse:
    """What SLAM does with a layer's confidence: ``mode`` one of ``weights``, ``mask``, ``ignore``
    (:data:`dcslam.stages.slam.CONFIDENCE_USES`), pixels below ``minimum`` dropped (weights, mask)."""

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
    camera: dict | None = None  # dcslam.slam.camera.judge_camera, with the measured kind (None: not asked)

    def __post_init__(self) -> None:
        from dcslam.geometry.rotations import nearest_rotation

        # poses composed in float32 leave SO(3) by ~1e-4 over a drive: written and scored as the nearest rotations
        T = np.array(self.T_world_cam, dtype=np.float64)
        T[:, :3, :3] = nearest_rotation(T[:, :3, :3])
        self.T_world_cam = T

    def health(self) -> dict:
        """The run's health (:func:`dcslam.slam.health.summarise`), merged with its evidence verdict and then its
        camera verdict, where it has them."""
        from dcslam.slam.health import HealthRules, summarise

        health = summarise(self.reports, self.health_rules or HealthRules(), self.frame_interval_s())
        if self.evidence is not None:
            from dcslam.slam.evidence import merge

            health = merge(health, self.evidence)
        if self.camera is not None:
            from dcslam.slam.camera import merge_camera

            health = merge_camera(health, self.camera)
        return health

    def frame_interval_s(self) -> float | None:
        """The median time between the run's frames (s), None when its timestamps do not say (fewer than two, or
        not increasing)."""
        t = np.asarray(self.timestamps, dtype=np.float64).reshape(-1)
        steps = np.diff(t)
        return float(np.median(steps)) if len(steps) and np.isfinite(steps).all() and (steps > 0).all() else None

    def road_corrected(self) -> np.ndarray | None:
        """The trajectory corrected by the road planes of the run's own frames
        (:func:`dcslam.slam.road.road_corrected`; steps between frames without a road as estimated), or None when
        its health rules fit no road (``max_road_drift_m`` 0). Shape: (N, 4, 4)."""
        from dcslam.slam.health import HealthRules
        from dcslam.slam.road import road_corrected

        if (self.health_rules or HealthRules()).max_road_drift_m <= 0:
            return None
        return road_corrected(self.T_world_cam, [getattr(r, "road", None) for r in self.reports])

    def summary(self) -> dict:
        import torch

        from dcslam.geometry.se3 import pose_error

        dt, dr = pose_error(torch.from_numpy(self.T_gt), torch.from_numpy(self.T_world_cam))
        n = len(self.reports)
        return {
            "drive": self.name, "frames": n, "points": len(self.map),
            "seconds": round(self.seconds, 3), "seconds_per_frame": round(self.seconds / max(n, 1), 4),
            "map_megabytes": round(self.map.nbytes() / 2 ** 20, 2),
            "rejected_steps": [{"frame": r.index, "reason": r.reason} for r in self.reports if not r.accepted],
            "health": self.health(),
            "translation_error_m": {"final": float(dt[-1]), "max": float(dt.max()), "mean": float(dt.mean())},
            "rotation_error_deg": {"final": float(dr[-1]) * 180 / np.pi, "max": float(dr.max()) * 180 / np.pi},
            "confidence": self.confidence,
            "sources": self.sources,
            "settings": self.settings,
            "effective_settings": self.effective_settings,
        }


def run_drive(drive: DriveFrames, slam, device: str = "cpu", description: str | None = None,
              settings: dict | None = None, confidence: ConfidenceUse = ConfidenceUse(),
              sources_kind: str | None = None, on_step: Callable | None = None) -> DriveRun:
    """SLAM (a :class:`dcslam.slam.pipeline.SLAM`, reset here) over every frame of ``drive``, whose confidence (if
    it has one) is used as ``confidence`` says. A frame's ``sources`` depth, when given, holds the pixels the
    odometry aligns instead of the depth's own, against the map fused from the depth
    (:meth:`~dcslam.slam.pipeline.SLAM.step_frame`'s ``source_frame``); ``sources_kind`` names that depth kind for
    the summary (None: the depth's own points). The frames are read and prepared one ahead, on a second thread.
    ``on_step(slam, report, frame, source_frame)``, when given, is called after each step in the loop's thread
    (e.g. :class:`dcslam.slam.record.SlamRecorder`): the run knows nothing of what it does with them."""
    import torch

    from dcslam.progress import Bar
    from dcslam.workers import cores_shared

    n = len(drive)
    if n < 1:
        raise DcslamError(f"{drive.where}: no frames")
    check_timestamps(drive.timestamps, drive.where)  # before any work, not after it
    K = torch.from_numpy(drive.K).float().to(device)
    slam.T_world_cam0 = torch.from_numpy(drive.T_world_cam[0]).float()
    slam.reset()
    prepare = frame_preparer(slam, K, device, confidence)
    frames, counts = iter(drive.frames), [0, 0]  # measured, kept pixels
    start = time.perf_counter()
    # the next frame is read and prepared (normals, colours, ICP sources, surfels) on a second thread while this one
    # is aligned and fused: the same operations on the same values, so the same poses, in less wall time (not in a
    # pool worker: its siblings already keep every core busy, and a second thread only slows them)
    with Bar(description or drive.name, total=n) as bar, prefetcher(not cores_shared()) as submit:
        pending = submit(lambda: prepare(_next_frame(frames, drive.where)))
        for i in range(n):
            frame, source_frame, measured, kept = pending.result()
            counts = [counts[0] + measured, counts[1] + kept]
            if i + 1 < n:
                pending = submit(lambda: prepare(_next_frame(frames, drive.where)))
            report = slam.step_frame(frame, torch.from_numpy(drive.T_world_cam[i]).float().to(device),
                                     source_frame=source_frame)
            if on_step is not None:
                on_step(slam, report, frame, source_frame)
            bar.advance(status=f"{report.points} points" + ("" if report.accepted else " (step rejected)"))
    seconds = time.perf_counter() - start
    used = {**confidence.record(drive.has_confidence),
            "kept_fraction": round(counts[1] / counts[0], 4) if counts[0] else 0.0}
    sources = {"mode": "depth"} if sources_kind is None else {"mode": "measured", "kind": sources_kind}
    return DriveRun(drive.name, slam.trajectory().detach().cpu().double().numpy(), drive.timestamps.copy(),
                    drive.T_world_cam.copy(), slam.mapper.global_map().detach().to("cpu"), list(slam.reports),
                    seconds, dict(settings or {}), used, slam.effective_settings(), slam.health, sources)


def _next_frame(frames, where: str) -> DepthFrame:
    try:
        return next(frames)
    except StopIteration:
        raise DcslamError(f"{where}: fewer frames than its poses") from None


def frame_preparer(slam, K, device: str, confidence: ConfidenceUse) -> Callable[[DepthFrame], tuple]:
    """A function making a drive frame ready for ``slam`` -> (frame, source frame or None, measured pixels, kept
    pixels); it depends on that frame alone, so it may run on another thread. K: (3, 3) on ``device``."""
    import torch

    from dcslam.slam.frame import prepare_frame

    def prepare(item: DepthFrame) -> tuple:
        depth_np, weight_np = confidence.apply(item.depth, item.confidence)
        depth = torch.from_numpy(np.ascontiguousarray(depth_np)).to(device)[None, None]
        weight = None if weight_np is None else torch.from_numpy(weight_np).to(device)[None, None]
        # uint8: read at the valid pixels only; None: a map without colours (grey), the same geometry
        rgb = None if item.rgb is None else torch.from_numpy(item.rgb).to(device).permute(2, 0, 1)[None]
        frame = prepare_frame(depth, K, rgb, slam.frame_settings, weight)
        source_frame = None
        if item.sources is not None:
            # no weights: the measured pixels are the evidence (a completer's confidence is about its fill)
            sparse = torch.from_numpy(np.ascontiguousarray(item.sources)).to(device)[None, None]
            source_frame = prepare_frame(sparse, K, None, slam.frame_settings)
        slam.precompute(frame, source_frame)
        measured = int(np.count_nonzero(item.depth > 0))
        kept = measured if depth_np is item.depth else int(np.count_nonzero(depth_np > 0))
        return frame, source_frame, measured, kept

    return prepare


def companion_verdict(main: DriveRun, companion: DriveRun, kind: str, rules=None, measured: bool = False) -> dict:
    """The evidence verdict of ``main`` against ``companion``, a run with the same settings and frames on the
    measured depth kind ``kind`` behind ``main``'s input (:func:`dcslam.slam.evidence.judge` under ``rules``, an
    :class:`~dcslam.slam.evidence.EvidenceRules`; None: the defaults; ``measured``: ``main``'s depth was measured,
    not completed), with the companion's final error against the ground truth, as run and road-corrected, and its
    seconds.

    When its health rules fit the road (``max_road_drift_m`` above 0), the companion's trajectory is road-corrected
    (:func:`dcslam.slam.road.road_corrected`: its pitch, roll and height from the road planes of its own frames) and
    the companion is judged without the road rule, which that correction answers (a sparse run's largest error at
    8 and 16 beams is vertical: docs/slam.md, "Independent evidence for completed depth")."""
    from dataclasses import replace

    from dcslam.slam.evidence import EvidenceRules, judge
    from dcslam.slam.health import HealthRules, summarise

    health_rules = companion.health_rules or HealthRules()
    T = companion.road_corrected()
    corrected = T is not None
    if corrected:
        health_rules = replace(health_rules, max_road_drift_m=0.0)
    else:
        T = companion.T_world_cam
    verdict = judge(main.T_world_cam, T, summarise(companion.reports, health_rules, companion.frame_interval_s()), kind,
                    rules or EvidenceRules(), road_corrected=corrected, measured=measured)
    final, fixed = (float(np.linalg.norm(t[-1, :3, 3] - companion.T_gt[-1, :3, 3])) for t in (companion.T_world_cam, T))
    return {**verdict, "companion_final_error_m": round(final, 4), "companion_corrected_error_m": round(fixed, 4),
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
