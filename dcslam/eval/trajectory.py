"""Trajectory scores: the thesis's localisation accuracy, and ATE / RPE with evo's definitions.

All poses are ``T_world_cam`` (N, 4, 4) float64; ``gt`` is the reference, ``est`` the estimate, pose i of one
paired with pose i of the other (see :func:`pair_by_timestamps`).

* Localisation accuracy (thesis, eq. in chapter 5): for each pose pair ``X = T_gt⁻¹ T_est``,
  ``L = ‖t_X‖ + acos((trace(R_X) − 1) / 2)`` (metres + radians), averaged over the poses. The argument of acos is
  clamped to [−1, 1], which only guards against round-off. The thesis's code clamped it to [0, 1]: every rotation
  error above 90° then counted as exactly π/2, and a round-off above 1 was harmless but a value below 0 was not —
  a defect, reproducible here with ``thesis_clamp=True``.
* ATE (evo's APE, ``translation_part``): per pose ``‖t_est,i − t_gt,i‖`` after aligning the estimate to the
  reference with the SE(3) Umeyama fit of positions (``evo_ape -a``), or without alignment.
* RPE (evo's RPE, delta 1 frame, consecutive pairs): ``E_i = (Q_i⁻¹ Q_{i+1})⁻¹ (P_i⁻¹ P_{i+1})`` with Q = gt and
  P = est; translation error ``‖t_E‖`` (m), rotation error = angle of ``R_E`` in degrees.

Statistics are evo's: rmse, mean, median, std (population), min, max.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from dcslam.errors import DcslamError

STATISTICS = ("rmse", "mean", "median", "std", "min", "max")


def _check_poses(*poses: np.ndarray) -> list[np.ndarray]:
    out = []
    for T in poses:
        T = np.asarray(T, dtype=np.float64)
        if T.ndim != 3 or T.shape[1:] != (4, 4):
            raise DcslamError(f"poses have shape {T.shape}, expected (N, 4, 4)")
        out.append(T)
    if len({len(T) for T in out}) > 1:
        raise DcslamError(f"trajectories have different lengths: {', '.join(str(len(T)) for T in out)} poses")
    if len(out[0]) == 0:
        raise DcslamError("empty trajectory")
    return out


def invert_se3(T: np.ndarray) -> np.ndarray:
    """(..., 4, 4) rigid transforms → their inverses."""
    T = np.asarray(T, dtype=np.float64)
    R_inv = np.swapaxes(T[..., :3, :3], -1, -2)
    out = np.zeros_like(T)
    out[..., :3, :3] = R_inv
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", R_inv, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def rotation_angle(R: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations → (N,) angles in radians in [0, π], from the unit quaternion (accurate near 0 and π,
    where ``acos`` of the trace is not)."""
    from dcslam.geometry.rotations import rotation_to_quaternion

    q = rotation_to_quaternion(np.asarray(R, dtype=np.float64))
    return 2.0 * np.arctan2(np.linalg.norm(q[..., :3], axis=-1), np.abs(q[..., 3]))


def localisation_errors(T_gt: np.ndarray, T_est: np.ndarray, thesis_clamp: bool = False) -> np.ndarray:
    """Per-pose localisation error L of the thesis (metres + radians). Shapes: (N, 4, 4), (N, 4, 4) → (N,).

    ``thesis_clamp=True`` clamps the acos argument to [0, 1] as the thesis's code did (a defect: rotation errors
    above 90° all count as π/2).
    """
    T_gt, T_est = _check_poses(T_gt, T_est)
    X = invert_se3(T_gt) @ T_est
    cos_angle = (np.trace(X[:, :3, :3], axis1=1, axis2=2) - 1.0) / 2.0
    cos_angle = np.clip(cos_angle, 0.0 if thesis_clamp else -1.0, 1.0)
    return np.linalg.norm(X[:, :3, 3], axis=1) + np.arccos(cos_angle)


def localisation_accuracy(T_gt: np.ndarray, T_est: np.ndarray, thesis_clamp: bool = False) -> float:
    """The thesis's localisation accuracy: the mean of :func:`localisation_errors` (lower is better)."""
    return float(localisation_errors(T_gt, T_est, thesis_clamp).mean())


def umeyama_alignment(x: np.ndarray, y: np.ndarray, with_scale: bool = False) -> tuple[np.ndarray, np.ndarray, float]:
    """Least-squares similarity (R, t, s) with ``y ≈ s R x + t`` (Umeyama 1991, as in evo).

    Shapes: x (N, 3), y (N, 3) → R (3, 3), t (3,), s. Fails when the points are degenerate (fewer than 2
    independent directions), where no unique rotation exists.
    """
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    if x.shape != y.shape or x.ndim != 2 or x.shape[1] != 3:
        raise DcslamError(f"point sets have shapes {x.shape} and {y.shape}, expected two (N, 3)")
    mean_x, mean_y = x.mean(axis=0), y.mean(axis=0)
    xc, yc = x - mean_x, y - mean_y
    sigma_x = (xc ** 2).sum() / len(x)
    cov = yc.T @ xc / len(x)
    u, d, vt = np.linalg.svd(cov)
    if np.count_nonzero(d > np.finfo(d.dtype).eps) < 2:
        raise DcslamError("trajectory positions are degenerate (all on a line or a point); alignment is not possible")
    S = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        S[2, 2] = -1.0
    R = u @ S @ vt
    s = float(np.trace(np.diag(d) @ S) / sigma_x) if with_scale else 1.0
    t = mean_y - s * R @ mean_x
    return R, t, s


