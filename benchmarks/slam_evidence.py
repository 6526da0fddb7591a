"""Calibrate the evidence rule (dcslam.slam.evidence) and the pair count of the health rules from the SLAM outputs of
a workspace, post hoc: every run of ``slam/<layer>/<drive>.{json,txt}`` is judged against the run of its measured
depth kind (``slam/<kind>/<drive>``, the companion that ``dcslam slam --evidence auto`` would run beside it), with
the truth being whether it ends (final translation error) more than ``--truth`` metres off.

Prints, per input and beam count, runs / ending > truth / flagged of those / flagged of the others, for the stored
verdicts (``stored``: the health in each JSON as written) and for the candidate rules (``--floors``, ``--sigmas``,
``--min-pairs``, ``--drift-sigmas``: each run judged against the stored run of its companion as run; with
``--rejudge`` against the companion run again and road-corrected, summarised under this checkout's health rules);
``--stored-floors`` the stored verdicts with the evidence floor lowered (by the stored gaps: nothing is run again)
and how far the completions' errors lie from their gaps near ``--truth``; ``--json`` also writes the per-run rows,
``--flags`` prints every false flag and miss of the stored verdicts with
its reasons, ``--weak-steps`` what the flagged steps of each sparse, dense and exact run were (held on a measured
velocity, held from step 1, or a jump or rejection), ``--drives 1000-1003`` keeps those drives only (a half of the
test set), ``--group`` prints the stored verdicts once more with the inputs grouped by kind (sparse, dense, exact,
classical completers, networks; each with measured sources apart). ``--rejudge`` judges every completion under the
evidence rule of this checkout rather than as stored, and the candidates with it: each companion (the sparse run of
a drive's measured kind, with the settings of the runs it judges) is run again, one at a time, and
:func:`dcslam.slam.drive.companion_verdict` judges the stored trajectory against it (a minute or two for a
workspace's companions; the completions are not re-run). A rerun companion that does not reproduce the stored sparse
run is named with its difference and the script exits 1 (MKL's summation order: a workspace made under
``MKL_CBWR=AUTO`` needs it set again).

    python benchmarks/slam_evidence.py /tmp/repro-ws-b --floors 0.2,0.3,0.4 --sigmas 3 --min-pairs 250,150
    python benchmarks/slam_evidence.py /tmp/calib-ws --flags --drives 1000-1003
    python benchmarks/slam_evidence.py /tmp/study-ws --group
    python benchmarks/slam_evidence.py /tmp/study-ws --group --rejudge
    python benchmarks/slam_evidence.py /tmp/calib-ws --stored-floors 0.49,0.48,0.45
"""
from __future__ import annotations

import argparse
import functools
import itertools
import json
import re
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

from dcslam.slam.evidence import EvidenceRules, judge, merge
from dcslam.slam.health import WEAK, HealthRules

PAIRS = re.compile(r"^(\d+) of \d+ points paired")


def layer_input(layer: str) -> tuple[str, str]:
    """(input, beams) of a layer's name: ``sparse@16`` -> (sparse, 16); ``nconv-sparse8+masked`` ->
    (nconv+masked, 8); ``sparse`` -> (sparse, 64); ``dense`` -> (dense, -)."""
    if layer in ("dense", "exact"):
        return layer, "-"
    if layer == "sparse":
        return "sparse", "64"
    if layer.startswith("sparse@"):
        return "sparse", layer.split("@", 1)[1]
    m = re.match(r"^(.*)-sparse(\d*)(\+.*)?$", layer)
    if m:
        return m.group(1) + (m.group(3) or ""), m.group(2) or "64"
    return layer, "?"


@functools.lru_cache(maxsize=None)
def _measured(source: str) -> str | None:
    from dcslam.io.drive import is_depth_kind, measured_kind

    return measured_kind(source if is_depth_kind(source) else Path(source))


def measured_depth(record: dict) -> bool:
    """Whether a run's depth input was measured (``dense``, ``exact``: a drive depth kind), not completed, as
    ``dcslam slam`` tells them apart when the companion is suspect."""
    from dcslam.io.drive import is_depth_kind

    source = str(record.get("settings", {}).get("source", ""))
    return is_depth_kind(source)


