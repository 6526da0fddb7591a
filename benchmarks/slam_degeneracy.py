"""Measure the health verdict on generated drives: SLAM at the defaults on each drive's depth kinds, and per run its
final error, the verdict as dcslam writes it (the step rules, the road figure, the drift bound where a step left a
direction degenerate), the verdict of the previous rule (the step rules and the drift bound on every run, no road),
the road figure and the bound's size, direction and frame.

The drives are the street generator's (``dcslam synth``'s scenes and sensors) at half KITTI size, written straight
to drive files with ``sparse`` (64 beams), ``sparse@<beams>`` and ``exact`` depth (tests/fixtures/street.py), so
that a few drives of a seed no test uses cost minutes, not the hour of full-size ``synth`` + ``prepare-kitti``.

    python benchmarks/slam_degeneracy.py /tmp/degeneracy --seeds 7171-7186 --beams 8,16 --frames 32 --slam-frames 30
"""
from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from pathlib import Path


def seeds_of(text: str) -> list[int]:
    """``7171-7178`` or ``7171,7175`` -> the seeds."""
    out = []
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        out += list(range(int(lo), int(hi or lo) + 1))
    return out


def make_drives(folder: Path, seeds: list[int], beams: int, frames: int) -> list[Path]:
    """One drive file per seed with ``sparse``, ``sparse@<beams>`` and ``exact`` depth (kept when already there)."""
    from tests.fixtures.street import write_generated_drive

    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for seed in seeds:
        path = folder / f"drive{seed}.h5"
        if not path.exists():
            write_generated_drive(path, seed, frames=frames, scale=0.5, beams=beams)
        paths.append(path)
    return paths


def judge_run(path: Path, kind: str, frames: int) -> dict:
    """SLAM at the defaults over the first ``frames`` frames of ``kind`` on a drive -> one row."""
    from dcslam.slam.config import build_slam
    from dcslam.slam.health import HealthRules, summarise
    from dcslam.stages.slam import SlamStageConfig, run_drive_file

    config = SlamStageConfig(depth=kind, frames=frames, evidence="none")
    run = run_drive_file(path, kind, build_slam(config.settings()), frames)
    summary = run.summary()
    health = summary["health"]
    without = summarise(run.reports, HealthRules(max_drift_m=0, max_road_drift_m=0))
    previous = bool(without["suspect"]) or health["drift"]["bound_m"] > HealthRules().max_drift_m
    return {"drive": path.stem, "kind": kind, "final_m": summary["translation_error_m"]["final"],
            "flagged": bool(health["suspect"]), "reasons": health["reasons"], "drift": health["drift"],
            "road": health["road"], "flagged_without_bound": bool(without["suspect"]), "flagged_before": previous,
            "seconds": round(run.seconds, 2)}


def rescaled(rows: list[dict], sigmas: float) -> list[dict]:
    """The rows re-judged with a drift bound of ``sigmas`` standard deviations (the bound is proportional to it; the
    other rules' verdicts are kept)."""
    from dcslam.slam.health import HealthRules

    limit = HealthRules().max_drift_m
    return [{**r, "flagged": r["flagged_without_bound"] or r["drift"]["bound_m"] * sigmas / r["drift"]["sigmas"]
             > limit} for r in rows if r["flagged_without_bound"] is not None]


def judge_completed(path: Path, kind: str, frames: int, folder: Path) -> dict:
    """IP-Basic (fast) completing ``kind`` on a drive, written as a layer that says what it completed, then
    ``dcslam slam`` on it with its companion (``--evidence auto``) -> one row (its final error and verdict; no
    "before", which would need the former companion too)."""
    import numpy as np

    from dcslam.depth.models.ip_basic import fast
    from dcslam.io.drive import DriveFile, Layer, load_depth, write_layer
    from dcslam.stages import slam
    from dcslam.workspace import Workspace

    completer = fast()
    layer = folder / f"{completer.name}-{kind}"
    layer.mkdir(parents=True, exist_ok=True)
    if not (layer / path.name).exists():
        with DriveFile(path) as drive:
            sparse = load_depth(drive, kind)
        write_layer(layer / path.name, Layer(depth=np.stack([completer(d) for d in sparse]).astype(np.float32),
                                             drive=path.stem, made_by=completer.name, config={"input": kind}))
    result = slam.run(Workspace(folder / "ws"), slam.SlamStageConfig(   # the depth's evidence: no camera
        depth=str(layer), drive=[str(path)], frames=frames, out=folder / "slam" / layer.name, evidence="auto",
        camera=False), force=True)[0]
    health = result.summary["health"]
    return {"drive": path.stem, "kind": f"{completer.name} ({kind})",
            "final_m": result.summary["translation_error_m"]["final"], "flagged": bool(health["suspect"]),
            "reasons": health["reasons"], "drift": health["drift"], "evidence": health["evidence"]["verdict"],
            "flagged_without_bound": None, "flagged_before": None, "seconds": result.summary["seconds"]}


