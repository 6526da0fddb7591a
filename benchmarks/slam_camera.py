"""The camera as a witness of SLAM runs on measured depth (:mod:`dcslam.slam.camera`): for every stored run of a
calibration workspace (``slam_calibration.py``'s test drives; the runs ``dcslam slam`` wrote under ``slam/KIND/``),
each step measured again from the drive's colour images with the run's own measured depth (started, as ``dcslam
slam --camera`` starts it, from the companion's steps: the stored run of that measured kind stands for the companion
of another input's run), the camera's trajectory composed, and its figure (the distance of the run's last position
from it) set beside the run's true final error and the verdict its summary holds (the rule now). Nothing is rerun:
the runs and their verdicts are the stored ones.

Prints every run's row and, for thresholds on the camera's gap, how many runs that end more than ``--truth`` metres
off and how many of the others it flags: alone, together with the rule now, and together with the road figure only.

    OMP_NUM_THREADS=1 python benchmarks/slam_camera.py /tmp/calib-ws [more workspaces] --json camera.json --jobs 2
"""
from __future__ import annotations

import argparse
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

KINDS = ("sparse", "sparse@16", "sparse@8")


def measured_of(summary: dict) -> str:
    """The measured depth kind behind a stored run's input, as ``dcslam slam --camera`` names it: the ICP sources'
    kind with ``--sources measured``, else :func:`dcslam.io.drive.measured_kind` of the source its summary records
    (a sparse kind its own, ``sparse`` for dense and exact, a layer the input it was predicted from)."""
    from dcslam.io.drive import measured_kind

    kind = summary.get("sources", {}).get("kind") or measured_kind(summary["settings"]["source"])
    if kind is None:
        raise SystemExit(f"{summary['settings']['source']}: does not say which measured depth it was made from")
    return kind


def before_camera(health: dict) -> dict:
    """A stored health as the rules without the camera left it: the camera's verdict taken out, its reason dropped
    and the reasons it overruled put back (:func:`dcslam.slam.camera.merge_camera` undone); as it is when the run
    was not judged by the camera."""
    camera = health.get("camera")
    if not camera:
        return health
    reasons = [r for r in health.get("reasons", []) if r != camera.get("reason")] + list(health.get("overruled", []))
    rest = {k: v for k, v in health.items() if k not in ("camera", "overruled")}
    return {**rest, "reasons": reasons, "suspect": bool(reasons)}


def measure(ws: Path, kind: str, drive: str) -> dict:
    """One stored run (``slam/<kind>/``, a depth kind or a prediction layer's name): its true final error, its
    stored verdict without the camera (:func:`before_camera`), the camera's figure and verdict
    (:func:`dcslam.slam.camera.judge_camera`), the verdict under the camera rule (that health merged with it, as
    ``dcslam slam --camera`` writes it, read as the tables read it) and the camera's own final error."""
    import torch

    from dcslam.io.drive import DriveFile
    from dcslam.io.slam_summary import run_verdict
    from dcslam.io.tum import read_tum
    from dcslam.slam.camera import camera_trajectory, judge_camera, merge_camera, witness

    torch.set_num_threads(1)
    stored = json.loads((ws / "slam" / kind / f"{drive}.json").read_text())
    health = before_camera(stored["health"])    # a run stored with --camera: judged as without it, then again
    summary = {**stored, "health": health}
    measured = measured_of(summary)
    stamps, T = read_tum(ws / "slam" / kind / f"{drive}.txt")
    with DriveFile(ws / "drives" / f"{drive}.h5") as d:
        first = int(np.argmin(np.abs(d.timestamps - stamps[0])))
        truth = np.linalg.inv(d.poses[first]) @ d.poses[first:first + len(T)]
        start = T
        companion = ws / "slam" / measured / f"{drive}.txt"   # the stored run of the measured kind stands for it
        if kind != measured and companion.exists():
            theirs = read_tum(companion)[1]
            start = theirs if len(theirs) == len(T) else T   # started from the companion's steps, as the stage
        steps = witness(d, measured, start, first_frame=first)[1]
        camera = camera_trajectory(T, steps)
    figure = judge_camera(T, camera, steps)
    ruled = run_verdict({**summary, "health": merge_camera(health, figure)})
    return {"workspace": ws.name, "kind": kind, "drive": drive, "measured": measured,
            "final_m": float(np.linalg.norm(T[-1, :3, 3] - truth[-1, :3, 3])),
            "camera_final_m": float(np.linalg.norm(camera[-1, :3, 3] - truth[-1, :3, 3])),
            "flagged": run_verdict(summary).suspect, "reasons": list(health["reasons"]),
            "camera_rule": ruled.suspect, "road_m": (health.get("road") or {}).get("drift_m"), **figure}