def companion_layer(layer: str, record: dict) -> str | None:
    """The layer folder of the run's measured depth kind (None: a sparse input, its own evidence)."""
    from dcslam.io.drive import is_depth_kind

    if layer == "sparse" or layer.startswith("sparse@"):
        return None
    source = record.get("settings", {}).get("source")
    kind = _measured(source) if source and (is_depth_kind(source) or Path(source).is_file()) else None
    if kind is None:  # a moved workspace: the beams from the layer's name
        _, beams = layer_input(layer)
        kind = "sparse" if beams in ("64", "-") else f"sparse@{beams}"
    return kind


def rejudge(health: dict, rules: HealthRules) -> dict:
    """The stored run verdict re-decided with ``rules.min_pairs`` at or below the one it was judged with: a step
    degraded only for its pair count becomes accepted when it has at least ``min_pairs`` pairs (its other checks
    passed); a step only weak where it was held (:func:`modelled_frames`) is not counted as degraded; the run-level
    rules of :func:`dcslam.slam.health.summarise` then apply as written, the road figure, the drift bound (where it
    counted), the prediction bound and the hold bound as stored. ``health`` without its evidence
    (:func:`own_health`)."""
    verdicts = {}
    modelled = modelled_frames(health)
    for step in health.get("flagged_steps", []):
        verdict = step["verdict"]
        if verdict == "degraded":
            why = list(step["why"])
            left = [w for w in why if not (PAIRS.match(w) and int(PAIRS.match(w).group(1)) >= rules.min_pairs)]
            verdict = "degraded" if left else "accepted"
            if left and step["frame"] in modelled and all(w.startswith(WEAK) for w in left):
                verdict = "held"                           # judged by the hold bound, not counted as degraded
        verdicts[step["frame"]] = verdict
    steps = health["accepted"] + health["degraded"] + health["rejected"]
    rejected = sum(v == "rejected" for v in verdicts.values())
    degraded = sum(v == "degraded" for v in verdicts.values())
    held = sum(v == "held" for v in verdicts.values())
    reasons = []
    if rejected > rules.max_rejected:
        reasons.append(f"{rejected} of {steps} steps rejected")
    if steps and degraded > rules.max_degraded_fraction * steps:
        reasons.append(f"{degraded} of {steps} steps degraded")
    run = longest = 0
    for frame in range(1, steps + 1):
        run = run + 1 if verdicts.get(frame) == "degraded" else 0
        longest = max(longest, run)
    if longest > rules.max_degraded_run:
        reasons.append(f"{longest} consecutive steps degraded")
    road = health.get("road")                              # the road figure as written
    if road and rules.max_road_drift_m > 0 and float(road["drift_m"]) > rules.max_road_drift_m:
        reasons.append(f"the road says the run {road['vertical']} {float(road['drift_m']):.2f} m")
    # the drift bound as written (dcslam.slam.health.drift_bound), where it counted (a degenerate step); a summary
    # from before it has the random walk's sigma
    drift = health.get("drift")
    bound = (float(drift["bound_m"]) * rules.drift_sigmas / float(drift["sigmas"]) if drift
             else rules.drift_sigmas * float(health.get("drift_sigma_m", 0.0)))
    if rules.max_drift_m > 0 and bound > rules.max_drift_m and (drift or {}).get("counted", True):
        reasons.append(f"accumulated uncertainty {bound:.2f} m ({rules.drift_sigmas:g} sigma)")
    # the prediction and hold bounds as written (none in a summary from before each existed), rescaled to the sigmas
    for key, what in (("prediction", "steps left a direction degenerate: the prediction there"),
                      ("hold", "steps held at the constant-velocity prediction:")):
        stored = health.get(key)
        if stored and rules.max_drift_m > 0:
            rescaled = float(stored["bound_m"]) * rules.drift_sigmas / float(stored["sigmas"])
            if rescaled > rules.max_drift_m:
                count = len(stored["frames"]) if key == "prediction" else stored["steps"]
                reasons.append(f"{count} {what} {rescaled:.2f} m ({rules.drift_sigmas:g} sigma)")
    return {**health, "accepted": steps - rejected - degraded - held, "degraded": degraded + held, "held": held,
            "rejected": rejected,
            "suspect": bool(reasons), "reasons": reasons}


