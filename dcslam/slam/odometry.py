"""Odometry: the pose of a new frame, from ground truth or by point-to-plane ICP against a model.

Odometry objects follow :class:`dcslam.slam.parts.Odometry`:
``estimate(frame, model, T_init, T_gt=None, T_last=None, scale=1.0) -> OdometryResult`` and its hooks. ICP is
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
from dcslam.geometry.motion import relative_motion
from dcslam.geometry.se3 import FAST_ROWS, rotate, rows_times, transform_points
from dcslam.native import point_to_plane_pairs
from dcslam.slam.association import ProjectiveAssociation
from dcslam.slam.frame import DENSE_FRACTION, Frame, valid_normals, valid_points
from dcslam.slam.pointmap import ModelView, voxel_representatives
from dcslam.slam.robust import Quadratic
from dcslam.slam.solvers import GaussNewton, Linearization


@dataclass
class OdometryResult:
    """Shape: T_world_cam (4, 4). ``accepted`` false means the estimate was rejected (``reason`` says why) and
    ``T_world_cam`` is the initial guess. ``information`` (6, 6): J^T W J of the final pairs at the estimate, and
    ``covariance`` (6, 6): :meth:`PointToPlane.covariance`, both float64 over the twist (translation, rotation) in the
    camera frame (None when the step never got that far): the degeneracy analysis of :mod:`dcslam.slam.health`.
    ``held`` (K, 6): the directions of motion the step held at the prediction (``hold_below``), each the twist
    (translation m, rotation rad; camera frame) that moves the sources by one metre along it, at the final pairs (None
    when it held none)."""

    T_world_cam: torch.Tensor
    accepted: bool = True
    reason: str = ""
    iterations: int = 0
    inliers: int = 0
    rmse: float = 0.0
    sources: int = 0
    conditioning: float = math.nan
    gate: float = math.nan
    sigma_m: float = math.nan
    sigma_deg: float = math.nan
    information: torch.Tensor | None = None
    covariance: torch.Tensor | None = None
    held: torch.Tensor | None = None


#: Iterations of each wide-gate ICP stage on dense depth (a value at more than :data:`DENSE_FRACTION` of the
#: pixels: completed or exact depth). On such depth Gauss-Newton with a 4x or 2x gate does not converge but cycles
#: with centimetre steps until the cap, which costs time and can walk a run off; a few iterations leave the final
#: error of tracking drives as it was (docs/slam.md, "Wide-gate iterations on dense depth"). Sparse depth converges
#: within the cap of each stage and keeps ``iterations``.
DENSE_COARSE_ITERATIONS = 3


def coarse_iterations_for(fraction: float, iterations: int) -> int:
    """Solver iterations of each wide-gate stage for depth with a value at ``fraction`` of the pixels:
    :data:`DENSE_COARSE_ITERATIONS` for dense depth, ``iterations`` (as the last stage) for sparse depth."""
    return min(DENSE_COARSE_ITERATIONS, iterations) if fraction > DENSE_FRACTION else iterations


class GroundTruthOdometry:
    """Poses read from the drive: returns ``T_gt`` (the first frame's too); given poses are not health-checked."""

    first_pose_from_gt = True
    assess_steps = False

    def estimate(self, frame: Frame, model: ModelView | None, T_init: torch.Tensor,
                 T_gt: torch.Tensor | None = None, T_last: torch.Tensor | None = None,
                 scale: float = 1.0) -> OdometryResult:
        if T_gt is None:
            raise DcslamError("ground-truth odometry needs the ground-truth pose of every frame")
        return OdometryResult(T_gt.to(frame.depth.dtype))

    def reset(self) -> None:
        """Nothing learnt from past steps."""

    def precompute(self, frame: Frame, scale: float = 1.0) -> None:
        """Nothing depends on the frame alone."""

    def effective_settings(self, scale: float) -> dict:
        return {}


class PointToPlane:
    """Point-to-plane residuals ``r_i = n_i . (T s_i - q_i)`` of source points ``s_i`` (camera frame) against
    associated target points ``q_i`` and normals ``n_i`` (world frame), within the gates, weighted by a robust
    kernel (:mod:`dcslam.slam.robust`; default plain least squares).

    :meth:`linearize` associates at the pose it is given and keeps those pairs; :meth:`cost` scores a candidate
    pose on the *same* pairs, as ICP's inner least-squares problem does. (Re-associating at the candidate made
    sparse LiDAR depth self-align: its scan rings land on the same pixels at the initial guess, so any move lost
    partners and the differentiable LM never left the initial pose.)

    ``weights`` (per source point, in [0, 1], e.g. a completer's confidence) multiply the kernel's weights in
    :meth:`linearize` and the kernel's cost in :meth:`cost`, so the pose is a differentiable function of them as of
    the depth; a point of weight 0 is never a pair (it is no evidence for the inlier count).

    Shape: source (F, 3), source_normals (F, 3) camera frame, weights (F,) or None (all 1).
    """

    def __init__(self, source: torch.Tensor, source_normals: torch.Tensor, associate, max_distance: float,
                 cos_max_angle: float, kernel=None, hold_below: float = 0.0, weights: torch.Tensor | None = None):
        if weights is not None and weights.shape != source.shape[:1]:
            raise DcslamError(f"weights have shape {tuple(weights.shape)}, expected ({source.shape[0]},)")
        self.source, self.source_normals, self.weights = source, source_normals, weights
        self.associate, self.max_distance, self.cos_max_angle = associate, max_distance, cos_max_angle
        self.kernel = kernel if kernel is not None else Quadratic()
        self.hold_below = hold_below
        self.scale = float(torch.linalg.vector_norm(source.detach(), dim=1).mean()) if source.shape[0] else 1.0
        self.pairs = None
        self._usable = None if weights is None else weights.detach() > 0   # the weight gate, once per problem
        self._D: tuple[torch.Tensor, torch.Tensor, list] | None = None      # _hold's scaling, once per problem

    def residuals(self, T: torch.Tensor):
        """(residuals (M,), inlier source index (M,), target points (M, 3), target normals (M, 3)) at pose T."""
        return self._pairs(T)[:4]

    def _pairs(self, T: torch.Tensor, jacobian: bool = False):
        """:meth:`residuals` and, where the native pass made it (``jacobian``), :meth:`linearize`'s Jacobian (M, 6)
        float64 of those pairs, else None."""
        if type(self.associate) is ProjectiveAssociation._Prepared:
            # the same pairs and residuals in one pass over the sources (dcslam.native), where it applies
            native = point_to_plane_pairs(self.source, self.source_normals, self._usable, T, self.associate,
                                          self.max_distance, self.cos_max_angle, FAST_ROWS, jacobian)
            if native is not None:
                return native
        p = transform_points(T, self.source)
        src, q, n = self.associate(p)
        diff = p.index_select(0, src) - q
        ok = ((diff.detach() ** 2).sum(1) < self.max_distance ** 2) & \
             ((rotate(T.detach(), self.source_normals.detach().index_select(0, src)) * n.detach()).sum(1)
              > self.cos_max_angle)
        if self._usable is not None:
            ok &= self._usable.index_select(0, src)
        keep = torch.nonzero(ok).squeeze(1)         # one nonzero and index_select: cheaper than four masks
        n = n.index_select(0, keep)
        return (diff.index_select(0, keep) * n).sum(1), src.index_select(0, keep), q.index_select(0, keep), n, None

    def _pair_weights(self, src: torch.Tensor) -> torch.Tensor | None:
        """Weights of the paired source points (float64), or None when every point counts fully."""
        return None if self.weights is None else self.weights.index_select(0, src).double()

    def _fixed_residuals(self, T: torch.Tensor) -> torch.Tensor:
        src, q, n = self.pairs
        return ((transform_points(T, self.source.index_select(0, src)) - q) * n).sum(1)

    def _mean_rho(self, r: torch.Tensor, pair_weights: torch.Tensor | None) -> torch.Tensor:
        rho = self.kernel.rho(r, self.max_distance)
        if pair_weights is not None:
            rho = pair_weights * rho
        return rho.sum() / max(r.numel(), 1)

    def cost(self, T: torch.Tensor) -> tuple[torch.Tensor, int]:
        """Mean (weighted) kernel cost at T of the pairs of the last :meth:`linearize` (which must come first)."""
        if self.pairs is None:
            raise DcslamError("PointToPlane.cost before linearize")
        r = self._fixed_residuals(T)
        return self._mean_rho(r.double(), self._pair_weights(self.pairs[0])), r.numel()

    def linearize(self, T: torch.Tensor) -> Linearization:
        r, src, q, n, J = self._pairs(T, jacobian=True)
        self.pairs = (src, q, n)
        if J is None:                               # (the native pass makes the same rows, bit for bit)
            m = rows_times(n, T[:3, :3])            # R^T n: the normal in the camera frame
            J = torch.cat([m, torch.cross(self.source.index_select(0, src), m, dim=1)], 1).double()
        rd = r.double()
        pw = self._pair_weights(src)
        if pw is None and type(self.kernel) is Quadratic:
            # every weight is exactly 1: J^T W J and J^T W r are J^T J and J^T r, bit for bit
            lin = Linearization(J.T @ J, J.T @ rd, self._mean_rho(rd, pw), r.numel(), float(r.numel()))
        else:
            w = self.kernel.weight(rd, self.max_distance)
            if pw is not None:
                w = w * pw
            lin = Linearization(J.T @ (w[:, None] * J), J.T @ (w * rd), self._mean_rho(rd, pw), r.numel(),
                                float(w.detach().sum()))
        if self.hold_below > 0 and r.numel() >= 6:
            lin.H_step = self._hold(lin)
        return lin

    def covariance(self, T: torch.Tensor, lin: Linearization, residuals: torch.Tensor | None = None) -> torch.Tensor:
        """First-order covariance of the twist (translation, rotation; camera frame) estimated at T from the pairs
        of ``lin`` (the linearization at T): ``s^2 (J^T W J)^-1`` with ``s^2`` the weighted residual variance
        ``sum w r^2 / (sum w - 6)``. It treats residuals as independent, so it is a lower bound on the true
        uncertainty (ICP's errors are correlated); :mod:`dcslam.slam.health` calibrates it. ``residuals``: those
        pairs' residuals at T when the caller has them (computed here otherwise). Shape: (6, 6) float64."""
        src = self.pairs[0]
        r = (self._fixed_residuals(T.detach()) if residuals is None else residuals).detach().double()
        w = self.kernel.weight(r, self.max_distance)
        pw = self._pair_weights(src)
        if pw is not None:
            w = w * pw.detach()
        dof = max(float(w.sum()) - 6.0, 1.0)
        s2 = float((w * r * r).sum()) / dof
        H = lin.H.detach().double()
        jitter = 1e-12 * float(torch.diagonal(H).sum()) + 1e-300
        return s2 * torch.linalg.inv(H + jitter * torch.eye(6, dtype=H.dtype, device=H.device))

    def _weak(self, lin: Linearization) -> tuple[torch.Tensor, torch.Tensor]:
        """(unit eigenvectors (6, K) of the normalised system whose eigenvalue is below ``hold_below``, as
        :meth:`ICPOdometry._conditioning` measures it, in the coordinates (translation, rotation times the mean
        source range); the scaling D (6,))."""
        if self._D is None:         # the scaling depends on the sources alone: made once per problem
            D = torch.tensor([1, 1, 1, self.scale, self.scale, self.scale], dtype=torch.float64, device=lin.H.device)
            self._D = D, D[:, None] * D[None, :], D.tolist()
        D, DD, scaling = self._D
        count = max(lin.weight or lin.count, 1e-12)
        if _clear_above(lin.H.detach().tolist(), scaling, count, 2 * self.hold_below):
            # every eigenvalue at least twice the floor: none below it, as eigh would say (no direction held)
            return lin.H.new_zeros(6, 0), D
        values, vectors = torch.linalg.eigh(lin.H.detach() / DD / count)
        return vectors[:, values < self.hold_below], D

    def _hold(self, lin: Linearization) -> torch.Tensor:
        """H plus a stiff prior along the directions the pairs do not constrain (:meth:`_weak`), so the step leaves
        the pose at its prediction there instead of sliding along a tunnel or an open road (Zhang et al., ICRA
        2016: solution remapping)."""
        weak, D = self._weak(lin)
        if not weak.shape[1]:
            return lin.H
        V = weak * D[:, None]                            # back to the unnormalised coordinates
        stiffness = 1e3 * float(torch.diagonal(lin.H.detach()).sum())
        return lin.H + stiffness * (V @ V.T)

    def held(self, lin: Linearization) -> torch.Tensor | None:
        """The directions :meth:`_hold` holds at ``lin`` as twists (K, 6) float64 that move the sources by one metre
        along each (a unit vector of the normalised coordinates divided by D), or None when it holds none."""
        if self.hold_below <= 0 or lin.count < 6:
            return None
        weak, D = self._weak(lin)
        return (weak / D[:, None]).T.contiguous() if weak.shape[1] else None


def _clear_above(H: list, D: list, count: float, floor: float) -> bool:
    """Whether ``H / (D D^T) / count - floor I`` (6 x 6, as nested lists) is positive definite, by a Cholesky
    factorisation in Python floats: then every eigenvalue of the normalised system exceeds ``floor``. False on any
    doubt (a pivot not above 0, NaN included), leaving the answer to ``torch.linalg.eigh``. Why: the conditioning
    check runs at every ICP iteration, and its eigh, a LAPACK call through torch, cost a sparse frame about 3 % of its
    CPU, while the floor is rarely approached (on a 64-beam drive the smallest eigenvalue is 0.014-0.017, the
    floor 0.0025)."""
    if not all(d > 0.0 for d in D):
        return False
    L = [[0.0] * 6 for _ in range(6)]
    for i in range(6):
        for j in range(i + 1):
            a = H[i][j] / (D[i] * D[j]) / count - (floor if i == j else 0.0)
            a -= sum(L[i][k] * L[j][k] for k in range(j))
            if i == j:
                if not a > 0.0:
                    return False
                L[i][i] = math.sqrt(a)
            else:
                L[i][j] = a / L[j][j]
    return True


class ICPOdometry:
    """Frame-to-model point-to-plane ICP.

    Args:
        solver: :class:`~dcslam.slam.solvers.GaussNewton` (default), ``LevenbergMarquardt`` or ``DifferentiableLM``.
        association: :class:`~dcslam.slam.association.ProjectiveAssociation` (default) or
            ``NearestNeighbourAssociation``.
        max_distance: correspondence gate, metres (pairs further apart are outliers); ignored when ``adaptive`` is
            given. Without a gate every pair pulls (gradSLAM's error).
        max_normal_angle_deg: pairs whose normals differ more are outliers.
        iterations: solver iterations (of each gate stage, unless ``coarse_iterations`` says otherwise).
        coarse_iterations: solver iterations of each wide-gate stage (every entry of ``coarse_to_fine`` but the
            last); 0: :func:`coarse_iterations_for` the frame's density (``iterations`` for sparse depth).
        min_inliers: fewer inlier pairs reject the step.
        min_conditioning: smallest eigenvalue of the normalised 6 x 6 system (rotation scaled by the mean source
            range, divided by the inlier count) below which the pose is unobservable (a plane) and the step is
            rejected.
        max_step_m, max_step_deg: an estimate further than this from ``T_init`` is rejected as a divergence.
        coarse_to_fine: gate multipliers, one solver run per entry (each up to ``iterations``): a wide gate first
            catches motions larger than the gate (a car moves about 1 m between KITTI frames), the last entry should
            be 1. ``(1.0,)`` is plain ICP with one gate, as Open3D's ``registration_icp``.
        source_voxel: keep one source point per voxel of this size (metres) for the alignment, as KISS-ICP does
            (0: every valid pixel). Near points no longer outweigh far ones and dense frames align several times
            faster; the pose stays a differentiable function of the kept pixels' depths.
        hold_below: directions of motion whose normalised eigenvalue (see :meth:`_conditioning`) is below this are
            held at the prediction (0: never); a step with such a direction is still reported, and the health check
            calls it degraded.
        kernel: robust kernel (:class:`~dcslam.slam.robust.GemanMcClure`) or None for plain least squares.
        adaptive: an :class:`~dcslam.slam.robust.AdaptiveThreshold` giving the gate from past prediction errors
            (KISS-ICP), or None for the fixed ``max_distance``. It is updated by :meth:`estimate` after each
            accepted step; :meth:`reset` clears it.

    The scene scale given to :meth:`estimate` multiplies ``max_distance`` and ``source_voxel`` (not the adaptive
    gate, which measures itself, nor ``max_step_m``).
    """

    first_pose_from_gt = False
    assess_steps = True

    def __init__(self, solver=None, association=None, max_distance: float = 0.5, max_normal_angle_deg: float = 30.0,
                 iterations: int = 20, min_inliers: int = 100, min_conditioning: float = 1e-5,
                 max_step_m: float = 5.0, max_step_deg: float = 30.0,
                 coarse_to_fine: tuple[float, ...] = (4.0, 2.0, 1.0), kernel=None, adaptive=None,
                 source_voxel: float = 0.0, hold_below: float = 0.0, coarse_iterations: int = 0):
        if not coarse_to_fine or any(m <= 0 for m in coarse_to_fine):
            raise DcslamError(f"coarse_to_fine must be positive gate multipliers, got {coarse_to_fine}")
        if coarse_iterations < 0:
            raise DcslamError(f"coarse_iterations must be >= 0, got {coarse_iterations}")
        self.coarse_iterations = coarse_iterations
        self.coarse_to_fine = tuple(coarse_to_fine)
        self.solver = solver if solver is not None else GaussNewton()
        self.association = association if association is not None else ProjectiveAssociation()
        self.max_distance, self.iterations = max_distance, iterations
        self.cos_max_angle = math.cos(math.radians(max_normal_angle_deg))
        self.min_inliers, self.min_conditioning = min_inliers, min_conditioning
        self.max_step_m, self.max_step_rad = max_step_m, math.radians(max_step_deg)
        self.kernel, self.adaptive, self.source_voxel = kernel, adaptive, source_voxel
        self.hold_below = hold_below

    def reset(self) -> None:
        """Forget what past steps taught (the adaptive threshold); call at the start of a sequence."""
        if self.adaptive is not None:
            self.adaptive.reset()

    def estimate(self, frame: Frame, model: ModelView | None, T_init: torch.Tensor,
                 T_gt: torch.Tensor | None = None, T_last: torch.Tensor | None = None,
                 scale: float = 1.0) -> OdometryResult:
        """Align ``frame`` to ``model`` from ``T_init`` (4, 4), the prediction; ``T_last`` (4, 4), the previous
        frame's pose, lets the adaptive threshold tell a moving step from a standing one; ``scale``: the scene
        scale (see :class:`dcslam.slam.parts.Odometry`). ``T_gt`` is not used."""
        T_init = T_init.to(frame.depth.dtype)
        if model is None:
            return OdometryResult(T_init, False, "empty model")
        valid, source, normals, weights = self.sources(frame, scale)
        if valid < self.min_inliers:
            return OdometryResult(T_init, False, f"{valid} valid source points", sources=valid)
        H, W = frame.shape
        coarse = self.coarse_iterations or coarse_iterations_for(valid / max(H * W, 1), self.iterations)
        associate = self.association.prepare(model)
        gate = self.adaptive.gate() if self.adaptive is not None else self.max_distance * scale
        T, iterations = T_init, 0
        for stage, multiplier in enumerate(self.coarse_to_fine):
            problem = PointToPlane(source, normals, associate, gate * multiplier, self.cos_max_angle, self.kernel,
                                   self.hold_below, weights)
            last = stage == len(self.coarse_to_fine) - 1
            result = self.solver.solve(problem, T, self.iterations if last else coarse)
            T, iterations = result.T, iterations + result.iterations
        lin = problem.linearize(T.detach())
        r = problem._fixed_residuals(T.detach())
        rmse = math.sqrt(float((r.detach().double() ** 2).mean())) if r.numel() else math.inf
        base = dict(iterations=iterations, inliers=lin.count, rmse=rmse, sources=source.shape[0], gate=gate)
        if not bool(torch.isfinite(T).all()):
            return OdometryResult(T_init, False, "non-finite pose", **base)
        if lin.count < self.min_inliers:
            return OdometryResult(T_init, False, f"{lin.count} inliers", **base)
        base["conditioning"] = conditioning = self._conditioning(lin, source)
        cov = problem.covariance(T, lin, r)
        base["information"], base["covariance"], base["held"] = lin.H.detach().double(), cov, problem.held(lin)
        base["sigma_m"] = math.sqrt(max(float(torch.linalg.eigvalsh(cov[:3, :3])[-1]), 0.0))
        base["sigma_deg"] = math.degrees(math.sqrt(max(float(torch.linalg.eigvalsh(cov[3:, 3:])[-1]), 0.0)))
        if conditioning < self.min_conditioning:
            return OdometryResult(T_init, False, f"degenerate geometry (conditioning {conditioning:.1e})", **base)
        step_m, step_rad = relative_motion(T_init.detach(), T.detach())
        if float(step_m) > self.max_step_m or float(step_rad) > self.max_step_rad:
            return OdometryResult(T_init, False, "diverged", **base)
        if self.adaptive is not None:
            self.adaptive.update(T_init, T, T_last if T_last is not None else T_init)
        return OdometryResult(T, True, "", **base)

    def sources(self, frame: Frame, scale: float = 1.0) -> tuple[int, torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """(number of valid pixels, source points (F, 3), their normals (F, 3), their weights (F,) or None) of a
        frame: every valid pixel, or one per ``source_voxel * scale``. They depend on the frame alone, so they are
        kept in :attr:`Frame.cache` (per voxel size) and may be computed ahead, on another thread
        (:meth:`precompute`)."""
        voxel = self.source_voxel * scale
        key = ("icp-sources", voxel)
        if key not in frame.cache:
            pixels, source = valid_points(frame)
            normals = valid_normals(frame)
            valid = pixels.numel()
            if voxel > 0 and valid >= self.min_inliers:
                keep = voxel_representatives(source, voxel)
                source, pixels, normals = (x.index_select(0, keep) for x in (source, pixels, normals))
            weights = None if frame.weight is None else frame.weight.reshape(-1).index_select(0, pixels)
            frame.cache[key] = (valid, source, normals, weights)
        return frame.cache[key]

    def precompute(self, frame: Frame, scale: float = 1.0) -> None:
        """Do the work on ``frame`` that does not depend on the map or the pose (:meth:`sources`)."""
        self.sources(frame, scale)

    def effective_settings(self, scale: float) -> dict:
        """``source_voxel`` and ``max_distance`` (the last gate) at ``scale``, and ``gates``, the gate of each
        coarse-to-fine stage (metres); the last two are None with the adaptive threshold, whose gate varies."""
        gate = None if self.adaptive is not None else self.max_distance * scale
        return {"source_voxel": self.source_voxel * scale, "max_distance": gate,
                "gates": None if gate is None else [gate * m for m in self.coarse_to_fine]}

    @staticmethod
    def _conditioning(lin: Linearization, source: torch.Tensor) -> float:
        """Smallest eigenvalue of J^T W J per unit weight, rotations scaled by the mean range: how well the pairs
        that count constrain each direction of motion (about 1/3 for a well-spread scene, 0 for a plane)."""
        scale = float(torch.linalg.vector_norm(source.detach(), dim=1).mean())
        D = torch.tensor([1, 1, 1, scale, scale, scale], dtype=torch.float64, device=lin.H.device)
        total = lin.weight if lin.weight is not None else lin.count
        Hn = lin.H.detach() / (D[:, None] * D[None, :]) / max(total, 1e-12)
        return float(torch.linalg.eigvalsh(Hn)[0])
