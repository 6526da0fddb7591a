"""The SLAM frame loop (:class:`SLAM`, one frame at a time or a whole sequence) and :func:`build_map` (mapping
with given poses)."""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import torch

from dcslam.constants import FIRST_STEP_PRIORS
from dcslam.errors import DcslamError
from dcslam.geometry.camera import check_depth
from dcslam.geometry.motion import relative_motion
from dcslam.slam.fusion import PointFusion
from dcslam.slam.frame import Frame, FrameSettings, prepare_frame, valid_points
from dcslam.slam.health import HealthRules, assess, summarise
from dcslam.slam.odometry import OdometryResult
from dcslam.slam.parts import Mapper, Odometry
from dcslam.slam.pointmap import PointMap
from dcslam.slam.road import RoadPlane, frame_road


def build_map(depth: torch.Tensor, K: torch.Tensor, T_world_cam: torch.Tensor, rgb: torch.Tensor | None = None,
              mapper: Mapper | None = None, frame_settings: FrameSettings = FrameSettings(),
              weight: torch.Tensor | None = None) -> PointMap:
    """Fuse depth frames seen from given poses (e.g. ground-truth odometry) into one point map.

    Differentiable: gradients of the map's points (and normals, radii) flow back to ``depth``, those of its colours
    to ``rgb``. The mapper (default: a new ``PointFusion(keep_graph=True)``) is reset first.

    Shape: depth (N, 1, H, W) metres (0 = none), K (3, 3), T_world_cam (N, 4, 4), rgb (N, 3, H, W) in [0, 1] or
    None, weight (N, 1, H, W) in [0, 1] or None (per-pixel trust, see :class:`~dcslam.slam.frame.Frame`)
    -> :class:`PointMap`.
    """
    N, H, W = check_depth(depth)
    if not isinstance(T_world_cam, torch.Tensor) or T_world_cam.shape != (N, 4, 4):
        raise DcslamError(f"T_world_cam has shape {tuple(getattr(T_world_cam, 'shape', ()))}, expected ({N}, 4, 4)")
    if rgb is not None and rgb.shape != (N, 3, H, W):
        raise DcslamError(f"rgb has shape {tuple(rgb.shape)}, expected ({N}, 3, {H}, {W})")
    if weight is not None and weight.shape != (N, 1, H, W):
        raise DcslamError(f"weight has shape {tuple(weight.shape)}, expected ({N}, 1, {H}, {W})")
    if mapper is None:
        mapper = PointFusion(keep_graph=True)
    mapper.reset()
    pm = PointMap.empty(depth.dtype, depth.device)
    for i in range(N):
        frame = prepare_frame(depth[i:i + 1], K, None if rgb is None else rgb[i:i + 1], frame_settings,
                              None if weight is None else weight[i:i + 1])
        pm = mapper.integrate(frame, T_world_cam[i].to(depth.dtype))
    return pm


@dataclass
class StepReport:
    """What one SLAM step did and how far to trust it (:mod:`dcslam.slam.health`). Shape: T_world_cam (4, 4).

    verdict: accepted, degraded or rejected; health: the reasons. sources: valid points of the frame; inliers: of
    them, paired within the gates; conditioning: see ``ICPOdometry._conditioning``; gap_m / gap_deg: distance of
    the estimate from the constant-velocity prediction; sigma_m / sigma_deg: the step's first-order standard
    deviation of position / rotation along its worst direction (``PointToPlane.covariance``; NaN when not measured);
    information / covariance: the step's (6, 6) ``OdometryResult.information`` and ``covariance`` (None when not
    measured); road: the frame's road plane (:func:`dcslam.slam.road.frame_road`; None when it saw no road or the
    rules do not ask for it); held: ``OdometryResult.held``, the directions the step held at the prediction (None:
    none).
    """

    index: int
    T_world_cam: torch.Tensor
    accepted: bool
    reason: str
    iterations: int
    inliers: int
    rmse: float
    points: int
    seconds: float
    verdict: str = "accepted"
    health: tuple[str, ...] = ()
    sources: int = 0
    conditioning: float = math.nan
    gap_m: float = 0.0
    gap_deg: float = 0.0
    sigma_m: float = math.nan
    sigma_deg: float = math.nan
    information: torch.Tensor | None = None
    covariance: torch.Tensor | None = None
    road: RoadPlane | None = None
    held: torch.Tensor | None = None


