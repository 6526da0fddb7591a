"""Odometry: the pose of a new frame, from ground truth or by point-to-plane ICP against a model.

Odometry objects share one method, ``estimate(frame, model, T_init, T_gt=None) -> OdometryResult``. ICP is
composed from parts: a solver (:class:`~dcslam.slam.solvers.GaussNewton`, ``LevenbergMarquardt``,
``DifferentiableLM``) and an association (:class:`~dcslam.slam.association.ProjectiveAssociation`,
``NearestNeighbourAssociation``), with distance and normal-angle gates. A degenerate step (no model, too few
inliers, an ill-conditioned system as for a single plane, a non-finite result) is *rejected*: the result keeps
``T_init`` and says why, and a pose is never NaN.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from dcslam.errors import DcslamError
from dcslam.geometry.se3 import rotate, transform_points
from dcslam.slam.association import ProjectiveAssociation
from dcslam.slam.frame import Frame
from dcslam.slam.pointmap import ModelView
from dcslam.slam.solvers import GaussNewton, Linearization


@dataclass
class OdometryResult:
    """Shape: T_world_cam (4, 4). ``accepted`` false means the estimate was rejected (``reason`` says why) and
    ``T_world_cam`` is the initial guess."""

    T_world_cam: torch.Tensor
    accepted: bool = True
    reason: str = ""
    iterations: int = 0
    inliers: int = 0
    rmse: float = 0.0


class GroundTruthOdometry:
    """Poses read from the drive: returns ``T_gt``."""

    def estimate(self, frame: Frame, model: ModelView | None, T_init: torch.Tensor,
                 T_gt: torch.Tensor | None = None) -> OdometryResult:
        if T_gt is None:
            raise DcslamError("ground-truth odometry needs the ground-truth pose of every frame")
        return OdometryResult(T_gt.to(frame.vertex.dtype))


class PointToPlane:
    """Point-to-plane residuals ``r_i = n_i . (T s_i - q_i)`` of source points ``s_i`` (camera frame) against
    associated target points ``q_i`` and normals ``n_i`` (world frame), within the gates.

    Shape: source (F, 3), source_normals (F, 3) camera frame.
    """

    def __init__(self, source: torch.Tensor, source_normals: torch.Tensor, associate, max_distance: float,
                 cos_max_angle: float):
        self.source, self.source_normals = source, source_normals
        self.associate, self.max_distance, self.cos_max_angle = associate, max_distance, cos_max_angle

    def residuals(self, T: torch.Tensor):
        """(residuals (M,), inlier source index (M,), target normals (M, 3)) at pose T (4, 4)."""
        p = transform_points(T, self.source)
        src, q, n = self.associate(p)
        p_src = p[src]
        diff = p_src - q
        ok = ((diff.detach() ** 2).sum(1) < self.max_distance ** 2) & \
             ((rotate(T.detach(), self.source_normals[src].detach()) * n.detach()).sum(1) > self.cos_max_angle)
        return (diff[ok] * n[ok]).sum(1), src[ok], n[ok]

    def _truncated(self, r: torch.Tensor) -> torch.Tensor:
        """Mean over all source points of r^2 for inliers and max_distance^2 for the rest: one objective whatever
        the inlier set, so that solvers may compare costs at different poses."""
        outliers = self.source.shape[0] - r.numel()
        return ((r * r).sum() + outliers * self.max_distance ** 2) / max(self.source.shape[0], 1)

    def cost(self, T: torch.Tensor) -> tuple[torch.Tensor, int]:
        r, _, _ = self.residuals(T)
        return self._truncated(r), r.numel()

    def linearize(self, T: torch.Tensor) -> Linearization:
        r, src, n = self.residuals(T)
        m = n @ T[:3, :3]                           # R^T n: the normal in the camera frame
        J = torch.cat([m, torch.cross(self.source[src], m, dim=1)], 1).double()
        rd = r.double()
        return Linearization(J.T @ J, J.T @ rd, self._truncated(rd), r.numel())


class ICPOdometry:
    """Frame-to-model point-to-plane ICP.

    Args:
        solver: ``GaussNewton()`` (default), ``LevenbergMarquardt()`` or ``DifferentiableLM()``.
        association: ``ProjectiveAssociation()`` (default) or ``NearestNeighbourAssociation()``.
        max_distance: metres; pairs further apart are outliers (the 0.5 m gate that halved gradSLAM's error).
        max_normal_angle_deg: pairs whose normals differ more are outliers.
        iterations: solver iterations.
        min_inliers: fewer inlier pairs reject the step.
        min_conditioning: smallest eigenvalue of the normalised 6 x 6 system (rotation scaled by the mean source
            range, divided by the inlier count) below which the pose is unobservable (a plane) and the step is
            rejected.
        max_step_m, max_step_deg: an estimate further than this from ``T_init`` is rejected as a divergence.
        coarse_to_fine: gate multipliers, one solver run per entry (each up to ``iterations``): a wide gate first
            catches motions larger than ``max_distance`` (a car moves about 1 m between KITTI frames), the last
            entry should be 1. ``(1.0,)`` is plain ICP with one gate, as Open3D's ``registration_icp``.
    """

    def __init__(self, solver=None, association=None, max_distance: float = 0.5, max_normal_angle_deg: float = 30.0,
                 iterations: int = 20, min_inliers: int = 100, min_conditioning: float = 1e-5,
                 max_step_m: float = 5.0, max_step_deg: float = 30.0,
                 coarse_to_fine: tuple[float, ...] = (4.0, 2.0, 1.0)):
        if not coarse_to_fine or any(m <= 0 for m in coarse_to_fine):
            raise DcslamError(f"coarse_to_fine must be positive gate multipliers, got {coarse_to_fine}")
        self.coarse_to_fine = tuple(coarse_to_fine)
        self.solver = solver if solver is not None else GaussNewton()
        self.association = association if association is not None else ProjectiveAssociation()
        self.max_distance, self.iterations = max_distance, iterations
        self.cos_max_angle = math.cos(math.radians(max_normal_angle_deg))
        self.min_inliers, self.min_conditioning = min_inliers, min_conditioning
        self.max_step_m, self.max_step_rad = max_step_m, math.radians(max_step_deg)

    def estimate(self, frame: Frame, model: ModelView | None, T_init: torch.Tensor,
                 T_gt: torch.Tensor | None = None) -> OdometryResult:
        T_init = T_init.to(frame.vertex.dtype)
        if model is None:
            return OdometryResult(T_init, False, "empty model")
        flat = frame.valid.reshape(-1)
        source = frame.vertex.reshape(-1, 3)[flat]
        if source.shape[0] < self.min_inliers:
            return OdometryResult(T_init, False, f"{source.shape[0]} valid source points")
        normals, associate = frame.normal.reshape(-1, 3)[flat], self.association.prepare(model)
        T, iterations = T_init, 0
        for multiplier in self.coarse_to_fine:
            problem = PointToPlane(source, normals, associate, self.max_distance * multiplier, self.cos_max_angle)
            result = self.solver.solve(problem, T, self.iterations)
            T, iterations = result.T, iterations + result.iterations
        lin = problem.linearize(T.detach())
        r, _, _ = problem.residuals(T.detach())
        rmse = math.sqrt(float((r.double() ** 2).mean())) if r.numel() else math.inf
        base = dict(iterations=iterations, inliers=lin.count, rmse=rmse)
        if not bool(torch.isfinite(T).all()):
            return OdometryResult(T_init, False, "non-finite pose", **base)
        if lin.count < self.min_inliers:
            return OdometryResult(T_init, False, f"{lin.count} inliers", **base)
        conditioning = self._conditioning(lin, source)
        if conditioning < self.min_conditioning:
            return OdometryResult(T_init, False, f"degenerate geometry (conditioning {conditioning:.1e})", **base)
        X = torch.linalg.solve(T_init.detach().double(), T.detach().double())
        angle = math.acos(max(-1.0, min(1.0, (float(torch.trace(X[:3, :3])) - 1) / 2)))
        if float(X[:3, 3].norm()) > self.max_step_m or angle > self.max_step_rad:
            return OdometryResult(T_init, False, "diverged", **base)
        return OdometryResult(T, True, "", **base)

    @staticmethod
    def _conditioning(lin: Linearization, source: torch.Tensor) -> float:
        scale = float(source.detach().norm(dim=1).mean())
        D = torch.tensor([1, 1, 1, scale, scale, scale], dtype=torch.float64, device=lin.H.device)
        Hn = lin.H.detach() / (D[:, None] * D[None, :]) / max(lin.count, 1)
        return float(torch.linalg.eigvalsh(Hn)[0])
