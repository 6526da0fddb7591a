"""Rerun recordings of SLAM runs (``dcslam slam --record``): one ``<drive>.rrd`` per drive, scrubbed through in the
Rerun viewer (``dcslam view``), to watch a map being built and see where completed depth puts its outliers.

On the ``frame`` sequence timeline, per frame: ``world/camera`` (the estimated pose, Transform3D),
``world/camera/image`` (its Pinhole, the camera image and the input depth, a 16-bit PNG), ``world/frame/points``
(the input depth's points in the world, coloured by the image), ``world/frame/sources`` (the points ICP aligned,
coloured by their weight when the depth has a confidence, else by their distance to the map as it stood before the
frame: green near, red at :data:`RESIDUAL_RED` voxels or more), ``world/map`` every :data:`MAP_EVERY` frames and at
the last (decimated to :data:`MAP_POINTS`), ``steps/verdict`` (TextLog: the step's verdict and its reasons) and the
scalars ``steps/pairs``, ``steps/sources``, ``steps/conditioning``, ``steps/gap_m`` and ``steps/verdict_level``
(0 accepted, 1 degraded, 2 rejected). Static: ``world/trajectory/estimated``, ``world/trajectory/ground_truth`` and,
when the stage ran one, ``world/trajectory/companion`` and, when its rules fit the road,
``world/trajectory/companion_road_corrected`` (the trajectory its evidence verdict judged the run against:
:meth:`dcslam.slam.drive.DriveRun.road_corrected`) (LineStrips3D of the camera positions, metres), logged when
the run is done.

Rerun (``rerun-sdk``, the ``viz`` extra, Python >= 3.11) is imported only here and only when a recording is asked
for; the SLAM loop knows nothing of it (:func:`dcslam.slam.drive.run_drive` calls a per-step callback).
"""
from __future__ import annotations

import contextlib
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError

#: The recording's file suffix, beside the drive's trajectory and summary.
SUFFIX = ".rrd"
#: The map is logged every this many frames (and at the last): often enough to watch it grow, rarely enough that a
#: recording of a long drive stays tens of megabytes.
MAP_EVERY = 10
#: At most this many map points per logged map, and per frame's point cloud (every k-th point kept).
MAP_POINTS = 50_000
FRAME_POINTS = 10_000
#: Source points this many effective voxels or more from the map are drawn fully red.
RESIDUAL_RED = 5.0
#: The input depth is stored as a 16-bit PNG in units of 1/DEPTH_UNITS m (3.9 mm steps up to 256 m): a tenth of the
#: float image's bytes for LiDAR depth, a third for dense depth.
DEPTH_UNITS = 256.0
#: Verdicts as a number for a scalar plot, and as a text-log level.
VERDICT_LEVELS = {"accepted": 0, "degraded": 1, "rejected": 2}
TEXT_LEVELS = {"accepted": "INFO", "degraded": "WARN", "rejected": "ERROR"}
INSTALL = "pip install 'dcslam[viz]'"


def require_rerun():
    """The ``rerun`` module, or a :class:`DcslamError` saying how to get it (before any SLAM work is done)."""
    if sys.version_info < (3, 11):
        raise DcslamError(f"--record: Rerun recordings need Python >= 3.11 (rerun-sdk), this is "
                          f"{sys.version_info.major}.{sys.version_info.minor}; run without --record")
    try:
        import rerun
    except ImportError:
        raise DcslamError(f"--record needs rerun-sdk: {INSTALL}") from None
    return rerun


def recording_path(out_dir: Path, name: str) -> Path:
    """Where a drive's recording goes: ``<out_dir>/<name>.rrd``, beside its summary."""
    return Path(out_dir) / f"{name}{SUFFIX}"


