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
when its road figure (:func:`dcslam.slam.road.road_drift`: the road plane of each frame's depth, step by step) says
it sank or rose more than ``max_road_drift_m``, when the steps that left a translation direction degenerate rest on a
prediction that may have put it more than ``max_drift_m`` from the truth (:func:`prediction_bound`), or when the
steps held at the prediction may have (:func:`hold_bound`).

The drift bound is the degeneracy analysis of Zhang & Singh (ICRA 2016) carried along a run: each measured step's
point-to-plane information J^T W J says how well its pairs constrain each direction of motion (its smallest
eigenvalues and their directions) and its covariance s^2 (J^T W J)^-1 how far the step may be off along each. The
position covariance each step leaves at a frame (its translation, and its rotation times the road driven since) is
summed over the steps as *correlated* errors: standard deviations add along a direction, they do not add as a random
walk. Consecutive steps see the same structure through the same beams, so a direction the scan barely constrains
slips the same way step after step (every 8-beam drive of the calibration sinks: its pitch and height err with one
sign). The direction in which the bound is largest is the one the run left unconstrained.

The thresholds of :class:`HealthRules` are calibrated on generated street drives; the measurements behind each are
in docs/slam.md ("Health rules and their calibration", "Degeneracy and the drift bound").
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

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
    max_drift_m: a run whose drift bound (:func:`drift_bound`, ``drift_sigmas`` times its correlated standard
        deviation) exceeds this may end further than this from the truth, and is suspect (0: never) when some step
        left a translation direction degenerate (its weakest share below ``degenerate_share``; or, without the
        steps' information, always): where every direction was measured the bound overstates the drift (at 8
        beams it exceeded 0.5 m on every run, of runs ending 0.09-0.41 m off) and the road figure judges the
        vertical. The bound is absolute, as the question it answers ("may this trajectory be more than 0.5 m
        off?"): a longer drive accumulates more and is flagged sooner.
    max_road_drift_m: a run whose road figure (:func:`dcslam.slam.road.road_drift`) exceeds this is suspect
        (0: never, and no road is fitted). The figure estimates the run's vertical error (median 0.015-0.028 m
        from the truth on the calibration drives), so its threshold is ``max_drift_m``'s goal: 0.5 m. It needs a
        road below the camera; frames without one are skipped and counted.
    drift_sigmas: standard deviations of the drift bound. 2.5: on the calibration drives it flags every run that
        ends more than 0.5 m off (those only it flags have bounds of 0.90-0.96 m at 3 sigma) and 1 of 14 16-beam
        runs that end within 0.5 m (4 at 3 sigma, bounds 0.51-0.88 m); at 8 beams it flags every run, whatever
        sigmas (bounds of 0.70-1.07 m at 3 sigma on runs that end 0.09-0.41 m off): docs/slam.md.
    degenerate_share: a translation direction whose share of a step's information (:func:`step_degeneracy`) is
        below this is degenerate (Zhang & Singh): the pairs say next to nothing there, the pose along it is the
        prediction's, and so is its uncertainty. On the calibration drives no step of the 52 runs that end within
        0.5 m has a share below 0.030; the steps that erred 0.56-1.18 m along a weak direction had 0.011-0.019.
    prior_sigma_m: the constant-velocity prediction's standard deviation per step, used along a degenerate
        direction (a car changes its velocity by a few centimetres per frame at 10 Hz).
    first_prior_sigma_m: the same for the first ICP step, which has no velocity to predict from (a car moves
        0.5-1.5 m per frame).
    hold_acceleration_mps2: standard deviations of the vehicle's acceleration along the camera's x (across), y
        (vertical) and z (forward) axes, which a step held at the constant-velocity prediction
        (:attr:`StepReport.held`) does not see: the k-th step of a hold that follows a measured velocity is off by
        ``frame_interval_s`` squared times k times the acceleration along the held direction, so a hold of n steps
        may add 1 + 2 + ... + n of them (:func:`hold_bound`). (0.2, 0.2, 1.0) m/s^2: a car accelerates and brakes
        along its axis and barely changes its sideways or vertical velocity (the constant twist of the prediction
        carries its turns); the real KITTI drive in tests/data changes its forward speed by a median 0.81 and at
        most 1.77 m/s^2, its sideways speed by 0.04 (at most 0.39) and its vertical speed by 0.07 (at most 0.41)
        m/s^2 (OXTS vf, vl, vu), within 2.5 of these on every axis.
        A hold from the first step, before any step measured a velocity, is not modelled: its prediction (no
        motion) misses the vehicle's whole motion, and such steps erred in every direction their pairs coupled to
        the held one (half-size drive 7175 at 64 beams: 0.64-1.28 m a step), so they count as degraded.
    frame_interval_s: the time between frames when the run does not say (KITTI's 10 Hz).
    hold_bound: judge the steps held after a measured velocity by :func:`hold_bound` (off: count them as degraded,
        as before the bound; ``benchmarks/slam_rule_ablation.py`` compares the two). Rejected steps are counted
        either way (``max_rejected``): judging those after a measured velocity by the bound as well missed an 8-beam
        run 0.785 m off on a seed it was not chosen on, whose only symptom was 5 rejected steps (docs/slam.md).
    prediction_bound: judge a run whose steps left a direction degenerate by what the prediction may have cost
        along those directions alone (:func:`prediction_bound`: ``prior_sigma_m`` a step, ``first_prior_sigma_m`` at
        the first, correlated, ``drift_sigmas``), not by the whole drift bound (off: the whole bound counts once
        some step is degenerate, the previous rule). The whole bound overstates where the pairs measured: at 8
        beams it passes 0.5 m on every run, and one degenerate step among 29 made it count; over the 1,392 stored
        runs of eight workspaces it was the only reason of 5 runs, all ending within 0.5 m (docs/slam.md, "The
        prediction bound and a 0.48 m floor").
    degenerate_pairs: a translation direction is degenerate only when the pairs' information along it (the smallest
        eigenvalue of the translation block of J^T W J: the number of unit normals' worth of pairs facing it) is
        also below this, whatever its share: a dense frame's 2 % share is still tens of pairs. On seed 6262 (8
        full-size drives at 64, 16 and 8 beams, dense and exact depth; 1,087 steps) every step that erred more than
        0.3 m had at most 8.7, none of those above 10 erred that much (docs/slam.md).
    """

    min_pairs: int = 100
    min_conditioning: float = 2.5e-3
    max_prediction_gap_m: float = 0.5
    max_prediction_gap_deg: float = 3.0
    max_degraded_fraction: float = 0.1
    max_degraded_run: int = 1
    max_rejected: int = 0
    max_drift_m: float = 0.5
    max_road_drift_m: float = 0.5
    drift_sigmas: float = 2.5
    degenerate_share: float = 0.02
    prior_sigma_m: float = 0.05
    first_prior_sigma_m: float = 0.5
    hold_acceleration_mps2: tuple[float, float, float] = (0.2, 0.2, 1.0)
    frame_interval_s: float = 0.1
    degenerate_pairs: float = 20.0
    hold_bound: bool = True
    prediction_bound: bool = True


#: The start of the reason :func:`assess` gives a weakly constrained step.
WEAK = "weakly constrained"


def assess(accepted: bool, reason: str, inliers: int, sources: int, conditioning: float, gap_m: float,
           gap_deg: float, has_velocity: bool, rules: HealthRules = HealthRules(),
           held=None) -> tuple[str, list[str]]:
    """The verdict of one odometry step and the evidence behind it -> (verdict, reasons). ``held``: the directions
    the step held at the prediction (``OdometryResult.held``, (K, 6), or None), named in its weak reason."""
    if not accepted:
        return "rejected", [reason or "rejected by the odometry"]
    reasons = []
    if inliers < rules.min_pairs:
        reasons.append(f"{inliers} of {sources} points paired (fewer than {rules.min_pairs} pairs)")
    if not math.isnan(conditioning) and conditioning < rules.min_conditioning:
        names = held_names(held)
        reasons.append(f"{WEAK} (conditioning {conditioning:.1e})"
                       + (f", held at the prediction ({', '.join(names)})" if names else ""))
    if has_velocity and (gap_m > rules.max_prediction_gap_m or gap_deg > rules.max_prediction_gap_deg):
        reasons.append(f"{gap_m:.2f} m / {gap_deg:.1f} deg from the constant-velocity prediction")
    return ("degraded" if reasons else "accepted"), reasons


#: Names of the camera axes (x right, y down, z forward): a direction is named by the axis it is closest to, in the
#: camera frame of the step that contributes most to it.
AXIS_NAMES = ("across the road (camera x)", "vertical (camera y)", "along the road (camera z)")


def _numpy(tensor) -> np.ndarray:
    return tensor.detach().cpu().double().numpy() if hasattr(tensor, "detach") else np.asarray(tensor, np.float64)


def _held(report) -> np.ndarray | None:
    """The directions a step held at the prediction as twists (K, 6) (:attr:`StepReport.held`), None for none."""
    held = getattr(report, "held", None)
    if held is None:
        return None
    held = _numpy(held).reshape(-1, 6)
    return held if len(held) and np.isfinite(held).all() else None


def held_names(held) -> list[str]:
    """Names of held directions (K, 6): the camera axis of a direction that is mostly a translation (at least half
    of its unit length in the normalised coordinates, :meth:`~dcslam.slam.odometry.PointToPlane.held`), else the
    axis of its rotation."""
    if held is None:
        return []
    names = []
    for v in _numpy(held).reshape(-1, 6):
        t = v[:3]
        name = (axis_name(t) if float(np.linalg.norm(t)) >= 0.5
                else "rotation about " + axis_name(v[3:]).split(" (")[1].rstrip(")"))
        if name not in names:
            names.append(name)
    return names


def modelled_holds(reports, rules: HealthRules | None = None) -> dict[int, tuple[np.ndarray, int]]:
    """{frame: (its held directions (K, 6), k: its place in the hold, 1 for the first step)} of the steps the hold
    bound models: held (:attr:`StepReport.held`), not rejected, every held direction mostly a translation
    (:func:`_translational`), in a hold (consecutive held or rejected steps) that began after a step measured a
    velocity (any step since the first that held nothing and was not rejected). The other held steps are judged as
    before holds were modelled: degraded, with the pairs' covariance; every held step so when ``rules.hold_bound``
    is off."""
    out, k, measured, from_measured = {}, 0, False, False
    if rules is not None and not rules.hold_bound:
        return out
    for r in reports:
        if r.index == 0:
            continue
        held = _held(r) if r.verdict != "rejected" else None
        if held is None and r.verdict != "rejected":
            k, measured = 0, True
            continue
        k += 1
        if k == 1:
            from_measured = measured
        if held is not None and from_measured and _translational(held):
            out[r.index] = (held, k)
    return out


def held_only(report, holds: dict) -> bool:
    """Whether a degraded step's only weakness is a hold the bound models (``holds``: :func:`modelled_holds` of its
    run) and every reason is its weak conditioning. Its pose there is the prediction's and :func:`hold_bound` judges
    what that may cost; the run rules do not count it as degraded."""
    return (report.verdict == "degraded" and report.index in holds and bool(report.health)
            and all(str(w).startswith(WEAK) for w in report.health))


def axis_name(direction_cam) -> str:
    """The name of the camera axis closest to a direction (3,) in the camera frame, sign ignored."""
    return AXIS_NAMES[int(np.argmax(np.abs(np.asarray(direction_cam, dtype=np.float64))))]


def step_degeneracy(information) -> dict | None:
    """Zhang & Singh's degeneracy analysis of one step: the translation and rotation blocks of its point-to-plane
    information J^T W J (6, 6: twist (translation, rotation), camera frame), each divided by its trace so that the
    eigenvalues are shares in [0, 1/3 for the smallest] whatever the number of pairs (a translation block's share is
    that of the pairs' normal weight along the direction; 0 along a corridor's axis).

    Returns ``{"translation": share, "translation_direction": (3,) camera frame, "translation_pairs": the
    eigenvalue itself (unit normals' worth of pairs along that direction), "rotation": share, "rotation_axis": (3,)
    camera frame}`` of the smallest eigenvalue of each block, or None without an information.
    """
    if information is None:
        return None
    H = _numpy(information)
    if not np.isfinite(H).all():
        return None
    out = {}
    for key, axis_key, block in (("translation", "translation_direction", H[:3, :3]),
                                 ("rotation", "rotation_axis", H[3:, 3:])):
        trace = float(np.trace(block))
        values, vectors = np.linalg.eigh(block / trace) if trace > 0 else (np.zeros(3), np.eye(3))
        out[key], out[axis_key] = float(values[0]), vectors[:, 0]
        if key == "translation":
            out["translation_pairs"] = float(values[0]) * max(trace, 0.0)
    return out


def _step_covariance(report, rules: HealthRules, holds: dict) -> np.ndarray | None:
    """The step's (6, 6) twist covariance: its own, or (a report without one) its worst-direction standard
    deviations ``sigma_m`` and ``sigma_deg`` in every direction; None when the step was not measured. Along the
    directions the odometry held, where the hold bound models them (``holds``: :func:`modelled_holds`), the pose is
    the prediction's, not the pairs': the covariance is conditioned on no error there (:func:`hold_bound` carries
    what holding may cost). Along each
    other degenerate translation direction (:attr:`HealthRules.degenerate_share`) the prediction's variance is
    added: the pairs barely moved the pose there from the prediction."""
    if getattr(report, "covariance", None) is not None:
        C = _numpy(report.covariance).copy()
        if not np.isfinite(C).all():
            return None
    elif math.isnan(report.sigma_m) or math.isnan(report.sigma_deg):
        return None
    else:
        C = np.diag([report.sigma_m ** 2] * 3 + [math.radians(report.sigma_deg) ** 2] * 3)
    if report.index in holds:
        held = holds[report.index][0]
        CV = C @ held.T
        inner = held @ CV
        if np.linalg.cond(inner) < 1e12:
            C = C - CV @ np.linalg.solve(inner, CV.T)
        return C
    _add_prediction(C, report, rules)
    return C


def _add_prediction(C: np.ndarray, report, rules: HealthRules) -> bool:
    """Add to the (6, 6) twist covariance ``C``, in place, the constant-velocity prediction's variance along each
    translation direction the step left degenerate (:func:`degenerate_directions`; the first ICP step has no
    velocity, so ``first_prior_sigma_m`` there); whether there was one."""
    prior = rules.first_prior_sigma_m if report.index == 1 else rules.prior_sigma_m
    directions = degenerate_directions(report, rules)
    for v in directions:
        C[:3, :3] += prior ** 2 * np.outer(v, v)
    return bool(directions)


def degenerate_directions(report, rules: HealthRules) -> list[np.ndarray]:
    """The unit translation directions (3,: camera frame) a step's pairs leave degenerate: their share of the
    translation block of its information below ``degenerate_share`` and fewer than ``degenerate_pairs`` pairs' worth
    facing them (Zhang & Singh); none without a finite information."""
    information = getattr(report, "information", None)
    if information is None or not np.isfinite(_numpy(information)).all():
        return []
    block = _numpy(information)[:3, :3]
    trace = float(np.trace(block))
    values, vectors = np.linalg.eigh(block / trace) if trace > 0 else (np.zeros(3), np.eye(3))
    return [v for value, v in zip(values, vectors.T)
            if value < rules.degenerate_share and value * trace < rules.degenerate_pairs]


def _prediction_covariances(reports, rules: HealthRules, holds: dict) -> list[tuple]:
    """(report, (6, 6) twist covariance) of every measured step (not rejected, not held where the hold bound models
    it) that left a translation direction degenerate: the prediction's variance along those directions alone."""
    out = []
    for r in reports:
        if r.index == 0 or r.verdict == "rejected" or r.index in holds:
            continue
        C = np.zeros((6, 6))
        if _add_prediction(C, r, rules):
            out.append((r, C))
    return out


def _hold_covariances(reports, rules: HealthRules, interval_s: float, holds: dict) -> list[tuple]:
    """(report, (6, 6) twist covariance) of every held step the bound models (``holds``: :func:`modelled_holds`):
    the prediction's error along the directions it held. The k-th step of a hold is off by
    ``hold_acceleration_mps2 * interval_s ** 2 * k`` metres per camera axis: the velocity held since the hold began
    misses what the vehicle's acceleration changed."""
    acceleration = np.asarray(rules.hold_acceleration_mps2, dtype=np.float64) * interval_s ** 2
    out = []
    for r in reports:
        if r.index in holds:
            held, k = holds[r.index]
            C = np.zeros((6, 6))
            for v in held:
                C += _along(v, acceleration * k) ** 2 * np.outer(v, v)
            out.append((r, C))
    return out


def _along(v: np.ndarray, translation: np.ndarray) -> float:
    """The standard deviation (metres) along a held direction ``v`` (a twist moving the sources one metre along it,
    mostly a translation: :func:`_translational`) of a prediction error with independent standard deviations
    ``translation`` (3,: metres along camera x, y, z): the translation part of the unit direction weighs the axes."""
    return float(np.linalg.norm(v[:3] * translation))


def _translational(held: np.ndarray) -> bool:
    """Whether every held direction (K, 6) is mostly a translation (at least half of its unit length in the
    normalised coordinates of :meth:`~dcslam.slam.odometry.PointToPlane.held`): what the hold bound models."""
    return bool((np.linalg.norm(held[:, :3], axis=1) >= 0.5).all())


def _directions(n: int = 400) -> np.ndarray:
    """``n`` unit directions spread evenly over a hemisphere (a Fibonacci lattice; u and -u bound alike).
    Shape: (n, 3)."""
    i = np.arange(n) + 0.5
    polar, azimuth = np.arccos(1 - i / n), math.pi * (1 + 5 ** 0.5) * i
    return np.stack([np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar), np.cos(polar)], 1)


def _position_covariances(A: np.ndarray, X: np.ndarray, B: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Covariance of a position error ``a - [d]x b`` (= a + b x d): ``a`` a translation error (covariance A), ``b`` a
    rotation error (B; cross-covariance X = cov(a, b)), ``d`` the lever from the rotation's centre.
    Shapes: A, X, B (S, 3, 3); d (S, 3) -> (S, 3, 3)."""
    D = np.zeros(d.shape[:-1] + (3, 3))
    D[..., 0, 1], D[..., 0, 2], D[..., 1, 2] = -d[..., 2], d[..., 1], -d[..., 0]
    D[..., 1, 0], D[..., 2, 0], D[..., 2, 1] = d[..., 2], -d[..., 1], d[..., 0]
    XD = X @ D.swapaxes(-1, -2)
    return A - XD - XD.swapaxes(-1, -2) + D @ B @ D.swapaxes(-1, -2)


def _correlated_std(P: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Per-step standard deviations along unit directions. Shapes: P (S, 3, 3), u (K, 3) -> (S, K)."""
    return np.sqrt(np.maximum(np.einsum("ki,sij,kj->sk", u, P, u), 0.0))


def _worst_direction(P: np.ndarray) -> np.ndarray:
    """The unit direction u maximising sum_i sqrt(u^T P_i u): the best of a lattice of directions, then the ascent
    u <- grad / |grad|, which never lowers a convex, positively homogeneous function such as this one. (3,)"""
    U = _directions()
    u = U[int(np.argmax(_correlated_std(P, U).sum(0)))]
    for _ in range(50):
        std = _correlated_std(P, u[None])[:, 0]
        kept = std > 0
        grad = (np.einsum("sij,j->si", P[kept], u) / std[kept, None]).sum(0)
        norm = float(np.linalg.norm(grad))
        if norm == 0 or np.allclose(grad / norm, u, atol=1e-10):
            break
        u = grad / norm
    return u


def drift_bound(reports, rules: HealthRules | None = None) -> dict:
    """How far the run's last position may be from the truth, and in which direction: ``rules.drift_sigmas`` times
    the sum over the measured steps of each step's standard deviation along a direction (the steps' errors taken as
    correlated: see the module's docstring), maximised over directions (``rules`` None: :class:`HealthRules`).

    A step i with twist covariance C (camera frame, :meth:`~dcslam.slam.odometry.PointToPlane.covariance`) moves a
    later frame k by ``R_i dt + (R_i dw) x (p_k - p_i)``: its translation, and its rotation about its own position
    times the road from there; along a direction the step leaves degenerate, the prediction's uncertainty
    (:attr:`HealthRules.degenerate_share`); along a direction it held, nothing (:func:`hold_bound`). Rejected
    steps and steps without a covariance add nothing (they are flagged on their own).

    Returns ``{"bound_m": b, "sigmas": rules.drift_sigmas, "direction_world": [3], "direction": a name of
    :data:`AXIS_NAMES`, "from_frame": None, "largest_frame": the step that adds most, "weakest_frame": the step
    with the smallest translation share (:func:`step_degeneracy`) of those it did not hold, "weakest_share": that
    share, "weakest_direction": its name}``; :func:`summarise` fills in ``from_frame`` (the first frame whose own
    bound along that direction exceeds ``max_drift_m``) when the bound exceeds it.
    """
    return _drift(reports, HealthRules() if rules is None else rules)[0]


def hold_bound(reports, rules: HealthRules | None = None, interval_s: float | None = None) -> dict:
    """How far the steps held at the constant-velocity prediction may have put the run's last position, and in
    which direction: ``rules.drift_sigmas`` times the correlated sum (as :func:`drift_bound`) of the prediction
    error along the directions each modelled held step held (:func:`modelled_holds`, :func:`_hold_covariances`: the
    vehicle's acceleration over the hold, ``interval_s`` seconds a frame; None: ``rules.frame_interval_s``).

    Returns ``{"bound_m": b, "sigmas": ..., "direction_world": [3] or None, "direction": a name or None,
    "from_frame": None, "largest_frame": ..., "steps": held steps, "frames": their frames, "held": the held
    directions' names, "acceleration_mps2": ..., "interval_s": ...}``; :func:`summarise` fills in ``from_frame``
    when the bound exceeds ``max_drift_m``."""
    return _hold(reports, HealthRules() if rules is None else rules, interval_s)[0]


def prediction_bound(reports, rules: HealthRules | None = None) -> dict:
    """How far the constant-velocity prediction may have put the run's last position along the directions its steps
    left degenerate (:func:`degenerate_directions`: there the pose is the prediction's, whatever the pairs'
    covariance says), and in which direction: ``rules.drift_sigmas`` times the correlated sum (as
    :func:`drift_bound`) of ``prior_sigma_m`` a step along each such direction (``first_prior_sigma_m`` at the first
    step, which has no velocity to predict from). Steps held where the hold bound models them are its, not this.

    Returns ``{"bound_m", "sigmas", "direction_world", "direction", "from_frame": None, "largest_frame", "frames":
    the steps counted, "prior_sigma_m", "first_prior_sigma_m"}``; :func:`summarise` fills in ``from_frame`` when the
    bound exceeds ``max_drift_m``."""
    return _prediction(reports, HealthRules() if rules is None else rules)[0]


def _prediction(reports, rules: HealthRules) -> tuple[dict, tuple | None]:
    """:func:`prediction_bound`, and its curve for :func:`_first_frame_over`."""
    steps = _prediction_covariances(reports, rules, modelled_holds(reports, rules))
    result, curve = _accumulate(reports, steps, rules.drift_sigmas)
    result.update(frames=[int(r.index) for r, _ in steps], prior_sigma_m=rules.prior_sigma_m,
                  first_prior_sigma_m=rules.first_prior_sigma_m)
    return result, curve


def _accumulate(reports, measured: list[tuple], sigmas: float) -> tuple[dict, tuple | None]:
    """The correlated bound of :func:`drift_bound` over ``measured``, ``[(report, twist covariance (6, 6))]``:
    ``({"bound_m", "sigmas", "direction_world", "direction", "from_frame": None, "largest_frame"}``, what
    :func:`_first_frame_over` needs to follow it frame by frame, None when ``measured`` is empty)."""
    empty = {"bound_m": 0.0, "sigmas": sigmas, "direction_world": None, "direction": None, "from_frame": None,
             "largest_frame": None}
    if not measured:
        return empty, None
    positions = np.stack([_numpy(r.T_world_cam)[:3, 3] for r in reports])
    index = {r.index: k for k, r in enumerate(reports)}
    R = np.stack([_numpy(r.T_world_cam)[:3, :3] for r, _ in measured])
    C = np.stack([C for _, C in measured])
    A = R @ C[:, :3, :3] @ R.transpose(0, 2, 1)
    X = R @ C[:, :3, 3:] @ R.transpose(0, 2, 1)
    B = R @ C[:, 3:, 3:] @ R.transpose(0, 2, 1)
    at = np.array([index[r.index] for r, _ in measured])
    P = _position_covariances(A, X, B, positions[-1][None, :] - positions[at])
    u = _worst_direction(P)
    std = _correlated_std(P, u[None])[:, 0]
    largest = int(np.argmax(std))
    result = {**empty, "bound_m": float(sigmas * std.sum()), "direction_world": [float(x) for x in u],
              "direction": axis_name(R[largest].T @ u), "largest_frame": int(measured[largest][0].index)}
    return result, (u, A, X, B, at, positions)


def _drift(reports, rules: HealthRules) -> tuple[dict, tuple | None]:
    """:func:`drift_bound`, and what :func:`_first_frame_over` needs to follow the bound frame by frame (None when
    no step was measured)."""
    holds = modelled_holds(reports, rules)
    steps = [r for r in reports if r.index > 0 and r.verdict != "rejected"]
    measured = [(r, C) for r, C in ((r, _step_covariance(r, rules, holds)) for r in steps) if C is not None]
    result, curve = _accumulate(reports, measured, rules.drift_sigmas)
    result.update(weakest_frame=None, weakest_share=None, weakest_pairs=None, weakest_direction=None,
                  degenerate_frames=[])
    shares = [(r.index, d) for r, d in ((r, step_degeneracy(getattr(r, "information", None))) for r, _ in measured
                                        if r.index not in holds) if d is not None]
    if shares:
        frame, d = min(shares, key=lambda fd: fd[1]["translation"])
        result.update(weakest_frame=int(frame), weakest_share=round(d["translation"], 5),
                      weakest_pairs=round(d["translation_pairs"], 2),
                      weakest_direction=axis_name(d["translation_direction"]),
                      degenerate_frames=[int(f) for f, d in shares if d["translation"] < rules.degenerate_share
                                         and d["translation_pairs"] < rules.degenerate_pairs])
    return result, curve


def _hold(reports, rules: HealthRules, interval_s: float | None) -> tuple[dict, tuple | None]:
    """:func:`hold_bound`, and its curve for :func:`_first_frame_over`."""
    interval = rules.frame_interval_s if interval_s is None else float(interval_s)
    held = _hold_covariances(reports, rules, interval, modelled_holds(reports, rules))
    result, curve = _accumulate(reports, held, rules.drift_sigmas)
    names = []
    for r, _ in held:
        names += [n for n in held_names(r.held) if n not in names]
    result.update(steps=len(held), frames=[int(r.index) for r, _ in held], held=names,
                  acceleration_mps2=list(rules.hold_acceleration_mps2), interval_s=round(interval, 6))
    return result, curve


def _first_frame_over(curve, sigmas: float, over_m: float, reports) -> int | None:
    """The first frame whose own bound (:func:`_accumulate`) along the run's worst direction exceeds ``over_m``."""
    u, A, X, B, at, positions = curve
    for k in range(len(positions)):
        mine = at <= k
        if not mine.any():
            continue
        P = _position_covariances(A[mine], X[mine], B[mine], positions[k][None, :] - positions[at[mine]])
        if sigmas * float(_correlated_std(P, u[None]).sum()) > over_m:
            return int(reports[k].index)
    return None


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


def summarise(reports, rules: HealthRules = HealthRules(), interval_s: float | None = None) -> dict:
    """Counts of verdicts over a run's step reports (objects with ``index``, ``verdict`` and ``health``; the first
    frame, which has nothing to align to, is not counted) and whether the trajectory is suspect, with why.
    ``interval_s``: the time between frames (None: ``rules.frame_interval_s``), for :func:`hold_bound`.

    A degraded step whose only weakness is a hold the bound models (:func:`held_only`: after a measured velocity) is
    not counted by the degraded-step rules: the hold bound judges what holding may cost.

    Returns ``{"accepted": n, "degraded": n, "rejected": n, "held": n (of the degraded: held only), "suspect":
    bool, "reasons": [str], "flagged_steps": [{"frame": i, "verdict": v, "why": [str], "held": [names]}],
    "drift_sigma_m": s (:func:`drift_sigma_m`), "drift": :func:`drift_bound` with ``counted`` (whether it took part
    in the verdict), "prediction": :func:`prediction_bound` (None with ``prediction_bound`` off), "hold":
    :func:`hold_bound`, "road": :func:`dcslam.slam.road.road_drift` of the reports' ``road`` planes (None when
    ``max_road_drift_m`` is 0)}``.
    """
    steps = [r for r in reports if r.index > 0]
    counts = {v: sum(r.verdict == v for r in steps) for v in VERDICTS}
    holds = modelled_holds(reports, rules)
    held = {r.index for r in steps if held_only(r, holds)}
    weak = [r for r in steps if r.verdict == "degraded" and r.index not in held]
    reasons = []
    if counts["rejected"] > rules.max_rejected:
        reasons.append(f"{counts['rejected']} of {len(steps)} steps rejected (pose predicted, not measured)")
    if steps and len(weak) > rules.max_degraded_fraction * len(steps):
        reasons.append(f"{len(weak)} of {len(steps)} steps degraded "
                       f"(more than {rules.max_degraded_fraction:.0%})" + (f"; {len(held)} more held" if held else ""))
    run = longest = 0
    for r in steps:
        run = run + 1 if r.verdict == "degraded" and r.index not in held else 0
        longest = max(longest, run)
    if longest > rules.max_degraded_run:
        reasons.append(f"{longest} consecutive steps degraded")
    road = _road(reports, rules, reasons)
    drift = _drift_verdict(reports, rules, reasons)
    prediction = _prediction_verdict(reports, rules, reasons)
    hold = _hold_verdict(reports, rules, interval_s, reasons)
    flagged = [{"frame": r.index, "verdict": r.verdict, "why": list(r.health), "held": held_names(_held(r))}
               for r in steps if r.verdict != "accepted"]
    return {**counts, "held": len(held), "suspect": bool(reasons), "reasons": reasons, "flagged_steps": flagged,
            "drift_sigma_m": round(drift_sigma_m(reports), 4), "drift": drift, "prediction": prediction, "hold": hold,
            "road": road}


def _past(bound: dict, curve, rules: HealthRules, reports) -> bool:
    """Whether a bound (:func:`_accumulate`'s) exceeds ``max_drift_m`` (above 0); if so its ``from_frame`` is filled
    in (:func:`_first_frame_over`). Its ``bound_m`` is rounded for the summary either way."""
    past = rules.max_drift_m > 0 and bound["bound_m"] > rules.max_drift_m
    if past:
        bound["from_frame"] = _first_frame_over(curve, rules.drift_sigmas, rules.max_drift_m, reports)
    bound["bound_m"] = round(bound["bound_m"], 4)
    return past


def _drift_verdict(reports, rules: HealthRules, reasons: list[str]) -> dict:
    """The drift bound of :func:`summarise`; counted (and, past ``max_drift_m``, a reason appended to ``reasons``)
    when no step's information says which directions were measured, or, with ``prediction_bound`` off, when some
    step that the odometry did not hold left a translation direction degenerate."""
    drift, curve = _drift(reports, rules)
    informed = any(getattr(r, "information", None) is not None for r in reports if r.index > 0)
    degenerate = bool(drift["degenerate_frames"]) and not rules.prediction_bound
    drift["counted"] = bool(rules.max_drift_m > 0 and (degenerate or not informed))
    if _past(drift, curve, rules, reports) and drift["counted"]:
        reasons.append(f"accumulated uncertainty {drift['bound_m']:.2f} m ({rules.drift_sigmas:g} sigma, steps "
                       f"correlated) exceeds {rules.max_drift_m:g} m: {drift['direction']} left unconstrained, "
                       f"past {rules.max_drift_m:g} m from frame {drift['from_frame']} (most from step "
                       f"{drift['largest_frame']})")
    return drift


def _prediction_verdict(reports, rules: HealthRules, reasons: list[str]) -> dict | None:
    """The prediction bound of :func:`summarise` (None with ``prediction_bound`` off): past ``max_drift_m`` (above
    0), a reason appended to ``reasons``."""
    if not rules.prediction_bound:
        return None
    prediction, curve = _prediction(reports, rules)
    if _past(prediction, curve, rules, reports):
        frames = prediction["frames"]
        reasons.append(f"{len(frames)} steps left a direction degenerate (frames {_frame_list(frames)}): the "
                       f"prediction there may have put it {prediction['bound_m']:.2f} m off ({rules.drift_sigmas:g} "
                       f"sigma of {rules.prior_sigma_m:g} m a step, {rules.first_prior_sigma_m:g} m at the first), "
                       f"more than {rules.max_drift_m:g} m: {prediction['direction']} left unconstrained, past "
                       f"{rules.max_drift_m:g} m from frame {prediction['from_frame']}")
    return prediction


def _frame_list(frames: list[int]) -> str:
    """``[1, 2, 3, 7]`` -> ``1-3, 7``."""
    runs, start = [], None
    for k, f in enumerate(frames):
        if start is None:
            start = f
        if k + 1 == len(frames) or frames[k + 1] != f + 1:
            runs.append(str(start) if start == f else f"{start}-{f}")
            start = None
    return ", ".join(runs)


def _hold_verdict(reports, rules: HealthRules, interval_s: float | None, reasons: list[str]) -> dict:
    """The hold bound of :func:`summarise`: past ``max_drift_m`` (above 0), a reason appended to ``reasons``."""
    hold, curve = _hold(reports, rules, interval_s)
    if _past(hold, curve, rules, reports):
        frames = hold["frames"]
        reasons.append(f"{hold['steps']} steps held at the constant-velocity prediction (frames {frames[0]}-"
                       f"{frames[-1]}): they may have put it {hold['bound_m']:.2f} m off ({rules.drift_sigmas:g} "
                       f"sigma of the vehicle's acceleration over the hold), more than {rules.max_drift_m:g} m: "
                       f"{hold['direction']} held, past {rules.max_drift_m:g} m from frame {hold['from_frame']}")
    return hold


#: How the reason of the road figure (:func:`_road`) begins: the one reason of a summary that measures the run's own
#: error instead of describing its steps (:func:`road_reason`).
ROAD_REASON = "the road says the run"


def road_reason(reasons) -> str | None:
    """The reason among ``reasons`` (a summary's) that the road figure gave, or None."""
    return next((r for r in reasons if r.startswith(ROAD_REASON)), None)


def _road(reports, rules: HealthRules, reasons: list[str]) -> dict | None:
    """The road figure of :func:`summarise` (None when ``max_road_drift_m`` is 0 or there are no reports), a
    reason appended to ``reasons`` when it exceeds ``max_road_drift_m``."""
    if rules.max_road_drift_m <= 0 or not reports:
        return None
    from dcslam.slam.road import road_drift

    T = np.stack([_numpy(r.T_world_cam) for r in reports])
    road = road_drift(T, [getattr(r, "road", None) for r in reports], rules.max_road_drift_m)
    if road["from_frame"] is not None:
        road["from_frame"] = int(reports[road["from_frame"]].index)
    if road["drift_m"] > rules.max_road_drift_m:
        reasons.append(f"{ROAD_REASON} {road['vertical']} {road['drift_m']:.2f} m (vertical, camera y), "
                       f"past {rules.max_road_drift_m:g} m from frame {road['from_frame']} (road seen in "
                       f"{road['frames_seen']} of {len(reports)} frames)")
    return road