@dataclass(frozen=True)
class Statistics:
    """evo's statistics of an error vector."""

    rmse: float
    mean: float
    median: float
    std: float
    min: float
    max: float

    @classmethod
    def of(cls, errors: np.ndarray) -> "Statistics":
        errors = np.asarray(errors, dtype=np.float64)
        if errors.size == 0:
            raise DcslamError("no errors to summarise")
        return cls(rmse=float(np.sqrt(np.mean(errors ** 2))), mean=float(np.mean(errors)),
                   median=float(np.median(errors)), std=float(np.std(errors)), min=float(np.min(errors)),
                   max=float(np.max(errors)))

    def as_dict(self) -> dict:
        return asdict(self)


def ate_errors(T_gt: np.ndarray, T_est: np.ndarray, align: bool = True) -> np.ndarray:
    """Per-pose translation errors (m) of evo's APE. Shapes: (N, 4, 4), (N, 4, 4) → (N,)."""
    T_gt, T_est = _check_poses(T_gt, T_est)
    p_gt, p_est = T_gt[:, :3, 3], T_est[:, :3, 3]
    if align:
        R, t, _ = umeyama_alignment(p_est, p_gt)
        p_est = p_est @ R.T + t
    return np.linalg.norm(p_est - p_gt, axis=1)


def rpe_errors(T_gt: np.ndarray, T_est: np.ndarray, delta: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Per-pair errors of evo's RPE over pairs (i, i + delta).

    Shapes: (N, 4, 4), (N, 4, 4) → translation errors (N − delta,) metres, rotation errors (N − delta,) degrees.
    """
    T_gt, T_est = _check_poses(T_gt, T_est)
    if delta < 1 or len(T_gt) <= delta:
        raise DcslamError(f"RPE needs more than delta={delta} poses, got {len(T_gt)}")
    Q_rel = invert_se3(T_gt[:-delta]) @ T_gt[delta:]
    P_rel = invert_se3(T_est[:-delta]) @ T_est[delta:]
    E = invert_se3(Q_rel) @ P_rel
    return np.linalg.norm(E[:, :3, 3], axis=1), np.degrees(rotation_angle(E[:, :3, :3]))


@dataclass(frozen=True)
class TrajectoryScores:
    """All trajectory scores of one estimate against its reference."""

    poses: int
    localisation: float
    localisation_thesis_clamp: float
    ate_aligned: Statistics | None
    ate: Statistics
    rpe_trans_m: Statistics | None
    rpe_rot_deg: Statistics | None

    def flat(self) -> dict:
        """One flat dict, e.g. ``ate_aligned_rmse``, for CSV rows."""
        row = {"poses": self.poses, "localisation": self.localisation,
               "localisation_thesis_clamp": self.localisation_thesis_clamp}
        for name in ("ate_aligned", "ate", "rpe_trans_m", "rpe_rot_deg"):
            stats = getattr(self, name)
            for s in STATISTICS:
                row[f"{name}_{s}"] = None if stats is None else getattr(stats, s)
        return row


def score_trajectory(T_gt: np.ndarray, T_est: np.ndarray) -> TrajectoryScores:
    """Every score of an estimate against its reference (paired pose by pose). Shapes: (N, 4, 4) each.

    RPE is ``None`` for a single pose; aligned ATE is ``None`` when the positions are degenerate (all on one line
    or point), where evo's alignment fails too.
    """
    T_gt, T_est = _check_poses(T_gt, T_est)
    rpe = rpe_errors(T_gt, T_est) if len(T_gt) > 1 else None
    try:
        ate_aligned = Statistics.of(ate_errors(T_gt, T_est, align=True))
    except DcslamError:
        ate_aligned = None
    return TrajectoryScores(
        poses=len(T_gt), localisation=localisation_accuracy(T_gt, T_est),
        localisation_thesis_clamp=localisation_accuracy(T_gt, T_est, thesis_clamp=True),
        ate_aligned=ate_aligned,
        ate=Statistics.of(ate_errors(T_gt, T_est, align=False)),
        rpe_trans_m=None if rpe is None else Statistics.of(rpe[0]),
        rpe_rot_deg=None if rpe is None else Statistics.of(rpe[1]))


def pair_by_timestamps(t_est: np.ndarray, t_gt: np.ndarray, allow_prefix: bool = False,
                       tolerance_s: float = 1e-4) -> int:
    """Check that an estimate's timestamps match the reference's, pose for pose; return the number of pairs.

    With ``allow_prefix`` the estimate may cover only the first poses of the reference (a SLAM run over the first
    ``frames`` frames of a drive); otherwise both must have the same length. Fails (:class:`DcslamError`) on
    different lengths, unsorted timestamps or timestamps that differ by more than ``tolerance_s``.
    Shapes: (N,), (M,).
    """
    t_est, t_gt = np.asarray(t_est, dtype=np.float64), np.asarray(t_gt, dtype=np.float64)
    for name, t in (("estimated", t_est), ("reference", t_gt)):
        if t.ndim != 1 or len(t) == 0:
            raise DcslamError(f"{name} timestamps have shape {t.shape}, expected (N,) with N > 0")
        if np.any(np.diff(t) <= 0):
            raise DcslamError(f"{name} timestamps are not strictly increasing")
    n = len(t_est)
    if n > len(t_gt) or (n != len(t_gt) and not allow_prefix):
        raise DcslamError(f"trajectories have different lengths: {n} estimated poses, {len(t_gt)} reference poses")
    worst = float(np.max(np.abs(t_est - t_gt[:n])))
    if worst > tolerance_s:
        bad = int(np.argmax(np.abs(t_est - t_gt[:n])))
        raise DcslamError(f"timestamps do not match: estimated pose {bad} at {t_est[bad]:.6f} s, reference at "
                          f"{t_gt[bad]:.6f} s")
    return n
