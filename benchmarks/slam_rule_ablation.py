"""What each part of the health verdict does: every SLAM run of a calibration workspace (``slam_calibration.py``'s
inputs: sparse at each beam count, dense, exact and every prediction layer, on the test drives) run again in this
process at the defaults, and each judged, with its companion where it has one, under each rule of :data:`RULES`
(health rules and evidence rules):

- ``before the hold bound``: held steps counted as degraded and a direction degenerate by its share alone;
- ``holds only``, ``pairs only``: the hold bound (:func:`dcslam.slam.health.hold_bound`) alone, degeneracy by share
  and pairs alone;
- ``before the prediction bound``: the whole drift bound counted once a step is degenerate, the evidence floor at
  0.5 m (the rule before :attr:`~dcslam.slam.health.HealthRules.prediction_bound`);
- ``prediction bound only``, ``floor 0.48 m only``: each change of the rule after it alone;
- ``this rule``: the defaults of :class:`dcslam.slam.health.HealthRules` and
  :class:`dcslam.slam.evidence.EvidenceRules`.

Prints, per rule, the runs that end more than ``--truth`` metres off and how many are flagged, and the others and
how many are flagged, over all the drives and over each half (``--halves``), then the per-input table of
``--compare`` (a rule's name; default ``before the prediction bound``) and this rule side by side, and every false
flag and miss of this rule. The SLAM runs take what ``dcslam slam`` takes (about 10 minutes for 88 runs of 30
full-size frames on one core); the trajectories are those of ``dcslam slam --evidence auto``, whose stored
verdicts ``slam_evidence.py`` reads.

    OMP_NUM_THREADS=1 python benchmarks/slam_rule_ablation.py /tmp/calib-ws --halves 1000-1003,1004-1007
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

from slam_evidence import drive_numbers, layer_input, table  # noqa: E402

from dcslam.slam.drive import DriveRun, companion_verdict  # noqa: E402
from dcslam.slam.evidence import EvidenceRules, merge  # noqa: E402
from dcslam.slam.health import HealthRules, summarise  # noqa: E402

_BEFORE = HealthRules(prediction_bound=False)
#: name -> (health rules, evidence rules)
RULES = {"before the hold bound": (replace(_BEFORE, degenerate_pairs=math.inf, hold_bound=False),
                                   EvidenceRules(floor_m=0.5)),
         "holds only": (replace(_BEFORE, degenerate_pairs=math.inf), EvidenceRules(floor_m=0.5)),
         "pairs only": (replace(_BEFORE, hold_bound=False), EvidenceRules(floor_m=0.5)),
         "before the prediction bound": (_BEFORE, EvidenceRules(floor_m=0.5)),
         "prediction bound only": (HealthRules(prediction_bound=True), EvidenceRules(floor_m=0.5)),
         "floor 0.48 m only": (_BEFORE, EvidenceRules(floor_m=0.48)),
         "this rule": (HealthRules(), EvidenceRules())}


def inputs(ws: Path) -> list[str]:
    """The depth sources ``slam_calibration.py`` runs: the drive's kinds, then ``predicted/<layer>`` per prediction
    folder that holds layers."""
    kinds = ["sparse", "sparse@16", "sparse@8", "dense", "exact"]
    predictions = ws / "predictions"
    layers = sorted(p.name for p in predictions.iterdir() if any(p.glob("*.h5"))) if predictions.is_dir() else []
    return kinds + [f"predicted/{name}" for name in layers]


def companion_kind(layer: str) -> str | None:
    """The measured kind a layer's companion runs on (None: a sparse input, its own evidence)."""
    if layer == "sparse" or layer.startswith("sparse@"):
        return None
    _, beams = layer_input(layer)
    return "sparse" if beams in ("64", "-") else f"sparse@{beams}"


def run_all(ws: Path, frames: int) -> dict[tuple[str, str], DriveRun]:
    """{(layer, drive): the run, without its map} of every input on every test drive, at the defaults."""
    import torch

    from dcslam.slam.config import SlamSettings, build_slam
    from dcslam.stages.slam import run_drive_file

    torch.set_num_threads(1)
    tests = json.loads((ws / "drives" / "splits.json").read_text())["test"]
    runs = {}
    for source in inputs(ws):
        layer = source.split("/", 1)[-1]
        for drive in tests:
            depth = ws / "predictions" / layer / f"{drive}.h5" if source.startswith("predicted/") else source
            run = run_drive_file(ws / "drives" / f"{drive}.h5", depth, build_slam(SlamSettings()), frames)
            run.map = None
            runs[(layer, drive)] = run
        print(f"ran {layer} on {len(tests)} drives", file=sys.stderr, flush=True)
    return runs