def table(rows: list[dict], truth: float) -> list[str]:
    """Markdown: per depth kind, runs / ending > truth / flagged of those (before / now) / flagged of the others."""
    groups = defaultdict(list)
    for r in rows:
        groups[r["kind"]].append(r)
    lines = [f"| input | runs | > {truth:g} m | flagged of those: previous / new | flagged of the others: previous / "
             "new |",
             "| --- | --- | --- | --- | --- |"]
    for kind in sorted(groups) + ["all"]:
        rs = rows if kind == "all" else groups[kind]
        bad = [r for r in rs if r["final_m"] > truth]
        good = [r for r in rs if r["final_m"] <= truth]
        def before(runs):
            known = [r["flagged_before"] for r in runs if r["flagged_before"] is not None]
            return str(sum(known)) if len(known) == len(runs) else "-"

        lines.append(f"| {kind} | {len(rs)} | {len(bad)} | {before(bad)} / {sum(r['flagged'] for r in bad)} | "
                     f"{before(good)} / {sum(r['flagged'] for r in good)} of {len(good)} |")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="folder for the drive files and rows.json")
    parser.add_argument("--seeds", default="7171-7178")
    parser.add_argument("--beams", default="8,16", help="fewer-beam kinds to run besides sparse and exact")
    parser.add_argument("--frames", type=int, default=32, help="frames per generated drive")
    parser.add_argument("--slam-frames", type=int, default=30, help="frames of each drive SLAM runs over")
    parser.add_argument("--kinds", default="sparse,exact", help="full-density kinds to run (of the first beams' "
                                                                "drives)")
    parser.add_argument("--truth", type=float, default=0.5, help="a run ending further than this (m) is bad")
    parser.add_argument("--drift-sigmas", default="", help="also tabulate the verdicts with these standard "
                                                           "deviations of the drift bound, comma-separated")
    parser.add_argument("--rows", action="store_true", help="re-read <out>/rows.json instead of running SLAM")
    parser.add_argument("--ip-basic", action="store_true", help="also IP-Basic (fast) completing each sparse kind, "
                                                                "judged with its companion")
    args = parser.parse_args(argv)
    if args.rows:
        rows = json.loads((args.out / "rows.json").read_text())
        print_tables(rows, args)
        return 0
    import torch

    torch.set_num_threads(1)
    seeds = seeds_of(args.seeds)
    rows = []
    for k, beams in enumerate(int(b) for b in args.beams.split(",")):
        drives = make_drives(args.out / f"beams{beams}", seeds, beams, args.frames)
        kinds = [f"sparse@{beams}"] + ([kind for kind in args.kinds.split(",") if kind] if k == 0 else [])
        for kind in kinds:
            for path in drives:
                row = judge_run(path, kind, args.slam_frames)
                rows.append(row)
                d = row["drift"]
                print(f"{kind:10s} {path.stem} final {row['final_m']:6.3f} {'FLAG' if row['flagged'] else 'ok  '} "
                      f"previous {'FLAG' if row['flagged_before'] else 'ok  '} bound {d['bound_m']:.2f} m "
                      f"{'counted' if d['counted'] else 'not counted'} road {row['road']['drift_m']:.2f} m "
                      f"{row['road']['vertical']} ({row['road']['frames_seen']} frames) | "
                      f"{'; '.join(row['reasons'])[:160]}", flush=True)
        for kind in ([f"sparse@{beams}"] + (["sparse"] if k == 0 else [])) if args.ip_basic else []:
            for path in drives:
                row = judge_completed(path, kind, args.slam_frames, args.out / f"beams{beams}")
                rows.append(row)
                print(f"{row['kind']:10s} {path.stem} final {row['final_m']:6.3f} "
                      f"{'FLAG' if row['flagged'] else 'ok  '} evidence {row['evidence']} bound "
                      f"{row['drift']['bound_m']:.2f} m | {'; '.join(row['reasons'])[:160]}", flush=True)
    (args.out / "rows.json").write_text(json.dumps(rows, indent=1, default=str))
    print_tables(rows, args)
    return 0


def print_tables(rows: list[dict], args) -> None:
    print("\nthe rules as they are")
    print("\n".join(table(rows, args.truth)))
    for sigmas in (float(x) for x in args.drift_sigmas.split(",") if x):
        print(f"\ndrift bound of {sigmas:g} sigma")
        print("\n".join(table(rescaled(rows, sigmas), args.truth)))


if __name__ == "__main__":
    sys.exit(main())