class SLAM:
    """Dense SLAM, one frame at a time: odometry against the mapper's model, then mapping at the estimated pose.

    >>> slam = SLAM(ICPOdometry(), PointFusion())
    >>> for i in range(n):
    ...     report = slam.step(depth[i:i + 1], K, rgb[i:i + 1])
    >>> slam.poses, slam.map

    The first frame is placed at ``T_world_cam0`` (identity by default), or at its ground-truth pose when the
    odometry says so (:attr:`dcslam.slam.parts.Odometry.first_pose_from_gt`). Each later frame starts from a
    constant-velocity prediction; a rejected odometry step keeps that prediction and is listed in
    :attr:`rejected`. With ``keep_graph`` (set on the mapper) poses and map stay connected to the inputs.

    The first ICP step (frame 1) has no velocity: it starts from frame 0's pose unless ``first_step_prior`` is
    ``drive-motion``, which predicts it by the motion from frame 0 to frame 1 of the ground-truth poses given to
    :meth:`step` (data beyond the depth).

    Metric settings (voxel sizes, the ICP gate) are for scenes of median depth ``reference_depth_m`` (a street): the
    first frame of a sequence fixes the scene scale ``min(1, median depth / reference_depth_m)`` (1 when
    ``reference_depth_m`` is 0), which every call to the parts then carries, so that a room scales them down in
    proportion and one set of defaults serves both. :meth:`effective_settings` says what they came to.
    """

    def __init__(self, odometry: Odometry, mapper: Mapper, frame_settings: FrameSettings = FrameSettings(),
                 T_world_cam0: torch.Tensor | None = None, health: HealthRules = HealthRules(),
                 reference_depth_m: float = 0.0, first_step_prior: str = "none"):
        if first_step_prior not in FIRST_STEP_PRIORS:
            raise DcslamError(f"unknown first-step prior {first_step_prior!r} (choose from "
                              f"{', '.join(FIRST_STEP_PRIORS)})")
        self.odometry, self.mapper, self.frame_settings = odometry, mapper, frame_settings
        self.T_world_cam0, self.health = T_world_cam0, health
        self.reference_depth_m, self.first_step_prior = reference_depth_m, first_step_prior
        self.reset()

    def reset(self) -> None:
        #: the scene scale of this sequence; None until its first frame fixes it
        self.scale: float | None = None if self.reference_depth_m > 0 else 1.0
        self.first_frame_median_depth_m: float | None = None
        self.mapper.reset()
        self.odometry.reset()
        self.poses: list[torch.Tensor] = []
        self.reports: list[StepReport] = []
        self._T_gt0: torch.Tensor | None = None  # frame 0's ground-truth pose, for the first-step prior

    def _fix_scale(self, frame: Frame) -> float:
        """The scene scale, fixed by the sequence's first frame (1 for a frame without valid depth)."""
        if self.scale is None:
            scale = 1.0
            if bool(frame.valid.any()):
                median = float(valid_points(frame)[1][:, 2].median())
                self.first_frame_median_depth_m = median
                scale = min(1.0, median / self.reference_depth_m)
            self.scale = scale
        return self.scale

    def effective_settings(self) -> dict:
        """The settings in metres as this sequence uses them: ``scene_scale`` (None before the first frame), the
        ``reference_depth`` and ``first_frame_median_depth`` it comes from, and the parts' own
        (:meth:`dcslam.slam.parts.Mapper.effective_settings`, ``Odometry.effective_settings``), e.g. ``voxel_size``,
        ``source_voxel``, ``max_distance``, ``gates``."""
        scale = 1.0 if self.scale is None else self.scale
        return {"scene_scale": self.scale, "reference_depth": self.reference_depth_m,
                "first_frame_median_depth": self.first_frame_median_depth_m,
                **self.mapper.effective_settings(scale), **self.odometry.effective_settings(scale)}

    @property
    def map(self) -> PointMap | None:
        return self.mapper.map

    @property
    def rejected(self) -> list[dict]:
        return [{"frame": r.index, "reason": r.reason} for r in self.reports if not r.accepted]

    def health_summary(self) -> dict:
        """Verdict counts and the suspect flag of the run so far (:func:`dcslam.slam.health.summarise`)."""
        return summarise(self.reports, self.health)

    def trajectory(self) -> torch.Tensor:
        """Estimated poses so far. Shape: (N, 4, 4)."""
        return torch.stack(self.poses)

    def _prediction(self, dtype, device, T_gt: torch.Tensor | None = None) -> torch.Tensor:
        if not self.poses:
            T0 = self.T_world_cam0 if self.T_world_cam0 is not None else torch.eye(4)
            return T0.to(dtype=dtype, device=device)
        last = self.poses[-1].detach()
        if len(self.poses) == 1:
            return last if self.first_step_prior == "none" else last @ self._first_motion(T_gt, dtype, device)
        prev = self.poses[-2].detach()
        return last @ torch.linalg.solve(prev, last)

    def _first_motion(self, T_gt: torch.Tensor | None, dtype, device) -> torch.Tensor:
        """Frame 0 → frame 1 motion of the ground-truth poses. Shape: T_gt (4, 4) -> (4, 4)."""
        if T_gt is None or self._T_gt0 is None:
            raise DcslamError(f"first_step_prior {self.first_step_prior!r} needs the ground-truth poses of frames 0 "
                              "and 1 (T_gt)")
        return torch.linalg.solve(self._T_gt0.to(dtype=dtype, device=device),
                                  T_gt.detach().to(dtype=dtype, device=device))

    def step(self, depth: torch.Tensor, K: torch.Tensor, rgb: torch.Tensor | None = None,
             T_gt: torch.Tensor | None = None, weight: torch.Tensor | None = None) -> StepReport:
        """Process one frame. Shape: depth (1, 1, H, W) metres, K (3, 3), rgb (1, 3, H, W) or None, T_gt (4, 4),
        weight (1, 1, H, W) in [0, 1] or None (per-pixel trust for ICP and fusion, see
        :class:`~dcslam.slam.frame.Frame`)."""
        start = time.perf_counter()
        return self.step_frame(prepare_frame(depth, K, rgb, self.frame_settings, weight), T_gt, start)

    def precompute(self, frame: Frame, source_frame: Frame | None = None) -> None:
        """Do the odometry's and the mapper's work on ``frame`` (and the odometry's on ``source_frame`` instead,
        when given: see :meth:`step_frame`) that depends on the frame alone (kept in :attr:`Frame.cache`): safe on
        another thread while :meth:`step_frame` processes the previous frame, and the results are the ones
        step_frame would compute. The odometry's part waits until the first frame has fixed the scene scale (until
        then step_frame computes it itself)."""
        self.mapper.precompute(frame)
        self._road(frame)
        scale = self.scale
        if scale is not None:
            self.odometry.precompute(frame if source_frame is None else source_frame, scale)

    def step_frame(self, frame: Frame, T_gt: torch.Tensor | None = None, start: float | None = None,
                   source_frame: Frame | None = None) -> StepReport:
        """Process one frame already made by ``prepare_frame(depth, K, rgb, self.frame_settings, weight)``, which
        depends on the frame alone: a caller may prepare the next frame on another thread while this one is
        aligned and fused (:func:`dcslam.slam.drive.run_drive` does). ``start``: the ``time.perf_counter()`` the
        report's seconds count from (default: now).

        ``source_frame``: another frame of the same camera and instant whose points the odometry aligns instead of
        ``frame``'s (e.g. the measured LiDAR pixels behind a completed ``frame``), so that the pose rests on
        measurements while the map fuses ``frame``; the report's sources and inliers are then its points. ``frame``
        alone fixes the scene scale and is fused. None: ``frame`` serves both."""
        start = time.perf_counter() if start is None else start
        T_init = self._prediction(frame.depth.dtype, frame.depth.device, T_gt)
        index = len(self.poses)
        if index == 0 and T_gt is not None:
            self._T_gt0 = T_gt.detach()
        scale = self._fix_scale(frame)
        if source_frame is not None and source_frame.shape != frame.shape:
            raise DcslamError(f"source frame of {source_frame.shape}, the frame of {frame.shape}: not the same camera")
        if index == 0:
            first_from_gt = T_gt is not None and self.odometry.first_pose_from_gt
            result = OdometryResult(T_gt.to(T_init.dtype) if first_from_gt else T_init)
        else:
            H, W = frame.shape
            model = self.mapper.model(T_init, frame.K, H, W)
            aligned = frame if source_frame is None else source_frame
            result = self.odometry.estimate(aligned, model, T_init, T_gt, T_last=self.poses[-1].detach(), scale=scale)
        self.mapper.integrate(frame, result.T_world_cam, scale)
        self.poses.append(result.T_world_cam)
        gap_m, gap_deg = _distance(T_init, result.T_world_cam)
        verdict, why = ("accepted", []) if index == 0 or not self.odometry.assess_steps else assess(
            result.accepted, result.reason, result.inliers, result.sources, result.conditioning, gap_m, gap_deg,
            has_velocity=index >= 2, rules=self.health, held=result.held)
        report = StepReport(index, result.T_world_cam, result.accepted, result.reason, result.iterations,
                            result.inliers, result.rmse, len(self.mapper.map), time.perf_counter() - start,
                            verdict, tuple(why), result.sources, result.conditioning, gap_m, gap_deg,
                            result.sigma_m, result.sigma_deg, result.information, result.covariance,
                            self._road(frame), result.held)
        self.reports.append(report)
        return report

    def _road(self, frame: Frame) -> RoadPlane | None:
        """The frame's road plane, fitted once to its valid pixels' points (kept in :attr:`Frame.cache`); None when
        the health rules do not ask for it (``max_road_drift_m`` 0) or the frame saw no road."""
        if self.health.max_road_drift_m <= 0:
            return None
        if "road" not in frame.cache:
            frame.cache["road"] = frame_road(valid_points(frame)[1])  # the valid pixels' points: no full image
        return frame.cache["road"]

    def run(self, depth: torch.Tensor, K: torch.Tensor, rgb: torch.Tensor | None = None,
            T_gt: torch.Tensor | None = None, weight: torch.Tensor | None = None) -> torch.Tensor:
        """Process a whole sequence. Shape: depth (N, 1, H, W), rgb (N, 3, H, W), T_gt (N, 4, 4), weight
        (N, 1, H, W) or None -> poses (N, 4, 4)."""
        N, H, W = check_depth(depth)
        if weight is not None and weight.shape != (N, 1, H, W):
            raise DcslamError(f"weight has shape {tuple(weight.shape)}, expected ({N}, 1, {H}, {W})")
        for i in range(N):
            self.step(depth[i:i + 1], K, None if rgb is None else rgb[i:i + 1], None if T_gt is None else T_gt[i],
                      None if weight is None else weight[i:i + 1])
        return self.trajectory()


def _distance(T_a: torch.Tensor, T_b: torch.Tensor) -> tuple[float, float]:
    """Translation (m) and rotation (deg) of T_a^-1 T_b. Shape: (4, 4), (4, 4)."""
    metres, radians = relative_motion(T_a.detach(), T_b.detach())
    return float(metres), math.degrees(float(radians))