def modelled_frames(health: dict) -> set[int]:
    """The frames of a stored run whose holds the hold bound models (:func:`dcslam.slam.health.modelled_holds`, read
    from the flagged steps: held, none of the held directions a rotation, in a hold that began after a step that
    held nothing and was not rejected; a step missing from the flagged ones was accepted)."""
    flagged = {s["frame"]: s for s in health.get("flagged_steps", [])}
    steps = health["accepted"] + health["degraded"] + health["rejected"]
    out, k, measured, from_measured = set(), 0, False, False
    for frame in range(1, steps + 1):
        step = flagged.get(frame, {"verdict": "accepted"})
        held = step.get("held") or [] if step["verdict"] != "rejected" else []
        if not held and step["verdict"] != "rejected":
            k, measured = 0, True
            continue
        k += 1
        if k == 1:
            from_measured = measured
        if held and from_measured and not any(h.startswith("rotation") for h in held):
            out.add(frame)
    return out


def own_health(health: dict) -> dict:
    """A stored run's health without its evidence verdict (the reasons its own steps gave, those a companion that
    agreed overruled included): what :func:`dcslam.slam.evidence.merge` started from."""
    evidence = health.get("evidence") or {}
    reasons = list(health.get("overruled", [])) + [r for r in health["reasons"] if r != evidence.get("reason")]
    own = {k: v for k, v in health.items() if k not in ("evidence", "overruled")}
    return {**own, "reasons": reasons, "suspect": bool(reasons)}


class Companions:
    """The companion runs of a workspace, run again on demand (one per measured kind, drive and SLAM settings) so
    that stored completions can be judged under this checkout's evidence rule."""

    def __init__(self, workspace: Path, runs: dict):
        self.workspace, self.runs, self.made, self.differences = workspace, runs, {}, {}

    def run(self, kind: str, drive: str, record: dict):
        from dcslam.slam.config import SlamSettings, build_slam
        from dcslam.stages.slam import run_drive_file

        fields = SlamSettings.__dataclass_fields__
        settings = SlamSettings(**{k: v for k, v in record.get("settings", {}).items() if k in fields})
        key = (kind, drive, repr(settings), record["frames"])
        if key not in self.made:
            run = run_drive_file(self.workspace / "drives" / f"{drive}.h5", kind, build_slam(settings),
                                 record["frames"], description=f"{drive} companion {kind}")
            stored = self.runs.get((kind, drive))
            if stored is not None and len(stored["T"]) == len(run.T_world_cam):
                self.differences[(kind, drive)] = float(np.abs(stored["T"] - run.T_world_cam).max())
            self.made[key] = run
        return self.made[key]


def load_runs(slam_dir: Path) -> dict[tuple[str, str], dict]:
    """{(layer, drive): {"record": summary JSON, "T": (N, 4, 4) trajectory}} of every run under ``slam_dir``."""
    from dcslam.io.tum import read_tum

    runs = {}
    for summary in sorted(slam_dir.glob("*/*.json")):
        trajectory = summary.with_suffix(".txt")
        if not trajectory.exists():
            continue
        record = json.loads(summary.read_text())
        _, T = read_tum(trajectory)
        runs[(summary.parent.name, summary.stem)] = {"record": record, "T": T}
    return runs


def verdicts(runs: dict, rules: HealthRules | None, evidence: EvidenceRules | None,
             companions: Companions | None = None) -> list[dict]:
    """One row per run: input, beams, drive, final error, flagged (and why). ``rules`` None: the stored health;
    ``evidence`` None: no companion; ``companions``: each completion judged against its companion run again
    (:func:`dcslam.slam.drive.companion_verdict`, this checkout's rule) instead of as stored."""
    rows = []
    for (layer, drive), run in sorted(runs.items()):
        record = run["record"]
        verdict = None
        kind = companion_layer(layer, record)
        own = own_health(record["health"])
        health = record["health"] if rules is None else rejudge(own, rules)
        if companions is not None and kind is not None:
            from types import SimpleNamespace

            from dcslam.slam.drive import companion_verdict

            companion = companions.run(kind, drive, record)
            health = merge(own if rules is None else health,
                           companion_verdict(SimpleNamespace(T_world_cam=run["T"]), companion, kind, evidence,
                                             measured=measured_depth(record)))
        elif evidence is not None and kind is not None:
            companion = runs.get((kind, drive))
            if companion is None:
                verdict = "no companion run"
            else:
                c_health = (companion["record"]["health"] if rules is None
                            else rejudge(companion["record"]["health"], rules))
                health = merge(health, judge(run["T"], companion["T"], c_health, kind, evidence,
                                             measured=measured_depth(record)))
                verdict = health["evidence"]["verdict"]
        source, beams = layer_input(layer)
        stored = health.get("evidence") or {}
        rows.append({"input": source, "beams": beams, "layer": layer, "drive": drive,
                     "final_m": float(record["translation_error_m"]["final"]),
                     "max_m": float(record["translation_error_m"]["max"]), "flagged": bool(health["suspect"]),
                     "evidence": verdict or stored.get("verdict"), "gap_m": stored.get("gap_m"),
                     "companion_sigma_m": stored.get("companion_sigma_m"),
                     "reasons": list(health["reasons"]), "overruled": list(health.get("overruled", [])),
                     "road_m": (health.get("road") or {}).get("drift_m"),
                     "bound_m": (health.get("drift") or {}).get("bound_m"),
                     "weakest_share": (health.get("drift") or {}).get("weakest_share")})
    return rows


