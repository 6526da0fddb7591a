"""The pose loss: the network's depth goes through dcslam's differentiable frame-to-model ICP, and the estimated
relative poses are compared with the ground truth.

Over a window of consecutive frames, the first frame is placed at its ground-truth pose and fused (PointFusion,
graph kept); every later frame is aligned to the map rendered at its constant-velocity prediction (from the
estimates so far, detached; zero motion for the second frame, as :class:`dcslam.slam.pipeline.SLAM` starts) by
point-to-plane ICP with the differentiable Levenberg-Marquardt, then fused at the estimate. The loss is the mean
over consecutive pairs of ``translation_weight * |t_E| + rotation_weight * angle(R_E)``, where
``E = (T_gt_{i-1}^-1 T_gt_i)^-1 (T_est_{i-1}^-1 T_est_i)`` (the thesis's localisation error of the step, metres +
radians). The gradient reaches the depth through the source points, their normals and the map points, and the
per-pixel weights (a network's confidence), when given, through ICP's residual weights and fusion's merges.

Cost on a CPU: :class:`TruncatedSolver` keeps the graph of the last ``k`` LM iterations only, and ``max_sources``
aligns a random subset of the valid pixels (besides the odometry's own ``source_voxel`` thinning).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import torch

from dcslam.errors import DcslamError
from dcslam.slam.solvers import SolveResult


class TruncatedSolver:
    """Truncated back-propagation through an iterative solver: the first ``iterations - grad_iterations``
    iterations run without gradient, the last ``grad_iterations`` from their (detached) result with it, so the
    graph and its memory grow with ``grad_iterations`` only. ``grad_iterations`` = 0 keeps every iteration.

    The gradient is then that of the last iterations' map from their starting pose (which the truncated part
    treats as a constant): near convergence, where each iteration contracts towards the optimum, it approaches the
    full gradient.
    """

    def __init__(self, solver, grad_iterations: int = 0):
        if grad_iterations < 0:
            raise DcslamError(f"grad_iterations must be >= 0, got {grad_iterations}")
        self.solver, self.grad_iterations = solver, grad_iterations

    def solve(self, problem, T: torch.Tensor, iterations: int) -> SolveResult:
        k = self.grad_iterations
        if k == 0 or k >= iterations or not torch.is_grad_enabled():
            return self.solver.solve(problem, T, iterations)
        with torch.no_grad():
            first = self.solver.solve(problem, T.detach(), iterations - k)
        last = self.solver.solve(problem, first.T.detach(), k)
        return SolveResult(last.T, first.iterations + last.iterations, last.last)


def _norm(x: torch.Tensor, eps: float) -> torch.Tensor:
    """|x| along the last axis, with a finite gradient at 0 (sqrt(|x|² + eps²) - eps)."""
    return torch.sqrt((x * x).sum(-1) + eps * eps) - eps


def relative_pose_error(T_est: torch.Tensor, T_gt: torch.Tensor, eps: float = 1e-9
                        ) -> tuple[torch.Tensor, torch.Tensor]:
    """Translation (metres) and geodesic rotation (radians) errors of each consecutive step of a trajectory:
    ``E_i = (T_gt_{i-1}^-1 T_gt_i)^-1 (T_est_{i-1}^-1 T_est_i)``, |t_E| and angle(R_E) = atan2(sin, cos) (smooth
    where acos is not: near 0).

    Shape: T_est, T_gt (N, 4, 4), N >= 2 -> (N - 1,), (N - 1,).
    """
    if T_est.ndim != 3 or T_est.shape[1:] != (4, 4) or T_est.shape != T_gt.shape or T_est.shape[0] < 2:
        raise DcslamError(f"trajectories have shapes {tuple(T_est.shape)} and {tuple(T_gt.shape)}, expected "
                          "(N, 4, 4) each with N >= 2")
    T_gt = T_gt.to(T_est.dtype)
    step_est = torch.linalg.solve(T_est[:-1], T_est[1:])
    step_gt = torch.linalg.solve(T_gt[:-1], T_gt[1:])
    E = torch.linalg.solve(step_gt, step_est)
    R = E[:, :3, :3]
    vee = torch.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], -1)
    cos = (R[:, 0, 0] + R[:, 1, 1] + R[:, 2, 2] - 1) / 2
    angle = torch.atan2(_norm(vee, eps) / 2, cos)
    return _norm(E[:, :3, 3], eps), angle


@dataclass(frozen=True)
class PoseLossSettings:
    """How the pose loss weighs its terms and thins its sources.

    translation_weight, rotation_weight: weights of |t_E| (metres) and angle(R_E) (radians); 1 and 1 is the
        thesis's localisation error.
    max_sources: align at most this many valid pixels of each frame, drawn at random (0: all of them).
    """

    translation_weight: float = 1.0
    rotation_weight: float = 1.0
    max_sources: int = 0

    def __post_init__(self) -> None:
        for name in ("translation_weight", "rotation_weight"):
            if not 0 <= getattr(self, name) < float("inf"):
                raise DcslamError(f"--pose-{name.replace('_weight', '')}-weight must be >= 0, "
                                  f"got {getattr(self, name)}")
        if self.max_sources < 0:
            raise DcslamError(f"--pose-max-sources must be >= 0, got {self.max_sources}")


def default_odometry(iterations: int = 10, grad_iterations: int = 0, source_voxel: float = 0.2):
    """The odometry of the pose loss: dcslam's ICP defaults (SLAM stage) with the differentiable LM, truncated to
    ``grad_iterations`` iterations with gradient (0: all), and without the SLAM's rejection of steps that diverge
    or are ill-conditioned (a rejected step keeps the prediction, whose error does not depend on the depth: with
    it, a network learnt to make ICP fail, 0.65 -> 0.50 m per step on a test drive, and its depth error grew from
    1.7 to 10 m). Only steps with fewer than 6 pairs or a non-finite result are still rejected."""
    from dcslam.slam.config import SlamSettings
    from dcslam.slam.odometry import ICPOdometry
    from dcslam.slam.solvers import DifferentiableLM

    s = SlamSettings()
    solver = TruncatedSolver(DifferentiableLM(tolerance=s.tolerance), grad_iterations)
    return ICPOdometry(solver=solver, max_distance=s.max_distance, max_normal_angle_deg=s.max_normal_angle,
                       iterations=iterations, source_voxel=source_voxel, hold_below=s.hold_below,
                       coarse_to_fine=tuple(float(x) for x in s.gate_schedule.split(",")),
                       min_inliers=6, min_conditioning=0.0, max_step_m=math.inf, max_step_deg=180.0)


def default_mapper():
    """PointFusion with the SLAM stage's voxel size, graph kept (the map points carry the depth's gradient)."""
    from dcslam.slam.config import SlamSettings
    from dcslam.slam.fusion import PointFusion

    return PointFusion(voxel_size=SlamSettings().voxel_size, keep_graph=True)


class PoseLoss:
    """``PoseLoss(odometry, mapper)(depth, K, T_world_cam, weight=None)`` -> (loss, details).

    Args:
        odometry: an :class:`dcslam.slam.parts.Odometry` (ICP whose solver is differentiable:
            :func:`default_odometry`); reset for every window.
        mapper: a :class:`dcslam.slam.parts.Mapper` with ``keep_graph`` (:func:`default_mapper`); reset for every
            window.
        settings: :class:`PoseLossSettings`.
        frame_settings: how depth becomes surfels (:class:`dcslam.slam.frame.FrameSettings`).

    Shape: depth (N, 1, H, W) metres, N >= 2; K (3, 3); T_world_cam (N, 4, 4) ground truth; weight (N, 1, H, W)
    per-pixel ICP weights in [0, 1] (a network's confidence) or None -> scalar loss, and a dict with the estimated
    poses ``T_est`` (N, 4, 4, detached), the per-step ``translation_m`` and ``rotation_rad`` (N - 1,) and the number
    of ``rejected`` steps.
    """

    def __init__(self, odometry=None, mapper=None, settings: PoseLossSettings = PoseLossSettings(),
                 frame_settings=None):
        from dcslam.slam.frame import FrameSettings

        self.odometry = odometry if odometry is not None else default_odometry()
        self.mapper = mapper if mapper is not None else default_mapper()
        self.settings = settings
        self.frame_settings = frame_settings if frame_settings is not None else FrameSettings()

    def _frame(self, depth: torch.Tensor, K: torch.Tensor, weight: torch.Tensor | None):
        from dcslam.slam.frame import prepare_frame

        return prepare_frame(depth, K, settings=self.frame_settings, weight=weight)

    def _sources(self, frame):
        """The frame with at most ``max_sources`` valid pixels kept (at random), for the alignment only."""
        n = self.settings.max_sources
        flat = frame.valid.reshape(-1)
        count = int(flat.sum())
        if n == 0 or count <= n:
            return frame
        index = torch.nonzero(flat).squeeze(1)
        keep = index[torch.randperm(count, device=index.device)[:n]]
        valid = torch.zeros_like(flat)
        valid[keep] = True
        return replace(frame, valid=valid.view_as(frame.valid))

    def trajectory(self, depth: torch.Tensor, K: torch.Tensor, T_world_cam: torch.Tensor,
                   weight: torch.Tensor | None = None) -> tuple[torch.Tensor, int]:
        """Estimated poses (N, 4, 4), differentiable w.r.t. ``depth`` (and ``weight``), and the rejected steps."""
        from dcslam.geometry.camera import check_depth

        N, H, W = check_depth(depth)
        if N < 2 or not isinstance(T_world_cam, torch.Tensor) or T_world_cam.shape != (N, 4, 4):
            raise DcslamError(f"the pose loss needs a window of >= 2 frames and their poses: depth has {N} frames, "
                              f"poses shape {tuple(getattr(T_world_cam, 'shape', ()))}")
        if weight is not None and weight.shape != depth.shape:
            raise DcslamError(f"weight has shape {tuple(weight.shape)}, expected {tuple(depth.shape)}")
        T_gt = T_world_cam.to(depth.dtype)
        self.mapper.reset()
        self.odometry.reset()
        poses, rejected = [T_gt[0]], 0
        w = (lambda i: None) if weight is None else (lambda i: weight[i:i + 1])
        self.mapper.integrate(self._frame(depth[0:1], K, w(0)), T_gt[0])
        for i in range(1, N):
            frame = self._frame(depth[i:i + 1], K, w(i))
            last = poses[-1].detach()
            T_init = last if i == 1 else last @ torch.linalg.solve(poses[-2].detach(), last)
            model = self.mapper.model(T_init, frame.K, H, W)
            result = self.odometry.estimate(self._sources(frame), model, T_init, T_last=last)
            rejected += not result.accepted
            self.mapper.integrate(frame, result.T_world_cam)
            poses.append(result.T_world_cam)
        return torch.stack(poses), rejected

    def __call__(self, depth: torch.Tensor, K: torch.Tensor, T_world_cam: torch.Tensor,
                 weight: torch.Tensor | None = None) -> tuple[torch.Tensor, dict]:
        T_est, rejected = self.trajectory(depth, K, T_world_cam, weight)
        translation, rotation = relative_pose_error(T_est, T_world_cam)
        s = self.settings
        loss = (s.translation_weight * translation + s.rotation_weight * rotation).mean()
        return loss, {"T_est": T_est.detach(), "translation_m": translation.detach(),
                      "rotation_rad": rotation.detach(), "rejected": rejected}