def separation(rows: list[dict], truth: float, road_m: float = 0.5) -> None:
    """For thresholds on the camera's gap: bad and good runs flagged by it alone, with the rule now, and with the
    road figure (``road_m``) alone beside it."""
    bad = [r for r in rows if r["final_m"] > truth]
    good = [r for r in rows if r["final_m"] <= truth]
    print(f"\n{len(bad)} runs end more than {truth:g} m off, {len(good)} within; the rule now flags "
          f"{sum(r['flagged'] for r in bad)} and {sum(r['flagged'] for r in good)}")
    print(f"the camera rule (dcslam slam --camera) flags {sum(r['camera_rule'] for r in bad)} and "
          f"{sum(r['camera_rule'] for r in good)}")
    print("| camera gap threshold m | bad / good flagged by the gap | rule or gap | road or gap |\n"
          "| --- | --- | --- | --- |")
    others = {"alone": lambda r: False, "rule": lambda r: r["flagged"],
              "road": lambda r: (r["road_m"] or 0.0) > road_m}
    for t in (0.3, 0.4, 0.45, 0.5, 0.6, 0.75):
        cells = [" / ".join(str(sum((r["gap_m"] > t) or other(r) for r in rs)) for rs in (bad, good))
                 for other in others.values()]
        print(f"| {t:g} | " + " | ".join(cells) + " |")


def by_input(rows: list[dict], truth: float) -> None:
    """Per input (the stored run's folder): runs, bad runs, and bad / good runs flagged by the rule now and by the
    camera rule."""
    print("\n| input | runs | > 0.5 m | flagged of those: now / camera rule "
          "| flagged of the others: now / camera rule |\n| --- | --- | --- | --- | --- |")
    for kind in sorted({r["kind"] for r in rows}):
        rs = [r for r in rows if r["kind"] == kind]
        bad = [r for r in rs if r["final_m"] > truth]
        good = [r for r in rs if r["final_m"] <= truth]
        print(f"| {kind} | {len(rs)} | {len(bad)} | {sum(r['flagged'] for r in bad)} / "
              f"{sum(r['camera_rule'] for r in bad)} | {sum(r['flagged'] for r in good)} / "
              f"{sum(r['camera_rule'] for r in good)} of {len(good)} |")


def tasks(workspaces: list[Path], kinds: list[str]) -> list[tuple[Path, str, str]]:
    """(workspace, kind, drive) of every stored run of the workspaces' test drives."""
    out = []
    for ws in workspaces:
        split = ws / "drives" / "splits.json"
        if not split.is_file():
            raise SystemExit(f"{ws}: no drives/splits.json (run slam_calibration.py first)")
        for drive in json.loads(split.read_text())["test"]:
            out += [(ws, kind, drive) for kind in kinds if (ws / "slam" / kind / f"{drive}.txt").is_file()]
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("workspace", type=Path, nargs="+")
    p.add_argument("--truth", type=float, default=0.5, help="a run ending further than this (m) is bad")
    p.add_argument("--kinds", default=",".join(KINDS), help=(
        "comma-separated inputs (slam/KIND/ runs): depth kinds or prediction layers' names, e.g. "
        "ip-basic-fast-sparse8"))
    p.add_argument("--jobs", type=int, default=1, help="worker processes")
    p.add_argument("--json", type=Path, help="write every row here")
    args = p.parse_args(argv)
    todo = tasks(args.workspace, args.kinds.split(","))
    rows = []
    with ProcessPoolExecutor(args.jobs) as pool:
        for row in pool.map(measure, *zip(*todo)):
            rows.append(row)
            print(f"{row['workspace']} {row['drive'][-9:-5]} {row['kind']:9s} final {row['final_m']:.3f} camera "
                  f"{row['camera_final_m']:.3f} gap {row['gap_m']:.3f} ({row['direction']}, sigma "
                  f"{row['sigma_m']:.3f}) camera rule {'FLAG' if row['camera_rule'] else '-'}, now "
                  f"{'FLAG ' + ' | '.join(row['reasons']) if row['flagged'] else '-'}", flush=True)
            if args.json:
                args.json.write_text(json.dumps(rows, indent=1))
    separation(rows, args.truth)
    by_input(rows, args.truth)
    return 0


if __name__ == "__main__":
    sys.exit(main())