def moved_floor(rows: list[dict], floor: float, sigmas: float = EvidenceRules().sigmas) -> list[dict]:
    """``rows`` (the stored verdicts) with the evidence floor lowered to ``floor``: a completion that agrees with its
    companion as stored departs, and is flagged, when its stored gap exceeds ``max(floor, sigmas x the companion's
    sigma)``. Nothing is run again: the gap is the one ``dcslam slam`` measured (a floor above the stored one would
    need the reasons a departure hid, so it is refused)."""
    moved = []
    for r in rows:
        if r["evidence"] == "agrees" and r["gap_m"] is not None:
            bound = max(floor, sigmas * (r["companion_sigma_m"] or 0.0))
            if r["gap_m"] > bound:
                r = {**r, "flagged": True, "evidence": "departs",
                     "reasons": [*r["reasons"], f"ends {r['gap_m']:.2f} m from its companion (floor {floor:g} m)"]}
        moved.append(r)
    return moved


def gap_bias(rows: list[dict], truth: float, within: float = 0.2) -> str:
    """How far the final error of the completions judged against a companion (agrees or departs) lies from their gap,
    over those whose gap is within ``within`` of ``truth``: the runs the floor decides."""
    near = [r["final_m"] - r["gap_m"] for r in rows if r["evidence"] in ("agrees", "departs")
            and r["gap_m"] is not None and abs(r["gap_m"] - truth) <= within]
    if not near:
        return f"no completion with a gap within {within:g} m of {truth:g} m"
    d = np.asarray(near)
    return (f"final error - gap over the {len(d)} completions with a gap within {within:g} m of {truth:g} m: median "
            f"{np.median(d):+.3f} m, 10th-90th percentile {np.percentile(d, 10):+.3f} to {np.percentile(d, 90):+.3f}"
            f" m, error above the gap in {np.mean(d > 0):.0%}")


def input_group(source: str) -> str:
    """The kind of an input (:func:`layer_input`'s first part): sparse, dense, exact, classical (a completer that needs
    no training, ``dcslam.depth.models.CLASSICAL``) or networks (any other layer), with ", measured sources" for a run
    that aligned the LiDAR's pixels against the completed map."""
    from dcslam.depth.models import CLASSICAL

    base, measured = source.removesuffix("+measured"), source.endswith("+measured")
    kind = base if base in ("sparse", "dense", "exact") else "classical" if base in CLASSICAL else "networks"
    return kind + (", measured sources" if measured else "")


def grouped(rows: list[dict]) -> list[dict]:
    """``rows`` with each input replaced by its :func:`input_group` (exact and dense counted at 64 beams)."""
    return [{**r, "input": input_group(r["input"]), "beams": "64" if r["beams"] == "-" else r["beams"]} for r in rows]


def table(rows: list[dict], truth: float) -> list[tuple]:
    """(input, beams, runs, > truth, flagged of those, flagged of the others) per input and beam count, and a total."""
    groups = defaultdict(list)
    for r in rows:
        groups[(r["input"], r["beams"])].append(r)
    out = []
    for key in sorted(groups, key=lambda k: (k[0], -int(k[1]) if k[1].isdigit() else 0)):
        rs = groups[key]
        bad = [r for r in rs if r["final_m"] > truth]
        good = [r for r in rs if r["final_m"] <= truth]
        out.append((*key, len(rs), len(bad), sum(r["flagged"] for r in bad), sum(r["flagged"] for r in good)))
    bad = [r for r in rows if r["final_m"] > truth]
    good = [r for r in rows if r["final_m"] <= truth]
    out.append(("all", "", len(rows), len(bad), sum(r["flagged"] for r in bad), sum(r["flagged"] for r in good)))
    return out