def judge(runs: dict, rules: HealthRules, evidence: EvidenceRules = EvidenceRules()) -> list[dict]:
    """One row per run (``slam_evidence.table``'s keys): its health under ``rules``, merged with its companion's
    verdict under ``evidence`` (the companion judged under ``rules`` too) where it has one."""
    rows = []
    for (layer, drive), run in sorted(runs.items()):
        main = replace(run, health_rules=rules)
        health = summarise(main.reports, rules, main.frame_interval_s())
        kind = companion_kind(layer)
        if kind is not None:
            companion = replace(runs[(kind, drive)], health_rules=rules)
            health = merge(health, companion_verdict(main, companion, kind, evidence,
                                                     measured=layer in ("dense", "exact")))
        final = float(np.linalg.norm(run.T_world_cam[-1, :3, 3] - run.T_gt[-1, :3, 3]))
        source, beams = layer_input(layer)
        rows.append({"input": source, "beams": beams, "layer": layer, "drive": drive, "final_m": final,
                     "flagged": bool(health["suspect"]), "reasons": list(health["reasons"])})
    return rows


def counts(rows: list[dict], truth: float) -> str:
    bad = [r for r in rows if r["final_m"] > truth]
    good = [r for r in rows if r["final_m"] <= truth]
    return (f"bad {sum(r['flagged'] for r in bad)} of {len(bad)} flagged, good {sum(r['flagged'] for r in good)} "
            f"of {len(good)} flagged")


def print_side_by_side(previous: list[tuple], now: list[tuple], truth: float) -> None:
    """Per input and beam count (``slam_evidence.table``'s rows): runs, ending beyond ``truth``, flagged of those and
    of the others under the previous rule and this one."""
    print(f"\n| input | beams | runs | > {truth:g} m | flagged of those: previous -> this rule "
          f"| flagged of the others: previous -> this rule |\n| --- | --- | --- | --- | --- | --- |")
    for (name, beams, runs, bad, hit, false), (*_, hit_now, false_now) in zip(previous, now):
        print(f"| {name} | {beams} | {runs} | {bad} | {hit} -> {hit_now} | {false} -> {false_now} of {runs - bad} |")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("workspace", type=Path)
    p.add_argument("--frames", type=int, default=30, help="SLAM frames per drive")
    p.add_argument("--truth", type=float, default=0.5, help="a run ending further than this (m) is bad")
    p.add_argument("--halves", help="two drive ranges to count apart, e.g. 1000-1003,1004-1007")
    p.add_argument("--json", type=Path, help="write every rule's rows here")
    p.add_argument("--compare", default="before the prediction bound", choices=[r for r in RULES if r != "this rule"],
                   help="the rule whose per-input table is printed beside this rule's")
    args = p.parse_args(argv)
    if not (args.workspace / "drives" / "splits.json").is_file():
        print(f"{args.workspace}: no drives/splits.json (run slam_calibration.py first)", file=sys.stderr)
        return 1
    runs = run_all(args.workspace, args.frames)
    results = {name: judge(runs, *rules) for name, rules in RULES.items()}
    halves = args.halves.split(",") if args.halves else []
    print(f"{args.workspace}: {len(runs)} runs, {args.frames} frames; bad = ending more than {args.truth:g} m off")
    for name, rows in results.items():
        parts = [f"all: {counts(rows, args.truth)}"]
        for half in halves:
            keep = drive_numbers(half)
            mine = [r for r in rows if r["drive"].removesuffix("_sync")[-4:] in keep]
            parts.append(f"{half}: {counts(mine, args.truth)}")
        print(f"{name:27s} | " + " | ".join(parts))
    print(f"\nper input: {args.compare} -> this rule")
    print_side_by_side(table(results[args.compare], args.truth), table(results["this rule"], args.truth), args.truth)
    for r in results["this rule"]:
        if (r["final_m"] > args.truth) != r["flagged"]:
            what = "MISS " if r["final_m"] > args.truth else "FALSE"
            print(f"{what} {r['layer']:24s} {r['drive'][-9:-5]} final {r['final_m']:.3f} m: "
                  f"{' | '.join(r['reasons']) or '-'}")
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
