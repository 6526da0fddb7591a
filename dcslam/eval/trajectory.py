"""Trajectory scores: the thesis's localisation accuracy, and ATE / RPE with evo's definitions.

All poses are ``T_world_cam`` (N, 4, 4) float64; ``gt`` is the reference, ``est`` the estimate, pose i of one
paired with pose i of the other (see :func:`pair_by_timestamps`).

* Localisation accuracy (thesis, eq. in chapter 5): for each pose pair ``X = T_gt⁻¹ T_est``,
  ``L = ‖t_X‖ + acos((trace(R_X) − 1) / 2)`` (metres + radians), averaged over the poses. Every rotation angle here
  (this one, RPE's, the drift's) is :func:`dcslam.geometry.motion.relative_motion`'s: the angle that acos names,
  computed as ``atan2(|sin|, cos)`` (exact near 0 and π, where acos of the trace loses half its digits) with a
  general inverse of ``T_gt`` (files' rotations are orthonormal to ~1e-7 only), so a trajectory scored against
  itself scores 0 to rounding. The thesis's code clamped the acos argument to [0, 1]: every rotation error above
  90° then counted as exactly π/2 — a defect, reproducible here with ``thesis_clamp=True``.
* ATE (evo's APE, ``translation_part``): per pose ``‖t_est,i − t_gt,i‖`` after aligning the estimate to the
  reference with the SE(3) Umeyama fit of positions (``evo_ape -a``), or without alignment.
* RPE (evo's RPE, delta 1 frame, consecutive pairs): ``E_i = (Q_i⁻¹ Q_{i+1})⁻¹ (P_i⁻¹ P_{i+1})`` with Q = gt and
  P = est; translation error ``‖t_E‖`` (m), rotation error = angle of ``R_E`` in degrees.
* KITTI odometry drift (the odometry devkit's ``evaluate_odometry.cpp``): from every 10th frame, for each length
  L in 100, 200, ..., 800 m, the segment ends at the first frame whose path length along the *ground truth*
  exceeds the start's by more than L; its error is ``E = (P_s⁻¹ P_e)⁻¹ (Q_s⁻¹ Q_e)`` (Q = gt, P = est);
  ``‖t_E‖ / L`` and ``angle(R_E) / L`` are averaged over all segments of all lengths:
  t_rel in % and r_rel in deg/100 m (the devkit's stats file has m/m and rad/m; its leaderboard prints % and
  deg/m). The devkit's "every 10 frames" is one second at KITTI's 10 Hz. It computes in 32-bit floats; here
  float64 with general matrix inverses, as in KISS-ICP's port of it, against which this is tested
  (tests/data/kitti_drift_reference.json).

Statistics are evo's: rmse, mean, median, std (population), min, max.

Pairing: :func:`associate_timestamps` pairs estimate and reference as evo's ``associate_trajectories`` does (nearest
timestamp within ``max_time_diff``, 10 ms by default); pose i of ``T_gt`` then goes with pose i of ``T_est``.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from dcslam.errors import DcslamError
from dcslam.geometry.motion import relative_motion

STATISTICS = ("rmse", "mean", "median", "std", "min", "max")
#: Segment lengths (m) and start step (frames) of the KITTI odometry devkit.
DRIFT_LENGTHS_M = (100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0)
DRIFT_STEP_FRAMES = 10
#: evo's default ``max_diff`` of ``associate_trajectories`` (seconds).
EVO_MAX_TIME_DIFF_S = 0.01


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


def localisation_errors(T_gt: np.ndarray, T_est: np.ndarray, thesis_clamp: bool = False) -> np.ndarray:
    """Per-pose localisation error L of the thesis (metres + radians). Shapes: (N, 4, 4), (N, 4, 4) → (N,).

    The angle is that of :func:`dcslam.geometry.motion.relative_motion` (``acos((trace − 1) / 2)`` evaluated
    exactly, with a true inverse of ``T_gt``). ``thesis_clamp=True`` clamps the acos argument to [0, 1] as the
    thesis's code did (a defect: rotation errors above 90° all count as π/2).
    """
    T_gt, T_est = _check_poses(T_gt, T_est)
    metres, radians = relative_motion(T_gt, T_est)
    if thesis_clamp:        # acos(clip(c, 0, 1)) = min(acos(c), π/2)
        radians = np.minimum(radians, np.pi / 2)
    return metres + radians


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
    Q_rel = np.linalg.solve(T_gt[:-delta], T_gt[delta:])
    P_rel = np.linalg.solve(T_est[:-delta], T_est[delta:])
    metres, radians = relative_motion(Q_rel, P_rel)
    return metres, np.degrees(radians)


def path_distances(T_world_cam: np.ndarray) -> np.ndarray:
    """Cumulative path length (m) at each pose, 0 at the first (the devkit's ``trajectoryDistances``).
    Shapes: (N, 4, 4) → (N,)."""
    (T,) = _check_poses(T_world_cam)
    steps = np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(steps)])


@dataclass(frozen=True)
class DriftSegment:
    """One devkit segment: frames ``first``..``last``, nominal ``length_m``, errors per metre (m/m and rad/m)."""

    first: int
    last: int
    length_m: float
    t_err_per_m: float
    r_err_rad_per_m: float


def drift_segments(T_gt: np.ndarray, T_est: np.ndarray, lengths_m=DRIFT_LENGTHS_M,
                   step: int = DRIFT_STEP_FRAMES) -> list[DriftSegment]:
    """Every segment the KITTI odometry devkit scores (its ``calcSequenceErrors``), in its order: starts every
    ``step`` frames, then lengths ascending. Empty when the ground truth is shorter than the shortest length.
    Shapes: (N, 4, 4), (N, 4, 4), paired pose by pose."""
    T_gt, T_est = _check_poses(T_gt, T_est)
    dist = path_distances(T_gt)
    firsts = np.arange(0, len(T_gt), step)
    lengths = np.asarray(lengths_m, dtype=np.float64)
    # the first frame whose distance exceeds dist[first] + length (dist is non-decreasing, so the devkit's linear
    # scan from ``first`` finds the same frame); len(dist) = none
    lasts = np.searchsorted(dist, dist[firsts][:, None] + lengths[None, :], side="right")
    first_idx, length_idx = np.nonzero(lasts < len(dist))
    if len(first_idx) == 0:
        return []
    first, last = firsts[first_idx], lasts[first_idx, length_idx]
    # general matrix inverses, as the devkit's Matrix::inv: the benchmark's files print 6 digits, so their rotations
    # are orthonormal to ~1e-7 only, and a transpose-inverse would move r_rel by ~1e-6 of itself
    solve = np.linalg.solve
    metres, radians = relative_motion(solve(T_est[first], T_est[last]), solve(T_gt[first], T_gt[last]))
    length = lengths[length_idx]
    t_err = metres / length
    r_err = radians / length
    return [DriftSegment(int(f), int(la), float(L), float(t), float(r))
            for f, la, L, t, r in zip(first, last, length, t_err, r_err)]


@dataclass(frozen=True)
class DriftFigures:
    """Mean drift over ``segments`` segments: t_rel in %, r_rel in deg/100 m."""

    segments: int
    t_rel_percent: float
    r_rel_deg_per_100m: float

    @classmethod
    def of(cls, segments: list[DriftSegment]) -> "DriftFigures":
        return cls(segments=len(segments),
                   t_rel_percent=100.0 * float(np.mean([s.t_err_per_m for s in segments])),
                   r_rel_deg_per_100m=100.0 * float(np.degrees(np.mean([s.r_err_rad_per_m for s in segments]))))


@dataclass(frozen=True)
class KittiDrift:
    """The KITTI odometry devkit's drift of one trajectory.

    ``overall`` averages every segment of every length (the devkit's figure); ``per_length`` maps each length with
    at least one segment to its own mean (the devkit's error-vs-length plot shows a length only when it has 3 or more
    segments). When the ground-truth path is shorter than 100 m, ``overall`` is ``None`` and ``note`` says so.
    """

    path_length_m: float
    overall: DriftFigures | None
    per_length: dict[float, DriftFigures]
    note: str = ""


def kitti_drift(T_gt: np.ndarray, T_est: np.ndarray, lengths_m=DRIFT_LENGTHS_M,
                step: int = DRIFT_STEP_FRAMES) -> KittiDrift:
    """KITTI odometry drift (t_rel %, r_rel deg/100 m) of an estimate against its reference, exactly as the devkit's
    ``evaluate_odometry.cpp`` computes it (see the module docstring). Shapes: (N, 4, 4), (N, 4, 4), paired pose by
    pose, poses ``step`` frames apart being the devkit's one second."""
    T_gt, T_est = _check_poses(T_gt, T_est)
    path_length = float(path_distances(T_gt)[-1])
    segments = drift_segments(T_gt, T_est, lengths_m, step)
    if not segments:
        return KittiDrift(path_length_m=path_length, overall=None, per_length={},
                          note=f"too short for KITTI drift: the reference path is {path_length:.1f} m, the shortest "
                               f"segment {min(lengths_m):g} m")
    per_length = {}
    for length in lengths_m:
        selected = [s for s in segments if s.length_m == length]
        if selected:
            per_length[float(length)] = DriftFigures.of(selected)
    return KittiDrift(path_length_m=path_length, overall=DriftFigures.of(segments), per_length=per_length)


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
    drift: KittiDrift | None = None

    def flat(self) -> dict:
        """One flat dict, e.g. ``ate_aligned_rmse``, for CSV rows; KITTI drift as ``kitti_t_rel_percent``,
        ``kitti_r_rel_deg_per_100m`` and ``kitti_segments`` (empty and 0 when the drive is too short)."""
        row = {"poses": self.poses, "localisation": self.localisation,
               "localisation_thesis_clamp": self.localisation_thesis_clamp}
        for name in ("ate_aligned", "ate", "rpe_trans_m", "rpe_rot_deg"):
            stats = getattr(self, name)
            for s in STATISTICS:
                row[f"{name}_{s}"] = None if stats is None else getattr(stats, s)
        overall = None if self.drift is None else self.drift.overall
        row["kitti_t_rel_percent"] = None if overall is None else overall.t_rel_percent
        row["kitti_r_rel_deg_per_100m"] = None if overall is None else overall.r_rel_deg_per_100m
        row["kitti_segments"] = 0 if overall is None else overall.segments
        return row


def score_trajectory(T_gt: np.ndarray, T_est: np.ndarray) -> TrajectoryScores:
    """Every score of an estimate against its reference (paired pose by pose). Shapes: (N, 4, 4) each.

    RPE is ``None`` for a single pose; aligned ATE is ``None`` when the positions are degenerate (all on one line
    or point), where evo's alignment fails too; ``drift.overall`` is ``None`` when the reference path is shorter
    than 100 m.
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
        rpe_rot_deg=None if rpe is None else Statistics.of(rpe[1]),
        drift=kitti_drift(T_gt, T_est))


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


@dataclass(frozen=True)
class Association:
    """Poses of an estimate and a reference paired by timestamp: ``est_indices`` (M,) and ``gt_indices`` (M,)
    index the two trajectories; ``est_poses`` / ``gt_poses`` are their full lengths; ``time_diffs_s`` (M,) the
    absolute timestamp differences of the pairs."""

    est_indices: np.ndarray
    gt_indices: np.ndarray
    est_poses: int
    gt_poses: int
    time_diffs_s: np.ndarray
    max_time_diff_s: float

    @property
    def pairs(self) -> int:
        return len(self.est_indices)

    def summary(self) -> str:
        """e.g. ``28 of 30 estimated poses paired with 40 reference poses (max. time difference 10 ms)``."""
        return (f"{self.pairs} of {self.est_poses} estimated poses paired with {self.gt_poses} reference poses "
                f"(max. time difference {1000 * self.max_time_diff_s:g} ms)")


def _nearest(t_query: np.ndarray, t_sorted: np.ndarray) -> np.ndarray:
    """Index in ``t_sorted`` of the nearest timestamp to each of ``t_query``; a tie goes to the earlier one (as
    ``np.argmin`` of the differences)."""
    right = np.clip(np.searchsorted(t_sorted, t_query, side="left"), 0, len(t_sorted) - 1)
    left = np.clip(right - 1, 0, len(t_sorted) - 1)
    take_left = np.abs(t_sorted[left] - t_query) <= np.abs(t_sorted[right] - t_query)
    return np.where(take_left, left, right)


def associate_timestamps(t_est: np.ndarray, t_gt: np.ndarray,
                         max_time_diff: float = EVO_MAX_TIME_DIFF_S) -> Association:
    """Pair estimated and reference poses by nearest timestamp, as evo's ``associate_trajectories``.

    Each pose of the trajectory with fewer poses (the estimate when both are as long) takes the nearest timestamp of
    the other; the pair is kept when they differ by at most ``max_time_diff`` seconds. Fails
    (:class:`DcslamError`) on empty, non-finite or not strictly increasing timestamps, a negative tolerance, or when
    no pose pairs. Shapes: (N,), (M,).
    """
    t_est, t_gt = np.asarray(t_est, dtype=np.float64), np.asarray(t_gt, dtype=np.float64)
    for name, t in (("estimated", t_est), ("reference", t_gt)):
        if t.ndim != 1 or len(t) == 0:
            raise DcslamError(f"{name} timestamps have shape {t.shape}, expected (N,) with N > 0")
        if not np.all(np.isfinite(t)):
            raise DcslamError(f"{name} timestamps are not all finite")
        if np.any(np.diff(t) <= 0):
            raise DcslamError(f"{name} timestamps are not strictly increasing")
    if not max_time_diff >= 0:
        raise DcslamError(f"max_time_diff is {max_time_diff}, expected >= 0 seconds")
    # evo walks the shorter trajectory (the estimate, its second one, when both are as long)
    if len(t_est) > len(t_gt):
        gt_idx, est_idx = np.arange(len(t_gt)), _nearest(t_gt, t_est)
    else:
        est_idx, gt_idx = np.arange(len(t_est)), _nearest(t_est, t_gt)
    diffs = np.abs(t_est[est_idx] - t_gt[gt_idx])
    keep = diffs <= max_time_diff
    if not keep.any():
        raise DcslamError(f"no estimated pose has a reference timestamp within {1000 * max_time_diff:g} ms "
                          f"(estimate {t_est[0]:.3f}..{t_est[-1]:.3f} s, {len(t_est)} poses; reference "
                          f"{t_gt[0]:.3f}..{t_gt[-1]:.3f} s, {len(t_gt)} poses); check the time bases or raise "
                          "the maximum time difference")
    return Association(est_indices=est_idx[keep], gt_indices=gt_idx[keep], est_poses=len(t_est),
                       gt_poses=len(t_gt), time_diffs_s=diffs[keep], max_time_diff_s=float(max_time_diff))