def print_table(title: str, lines: list[tuple], truth: float) -> None:
    print(f"\n{title}")
    print(f"| input | beams | runs | > {truth:g} m | flagged of those | false flags |")
    print("| --- | --- | --- | --- | --- | --- |")
    for source, beams, n, bad, hit, false in lines:
        print(f"| {source} | {beams} | {n} | {bad} | {hit} | {false} of {n - bad} |")


def drive_numbers(text: str) -> set[str]:
    """``1000-1003`` or ``1000,1002`` -> the drive numbers as strings."""
    out = set()
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        out |= {str(n) for n in range(int(lo), int(hi or lo) + 1)}
    return out


def weak_steps(health: dict) -> tuple[str, list[str]]:
    """What a run's flagged steps were, from its stored health: ``(kind, steps)`` with kind ``"held"`` when every
    degraded step was only weakly constrained and came after a measured velocity (a step accepted or held on one
    before it: the odometry held its constant-velocity prediction along the weak direction), ``"unmeasured"`` when
    weak steps hold from step 1 on, before any velocity was measured, ``"jumped or rejected"`` when a step was far
    from its prediction, short of pairs, or rejected, ``""`` without flagged steps; steps as ``<frame><codes>`` (W weak,
    J far from the prediction, P few pairs, R rejected)."""
    steps, measured, kinds = [], False, set()
    flagged = {s["frame"]: s for s in health.get("flagged_steps", [])}
    for frame in range(1, health["accepted"] + health["degraded"] + health["rejected"] + 1):
        step = flagged.get(frame)
        if step is None:
            measured = True
            continue
        codes = "R" if step["verdict"] == "rejected" else "".join(
            "W" if w.startswith("weakly") else "P" if PAIRS.match(w) else "J" for w in step["why"])
        steps.append(f"{frame}{codes}")
        if codes != "W":
            kinds.add("jumped or rejected")
            measured = False
        else:
            kinds.add("held" if measured else "unmeasured")
    kind = next((k for k in ("jumped or rejected", "unmeasured", "held") if k in kinds), "")
    return kind, steps


def print_weak_steps(runs: dict, truth: float) -> None:
    """Every sparse, dense and exact run with a flagged step: its final error and what its steps were
    (:func:`weak_steps`)."""
    print(f"\nflagged steps of sparse, dense and exact runs (bad: ending more than {truth:g} m off)")
    for (layer, drive), run in sorted(runs.items()):
        if companion_layer(layer, run["record"]) is not None and layer not in ("dense", "exact"):
            continue
        kind, steps = weak_steps(run["record"]["health"])
        if steps:
            final = float(run["record"]["translation_error_m"]["final"])
            print(f"{'bad ' if final > truth else 'good'} {layer:10s} {drive[-9:-5]} final {final:6.3f} m  "
                  f"{kind:18s} {' '.join(steps)}")


def print_flags(rows: list[dict], truth: float) -> None:
    """Every false flag (a run within ``truth`` flagged) and every miss (a run beyond it not flagged), with the
    reasons of its summary, the evidence verdict and its gap, the road figure and the drift bound."""
    print(f"\nfalse flags (ending within {truth:g} m, flagged) and misses (ending beyond, not flagged)")
    for r in rows:
        bad = r["final_m"] > truth
        if bad == r["flagged"]:
            continue
        what = "MISS" if bad else "FALSE"
        print(f"{what:5s} {r['layer']:24s} {r['drive'][-9:-5]} final {r['final_m']:.3f} m, evidence "
              f"{r['evidence']} (gap {r['gap_m'] if r['gap_m'] is not None else '-'}), road {r['road_m']}, bound "
              f"{r['bound_m']} (weakest share {r['weakest_share']}): {' | '.join(r['reasons']) or '-'}"
              + (f" [overruled: {' | '.join(r['overruled'])}]" if r["overruled"] else ""))


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("workspace", type=Path)
    p.add_argument("--truth", type=float, default=0.5, help="a run ending further than this (m) is bad")
    p.add_argument("--floors", default="0.3", help="candidate floor_m values, comma-separated")
    p.add_argument("--sigmas", default="3", help="candidate sigmas values, comma-separated")
    p.add_argument("--min-pairs", default=str(HealthRules().min_pairs), help="candidate min_pairs values")
    p.add_argument("--drift-sigmas", default=f"{HealthRules().drift_sigmas:g}",
                   help="candidate drift_sigmas values (standard deviations of the drift bound)")
    p.add_argument("--json", type=Path, help="write the per-run rows of every candidate here")
    p.add_argument("--runs", action="store_true", help="print every run of the last candidate")
    p.add_argument("--flags", action="store_true",
                   help="print every false flag and miss of the stored verdicts, with its reasons")
    p.add_argument("--drives", help="only these drives, by number: 1000-1003 or 1000,1002")
    p.add_argument("--group", action="store_true",
                   help="also print the stored verdicts with the inputs grouped by kind")
    p.add_argument("--weak-steps", action="store_true",
                   help="print what the flagged steps of every sparse, dense and exact run were")
    p.add_argument("--stored-floors", help="the stored verdicts with the evidence floor lowered to each of these "
                   "(comma-separated, metres; by the stored gaps, nothing run again), and the gap's bias near --truth")
    p.add_argument("--rejudge", action="store_true",
                   help="judge the completions under this checkout's evidence rule, the candidates' included, "
                        "against their companions run again and road-corrected")
    return p


