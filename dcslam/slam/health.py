"""Is a SLAM step, and a whole run, to be trusted? Verdicts from evidence, so that SLAM never fails silently.

Each odometry step gets one verdict:

- ``rejected``: the odometry refused the estimate (too few points or pairs, degenerate geometry, non-finite, a
  divergence) and the pose is the constant-velocity prediction;
- ``degraded``: the estimate was kept but the evidence is weak: few pairs (a count of them) constrain it, the pairs
  barely constrain some direction of motion (a tunnel, a plane), or the estimate ended far from the
  constant-velocity prediction (a car cannot change its velocity by metres in 0.1 s);
- ``accepted``: none of that.

:func:`summarise` turns a run's reports into counts and a ``suspect`` flag with its reasons: a run is suspect when
any step was rejected, when more than a small fraction of its steps were degraded, when two consecutive steps were,
or when its accumulated first-order uncertainty (:func:`drift_sigma_m`, three sigma) says it may end more than
``max_drift_m`` from the truth: slow drift that no single step shows.

The thresholds of :class:`HealthRules` are calibrated on generated street drives at 64, 32, 16 and 8 beams and on
dense depth; the measurements behind each are in docs/slam.md ("Health rules and their calibration").
"""
from __future__ import annotations

import math
from dataclasses import dataclass

VERDICTS = ("accepted", "degraded", "rejected")


@dataclass(frozen=True)
class HealthRules:
    """Thresholds of the verdicts (calibration: docs/slam.md, "Health rules and their calibration").

    min_pairs: a step with fewer pairs (inliers) than this is degraded. A count, not a share of the frame's points:
        how precisely a step is measured depends on how many pairs constrain it, whatever the depth's density.
        100, the ICP odometry's own ``min_inliers``: on 8-beam depth the count does not tell drives that track from
        drives that do not (those ending within 0.5 m pair 100-214 per step, those ending further 100-156); their
        rejected steps do. A higher count flagged 8- and 16-beam drives that end 0.06-0.23 m off.
    min_conditioning: normalised conditioning (see :meth:`ICPOdometry._conditioning`) below which a step is
        degraded (the odometry itself rejects below its own, lower, bound).
    max_prediction_gap_m, max_prediction_gap_deg: distance of the estimate from the constant-velocity prediction
        above which a step is degraded (only once a velocity is known, from the third frame on).
    max_degraded_fraction: a run with more degraded steps than this fraction is suspect.
    max_degraded_run: a run with more consecutive degraded steps than this is suspect (isolated weak steps happen;
        two in a row mean the tracker has lost the scene).
    max_rejected: a run with more rejected steps than this is suspect.
    max_drift_m: a run whose accumulated uncertainty (three times :func:`drift_sigma_m`) exceeds this may end
        further than this from the truth, and is suspect (0: never). The bound is absolute, as the question it
        answers ("may this trajectory be more than 0.5 m off?"): a longer drive accumulates more and is flagged
        sooner.
    """

    min_pairs: int = 100
    min_conditioning: float = 2.5e-3
    max_prediction_gap_m: float = 0.5
    max_prediction_gap_deg: float = 3.0
    max_degraded_fraction: float = 0.1
    max_degraded_run: int = 1
    max_rejected: int = 0
    max_drift_m: float = 0.5


def assess(accepted: bool, reason: str, inliers: int, sources: int, conditioning: float, gap_m: float,
           gap_deg: float, has_velocity: bool, rules: HealthRules = HealthRules()) -> tuple[str, list[str]]:
    """The verdict of one odometry step and the evidence behind it -> (verdict, reasons)."""
    if not accepted:
        return "rejected", [reason or "rejected by the odometry"]
    reasons = []
    if inliers < rules.min_pairs:
        reasons.append(f"{inliers} of {sources} points paired (fewer than {rules.min_pairs} pairs)")
    if not math.isnan(conditioning) and conditioning < rules.min_conditioning:
        reasons.append(f"weakly constrained (conditioning {conditioning:.1e})")
    if has_velocity and (gap_m > rules.max_prediction_gap_m or gap_deg > rules.max_prediction_gap_deg):
        reasons.append(f"{gap_m:.2f} m / {gap_deg:.1f} deg from the constant-velocity prediction")
    return ("degraded" if reasons else "accepted"), reasons


def drift_sigma_m(reports) -> float:
    """First-order standard deviation of the last position accumulated over a run, from each measured step's own
    uncertainty (``sigma_m``, ``sigma_deg`` of :class:`~dcslam.slam.pipeline.StepReport`): position errors add up as
    a random walk, and a heading error at frame i moves every later position by the path length still to drive times
    that angle. Rejected steps and steps without an estimate (NaN) add nothing (they are flagged on their own).

    A drift no single step shows (every step a little short along a street with few facades) adds up here. ICP's
    covariance treats residuals as independent and so underestimates the true error; :class:`HealthRules` bounds it
    by measurement.
    """
    if not reports:
        return 0.0
    import torch

    positions = torch.stack([r.T_world_cam.detach().double()[:3, 3].cpu() for r in reports])
    lengths = (positions[1:] - positions[:-1]).norm(dim=1)
    still_to_drive = (lengths.flip(0).cumsum(0).flip(0).tolist() + [0.0]) if len(lengths) else [0.0]
    variance = 0.0
    for r in reports:
        if r.index == 0 or r.verdict == "rejected" or math.isnan(r.sigma_m) or math.isnan(r.sigma_deg):
            continue
        lever = still_to_drive[r.index] if r.index < len(still_to_drive) else 0.0
        variance += r.sigma_m ** 2 + (math.radians(r.sigma_deg) * lever) ** 2
    return math.sqrt(variance)


def summarise(reports, rules: HealthRules = HealthRules()) -> dict:
    """Counts of verdicts over a run's step reports (objects with ``index``, ``verdict`` and ``health``; the first
    frame, which has nothing to align to, is not counted) and whether the trajectory is suspect, with why.

    Returns ``{"accepted": n, "degraded": n, "rejected": n, "suspect": bool, "reasons": [str],
    "flagged_steps": [{"frame": i, "verdict": v, "why": [str]}], "drift_sigma_m": s}`` (:func:`drift_sigma_m`).
    """
    steps = [r for r in reports if r.index > 0]
    counts = {v: sum(r.verdict == v for r in steps) for v in VERDICTS}
    reasons = []
    if counts["rejected"] > rules.max_rejected:
        reasons.append(f"{counts['rejected']} of {len(steps)} steps rejected (pose predicted, not measured)")
    if steps and counts["degraded"] > rules.max_degraded_fraction * len(steps):
        reasons.append(f"{counts['degraded']} of {len(steps)} steps degraded "
                       f"(more than {rules.max_degraded_fraction:.0%})")
    run = longest = 0
    for r in steps:
        run = run + 1 if r.verdict == "degraded" else 0
        longest = max(longest, run)
    if longest > rules.max_degraded_run:
        reasons.append(f"{longest} consecutive steps degraded")
    sigma = drift_sigma_m(reports)
    if rules.max_drift_m > 0 and 3 * sigma > rules.max_drift_m:
        reasons.append(f"accumulated uncertainty {3 * sigma:.2f} m (3 sigma) exceeds {rules.max_drift_m:g} m")
    flagged = [{"frame": r.index, "verdict": r.verdict, "why": list(r.health)} for r in steps
               if r.verdict != "accepted"]
    return {**counts, "suspect": bool(reasons), "reasons": reasons, "flagged_steps": flagged,
            "drift_sigma_m": round(sigma, 4)}
