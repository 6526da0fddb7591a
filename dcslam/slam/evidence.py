"""Evidence about a SLAM run that does not come from its own depth: the trajectory of a companion run on the measured
pixels alone.

Completed depth that is wrong in a consistent way (a scale error, a smeared surface) defeats the per-step checks of
:mod:`dcslam.slam.health`: every step has thousands of pairs, a tight covariance and agrees with the motion
prediction, yet the trajectory ends metres off. The LiDAR's measured pixels behind that completion
(:func:`dcslam.io.drive.measured_kind`) give an odometry of their own whose errors are not those of the completion;
the main run must stay within that companion's trajectory plus the companion's own uncertainty.

:func:`judge` compares the two: the main run *departs* when it ends further from the companion than
``max(floor_m, sigmas * companion drift_sigma_m)``; the evidence is *unbounded* (and the run suspect: nothing
independent vouches for it) when the companion is itself suspect, unless the run's depth was measured (``dense``,
``exact``), which its own steps then judge, as they judge a sparse input; :func:`unavailable` records a run for which no
companion could be made (a layer that does not say what it was predicted from) or that was not asked for.
:func:`merge` folds the verdict into a health summary so that every reader of ``health.suspect`` and
``health.reasons`` follows. The SLAM stage hands :func:`judge` the companion's road-corrected trajectory
(:func:`dcslam.slam.road.road_corrected`) and judges the companion without its road rule: sparse LiDAR odometry's
largest error is vertical at 8 and 16 beams, and the road measures it (a companion that sank is a witness again
once corrected). Calibration: docs/slam.md, "Independent evidence for completed depth".
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Verdicts of :func:`judge` and :func:`unavailable`.
EVIDENCE_VERDICTS = ("agrees", "departs", "unbounded", "unavailable", "own", "off")


@dataclass(frozen=True)
class EvidenceRules:
    """Bound of the position gap between a run and its companion (calibration: docs/slam.md, "Independent evidence
    for completed depth").

    sigmas: the companion's accumulated uncertainty (:func:`dcslam.slam.health.drift_sigma_m`) times this bounds
        how far its own trajectory may be from the truth.
    floor_m: the smallest bound: two honest odometries on different depth differ by a few centimetres per metre
        driven whatever their covariances say, and a bound of centimetres would flag them. 0.48, 2 cm under the
        0.5 m the verdict asks about: a margin for a gap that scatters around the run's own error (what it caught
        and what it cost: docs/slam.md, "The prediction bound and a 0.48 m floor").
    """

    sigmas: float = 3.0
    floor_m: float = 0.48

    def bound_m(self, companion_sigma_m: float) -> float:
        return max(self.floor_m, self.sigmas * float(companion_sigma_m))


def position_gaps(T_main: np.ndarray, T_companion: np.ndarray) -> np.ndarray:
    """Distance (m) between the two trajectories' positions frame by frame, over the frames both have.
    Shape: T_main (N, 4, 4), T_companion (M, 4, 4) -> (min(N, M),). Both start from the same first pose."""
    n = min(len(T_main), len(T_companion))
    a = np.asarray(T_main, dtype=np.float64)[:n, :3, 3]
    b = np.asarray(T_companion, dtype=np.float64)[:n, :3, 3]
    return np.linalg.norm(a - b, axis=1)


def judge(T_main: np.ndarray, T_companion: np.ndarray, companion_health: dict, companion: str,
          rules: EvidenceRules = EvidenceRules(), road_corrected: bool = False, measured: bool = False) -> dict:
    """The evidence verdict of a run against its companion (``companion``: the measured depth kind it ran on;
    ``companion_health``: its :func:`dcslam.slam.health.summarise`; ``road_corrected``: ``T_companion`` is its
    road-corrected trajectory, said so in the reason; ``measured``: the run's depth was measured, not completed,
    e.g. ``dense`` or ``exact``).

    A suspect companion bounds nothing. A completion is then ``unbounded`` (suspect): its own steps do not see the
    errors of a completion that is wrong in a consistent way, which is why it has a companion. Measured depth is
    then judged by its own steps, the evidence a sparse input has (``own``, not suspect on this account): those
    steps' checks were calibrated on measured depth (docs/slam.md, "Independent evidence for completed depth").

    The gap that counts is the one at the last frame both have: the question, as for every figure of the health
    verdict, is how far the run *ends* from the truth (a gap beyond the bound that closes again is not counted; the
    largest gap is kept beside it).

    Returns ``{"verdict": "agrees" | "departs" | "unbounded" | "own", "companion": str, "road_corrected": bool,
    "suspect": bool, "reason": str | None, "gap_m": the last frame's gap, "gap_frame": the first frame from which
    the gap stays beyond the bound (the last frame when it ends within it), "max_gap_m": the largest gap,
    "max_gap_frame": its frame, "bound_m": the bound, "companion_sigma_m": s, "companion_reasons": [str]}``, and
    ``"note"`` with ``own``.
    """
    gaps = position_gaps(T_main, T_companion)
    sigma = float(companion_health.get("drift_sigma_m", 0.0))
    bound = rules.bound_m(sigma)
    gap = float(gaps[-1]) if len(gaps) else 0.0
    frame = max(len(gaps) - 1, 0)                      # where it ends within the bound: the last frame
    if gap > bound:                                    # beyond it: the frame after the last one within it
        within = np.flatnonzero(gaps <= bound)
        frame = int(within[-1]) + 1 if len(within) else 0
    largest = int(np.argmax(gaps)) if len(gaps) else 0
    name = f"the {companion} companion" + (" (road-corrected)" if road_corrected else "")
    record = {"companion": companion, "road_corrected": road_corrected, "gap_m": round(gap, 4), "gap_frame": frame,
              "max_gap_m": round(float(gaps[largest]) if len(gaps) else 0.0, 4), "max_gap_frame": largest,
              "bound_m": round(bound, 4), "companion_sigma_m": round(sigma, 4),
              "companion_reasons": [str(r) for r in companion_health.get("reasons", [])]}
    if companion_health.get("suspect"):
        if measured:   # the companion's reasons are in its record
            return {"verdict": "own", "suspect": False, **record, "reason": None,
                    "note": f"judged by its own steps, as measured depth: {name} is itself suspect"}
        why = "; ".join(record["companion_reasons"]) or "suspect"
        return {"verdict": "unbounded", "suspect": True, **record,
                "reason": f"no evidence bounds the drift ({name} is itself suspect: {why})"}
    if gap > bound:
        return {"verdict": "departs", "suspect": True, **record,
                "reason": f"ends {gap:.2f} m from {name}, past the bound from frame {frame} (bound {bound:.2f} m: "
                          f"{rules.sigmas:g} x its sigma {sigma:.3f} m, at least {rules.floor_m:g} m)"}
    return {"verdict": "agrees", "suspect": False, **record, "reason": None}


def unavailable(why: str, verdict: str = "unavailable") -> dict:
    """The record of a run with no companion: ``verdict`` ``unavailable`` (none could be made: ``why`` says so, and
    the summary says that no evidence bounds the drift), ``own`` (a sparse input: its run is its own evidence) or
    ``off`` (not asked for). Neither makes the run suspect."""
    if verdict not in ("unavailable", "own", "off"):
        raise ValueError(f"unknown verdict {verdict!r}")
    return {"verdict": verdict, "suspect": False, "companion": None,
            "reason": f"no evidence bounds the drift ({why})" if verdict == "unavailable" else None, "note": why}


def merge(health: dict, evidence: dict) -> dict:
    """``health`` (:func:`dcslam.slam.health.summarise`) with the evidence verdict folded in: ``evidence`` added,
    ``suspect`` set and its reason appended when the evidence makes the run suspect.

    A companion that agrees outweighs the run's own weak-step reasons (degraded steps, held steps, its drift bound: on
    completed depth they misjudge in both directions) when no step was rejected; those reasons move to
    ``overruled``. The road figure's reason stays (:func:`dcslam.slam.health.road_reason`): it measures the run's own
    vertical error from its depth, which the companion's agreement within its 0.5 m floor does not rule out."""
    from dcslam.slam.health import road_reason   # not at import: evidence is on the path of ``dcslam --help``

    merged = {**health, "reasons": list(health.get("reasons", [])), "evidence": evidence}
    if evidence.get("suspect"):
        merged["suspect"] = True
        merged["reasons"].append(evidence["reason"])
    elif evidence.get("verdict") == "agrees" and merged.get("suspect") and not health.get("rejected", 0):
        road = road_reason(merged["reasons"])
        overruled = [r for r in merged["reasons"] if r != road]
        merged["reasons"], merged["suspect"] = ([road] if road else []), bool(road)
        if overruled:
            merged["overruled"] = overruled
    return merged


def evidence_line(health: dict) -> str | None:
    """One line on the evidence for a printed summary (None when there is nothing to say: a sparse input, or
    evidence that agrees and is already counted as ``ok``)."""
    ev = health.get("evidence")
    if not ev:
        return None
    if ev["verdict"] == "agrees":
        corrected = " (road-corrected)" if ev.get("road_corrected") else ""
        return (f"ends within {ev['gap_m']:.2f} m of the {ev['companion']} companion{corrected} "
                f"(bound {ev['bound_m']:.2f} m)")
    if ev["verdict"] == "unavailable":
        return ev["reason"]
    if ev["verdict"] == "own" and ev.get("companion"):
        return ev["note"]
    if ev["verdict"] == "off":
        return "no evidence bounds the drift (--evidence none)"
    return None