def candidates(args, runs: dict, companions: Companions | None) -> dict[str, list[dict]]:
    """The rows of every candidate rule (``--min-pairs`` x ``--drift-sigmas`` x ``--sigmas`` x ``--floors``),
    each table printed."""
    results = {}
    for pairs, drift, sigmas, floor in itertools.product(
            [int(p) for p in args.min_pairs.split(",")], [float(d) for d in args.drift_sigmas.split(",")],
            [float(s) for s in args.sigmas.split(",")], [float(f) for f in args.floors.split(",")]):
        name = f"min_pairs {pairs}, drift bound {drift:g} sigma, evidence {sigmas:g} sigma, floor {floor:g} m"
        results[name] = verdicts(runs, HealthRules(min_pairs=pairs, drift_sigmas=drift),
                                 EvidenceRules(sigmas=sigmas, floor_m=floor), companions)
        print_table(name, table(results[name], args.truth), args.truth)
    return results


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    runs = load_runs(args.workspace / "slam")
    if args.drives:
        keep = drive_numbers(args.drives)
        runs = {k: v for k, v in runs.items() if k[1].removesuffix("_sync")[-4:] in keep}
    if not runs:
        print(f"no SLAM outputs under {args.workspace / 'slam'}", file=sys.stderr)
        return 1
    companions = Companions(args.workspace, runs) if args.rejudge else None
    results = {"stored": verdicts(runs, None, None, companions)}
    title = ("rejudged verdicts (the steps' health as written, the evidence of this checkout's rule)" if args.rejudge
             else "stored verdicts (the health as written, with its evidence)")
    differ = {key: d for key, d in (companions.differences if companions else {}).items() if d > 1e-6}
    for (kind, drive), difference in sorted(differ.items()):
        print(f"{kind} {drive}: the companion run again differs from the stored run by up to {difference:.3g} m",
              file=sys.stderr)
    print_table(title, table(results["stored"], args.truth), args.truth)
    if args.group:
        print_table(title.split(" (")[0] + ", inputs grouped by kind", table(grouped(results["stored"]), args.truth),
                    args.truth)
    if args.stored_floors:
        print(f"\n{gap_bias(results['stored'], args.truth)}")
        for floor in [float(f) for f in args.stored_floors.split(",")]:
            if floor > EvidenceRules().floor_m:
                print(f"--stored-floors {floor:g}: above the stored floor {EvidenceRules().floor_m:g} m",
                      file=sys.stderr)
                return 2
            results[f"stored, floor {floor:g} m"] = moved_floor(results["stored"], floor)
            print_table(f"stored verdicts, evidence floor {floor:g} m", table(results[f"stored, floor {floor:g} m"],
                                                                               args.truth), args.truth)
    if args.flags:
        print_flags(results["stored"], args.truth)
    if args.weak_steps:
        print_weak_steps(runs, args.truth)
    results.update(candidates(args, runs, companions))
    if args.runs:
        for r in list(results.values())[-1]:
            print(f"{r['layer']:28s} {r['drive'][-9:-5]} final {r['final_m']:6.3f} gap {r['gap_m'] or 0:6.3f} "
                  f"{'FLAG' if r['flagged'] else '    '} {r['evidence']} {'; '.join(r['reasons'])[:120]}")
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    if differ:
        print(f"{len(differ)} companion run(s) did not reproduce the stored ones: the rejudged verdicts are not the "
              f"workspace's (set MKL_CBWR as when it was made)", file=sys.stderr)
        return 1
    return 0

if __name__ == "__main__":
    sys.exit(main())