def every_kth(points: np.ndarray, limit: int) -> np.ndarray:
    """Every k-th row of ``points`` (N, ...) with k the smallest step that keeps at most ``limit`` rows."""
    k = max(1, -(-len(points) // limit))
    return points[::k]


def depth_png(depth_m: np.ndarray) -> bytes:
    """Depth (H, W) in metres as a single-channel 16-bit PNG in units of 1/:data:`DEPTH_UNITS` m (0: none)."""
    import cv2

    units = np.clip(np.round(np.nan_to_num(depth_m, nan=0.0) * DEPTH_UNITS), 0, 65535).astype(np.uint16)
    ok, png = cv2.imencode(".png", units)
    if not ok:
        raise DcslamError(f"could not encode a depth image of shape {depth_m.shape} as PNG")
    return png.tobytes()


def positions(T_world_cam: np.ndarray) -> np.ndarray:
    """Camera positions (N, 3) float32 of poses (N, 4, 4)."""
    return np.ascontiguousarray(np.asarray(T_world_cam)[:, :3, 3], dtype=np.float32)


def ramp(values: np.ndarray) -> np.ndarray:
    """Colours (N, 3) uint8 from green (0) to red (1) of ``values`` (N,) clipped to [0, 1]."""
    v = np.clip(np.nan_to_num(values, nan=1.0), 0.0, 1.0)[:, None]
    return (255 * ((1 - v) * np.array([0.1, 0.8, 0.2]) + v * np.array([0.9, 0.1, 0.1]))).astype(np.uint8)


class SlamRecorder:
    """Logs a SLAM run into a Rerun recording stream ``stream``: :meth:`step` per frame (the callback
    :func:`dcslam.slam.drive.run_drive` takes), :meth:`finish` with the finished run."""

    def __init__(self, stream, rr) -> None:
        self.stream, self.rr = stream, rr
        self._map_before = None     # (cKDTree of the decimated local map before the frame, effective voxel size)
        self._pinhole_logged = False

    def step(self, slam, report, frame, source_frame=None) -> None:
        """Log frame ``report.index``: ``frame`` (a :class:`dcslam.slam.frame.Frame` after ``slam.step_frame``),
        ``source_frame`` the frame whose points were aligned (None: ``frame``), ``report`` its StepReport."""
        rr, rec, i = self.rr, self.stream, report.index
        rec.set_time("frame", sequence=i)
        T = report.T_world_cam.detach().cpu().double().numpy()
        rec.log("world/camera", rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]))
        self._log_images(frame)
        vertex = frame.vertex.detach().cpu().numpy()
        valid = frame.valid.detach().cpu().numpy()
        world = vertex[valid] @ T[:3, :3].T.astype(np.float32) + T[:3, 3].astype(np.float32)
        colors = None if frame.rgb is None else (frame.rgb.detach().cpu().numpy()[valid] * 255).astype(np.uint8)
        rec.log("world/frame/points", rr.Points3D(every_kth(world, FRAME_POINTS),
                                                  colors=None if colors is None else every_kth(colors, FRAME_POINTS)))
        self._log_sources(source_frame if source_frame is not None else frame, T)
        self._log_step(report)
        self._remember_map(slam)
        if i % MAP_EVERY == 0:
            self.log_map(slam.mapper.global_map())

    def _log_images(self, frame) -> None:
        rr, rec = self.rr, self.stream
        H, W = frame.shape
        if not self._pinhole_logged:  # the camera does not change within a drive
            rec.log("world/camera/image", rr.Pinhole(image_from_camera=frame.K.detach().cpu().double().numpy(),
                                                     width=W, height=H, camera_xyz=rr.ViewCoordinates.RDF),
                    static=True)
            self._pinhole_logged = True
        if frame.rgb is not None:
            rgb = (frame.rgb.detach().cpu().numpy().reshape(H, W, 3) * 255).clip(0, 255).astype(np.uint8)
            rec.log("world/camera/image/rgb", rr.Image(rgb).compress(jpeg_quality=85))
        rec.log("world/camera/image/depth", rr.EncodedDepthImage(
            depth_png(frame.depth.detach().cpu().numpy().reshape(H, W)), media_type="image/png", meter=DEPTH_UNITS))

    def _log_sources(self, aligned, T: np.ndarray) -> None:
        """The aligned frame's points in the world, coloured by weight, or by distance to the map before the frame."""
        valid = aligned.valid.detach().cpu().numpy()
        points = aligned.vertex.detach().cpu().numpy()[valid] @ T[:3, :3].T + T[:3, 3]
        if aligned.weight is not None:
            shade = 1.0 - aligned.weight.detach().cpu().numpy().reshape(valid.shape)[valid]  # low weight: red
        elif self._map_before is not None:
            tree, voxel = self._map_before
            shade = tree.query(points, k=1)[0] / (RESIDUAL_RED * voxel)
        else:
            shade = np.zeros(len(points))  # the first frame: no map to be far from
        keep = every_kth(np.arange(len(points)), FRAME_POINTS)
        self.stream.log("world/frame/sources", self.rr.Points3D(points[keep].astype(np.float32),
                                                                colors=ramp(shade[keep])))

    def _log_step(self, report) -> None:
        rr, rec = self.rr, self.stream
        reasons = [r for r in (*report.health, report.reason if not report.accepted else "") if r]
        text = f"frame {report.index}: {report.verdict}" + (f" ({'; '.join(reasons)})" if reasons else "")
        rec.log("steps/verdict", rr.TextLog(text, level=TEXT_LEVELS.get(report.verdict, "INFO")))
        rec.log("steps/verdict_level", rr.Scalars([float(VERDICT_LEVELS.get(report.verdict, 2))]))
        if report.index == 0:  # the first frame is placed, not aligned: it has no pairs to plot
            return
        for name, value in (("pairs", report.inliers), ("sources", report.sources),
                            ("conditioning", report.conditioning), ("gap_m", report.gap_m)):
            if np.isfinite(value):
                rec.log(f"steps/{name}", rr.Scalars([float(value)]))

    def _remember_map(self, slam) -> None:
        """The local map after this frame, decimated, as the next frame's reference for its source colours."""
        from scipy.spatial import cKDTree

        local = slam.mapper.map
        voxel = float(slam.effective_settings().get("voxel_size") or 0.1)
        if local is None or len(local) == 0:
            self._map_before = None
            return
        self._map_before = (cKDTree(every_kth(local.points.detach().cpu().numpy(), MAP_POINTS)), voxel)

    def log_map(self, pointmap) -> None:
        """The map (a :class:`dcslam.slam.pointmap.PointMap` or None), at most :data:`MAP_POINTS` of its points."""
        if pointmap is None or len(pointmap) == 0:
            return
        points = every_kth(pointmap.points.detach().cpu().numpy().astype(np.float32), MAP_POINTS)
        colors = every_kth((pointmap.colors.detach().cpu().clamp(0, 1).numpy() * 255).astype(np.uint8), MAP_POINTS)
        self.stream.log("world/map", self.rr.Points3D(points, colors=colors))

    def finish(self, run, companion=None) -> None:
        """Log the final map at the last frame and the trajectories of ``run`` (a :class:`DriveRun`: estimated,
        ground truth) and ``companion`` (a DriveRun or None) as static line strips."""
        rr, rec = self.rr, self.stream
        last = len(run.T_world_cam) - 1
        if last % MAP_EVERY != 0:
            rec.set_time("frame", sequence=last)
            self.log_map(run.map)
        strips = {"estimated": (run.T_world_cam, [40, 120, 255]), "ground_truth": (run.T_gt, [160, 160, 160])}
        if companion is not None:
            strips["companion"] = (companion.T_world_cam, [255, 150, 0])
            corrected = companion.road_corrected()    # what the evidence verdict judged the run against
            if corrected is not None:
                strips["companion_road_corrected"] = (corrected, [255, 210, 0])
        for name, (T, color) in strips.items():
            rec.log(f"world/trajectory/{name}", rr.LineStrips3D([positions(T)], colors=[color]), static=True)


@contextlib.contextmanager
def drive_recording(path: Path, force: bool = False) -> Iterator[SlamRecorder]:
    """A :class:`SlamRecorder` writing to ``path`` (a .rrd file), published under its name only when the block
    completes (written under a temporary name in the same folder, then renamed); nothing is overwritten without
    ``force``."""
    from dcslam.io.atomic import atomic_output

    rr = require_rerun()
    with atomic_output(path, force) as tmp:
        stream = rr.RecordingStream("dcslam", recording_id=Path(path).stem)
        stream.save(str(tmp))
        try:
            yield SlamRecorder(stream, rr)
        finally:
            stream.flush()
            stream.disconnect()
