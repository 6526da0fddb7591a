"""Forward-backward consistency as evidence for a SLAM run on sparse depth: each sparse run of a calibration
workspace (``slam_calibration.py``'s test drives, 64/16/8 beams) is made again over the same frames in reverse
order, and the two runs' estimates of the last frame's pose relative to the first are composed. A run whose errors
do not repeat in reverse ends far from the identity; a run whose error is one the geometry forces both ways (a scale
along a corridor) does not, so the figure is measured, not assumed: per run the final error, the verdict of the
rule now (``dcslam slam``'s, the run's own steps), and the forward-backward gap (metres, and degrees).

Prints every run's row and, for a threshold on the gap, how many runs that end more than ``--truth`` metres off and
how many of the others it flags alone and together with the rule now.

    OMP_NUM_THREADS=1 python benchmarks/slam_forward_backward.py /tmp/calib-ws --json fb.json
"""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

KINDS = ("sparse", "sparse@16", "sparse@8")


def reversed_frames(drive):
    """``drive`` (a :class:`dcslam.io.drive_frames.DriveFrames`) with its frames in reverse order: the depth read
    first, the poses and the frames reversed, the timestamps mirrored so that they increase with the same steps."""
    frames = list(drive.frames)[::-1]
    t = np.asarray(drive.timestamps, dtype=np.float64)
    return replace(drive, T_world_cam=drive.T_world_cam[::-1].copy(), timestamps=(t[-1] - t[::-1]) + t[0],
                   frames=iter(frames))


def relative(T: np.ndarray) -> np.ndarray:
    """The last pose of the trajectory ``T`` (N, 4, 4) in the frame of its first."""
    return np.linalg.inv(T[0]) @ T[-1]


def gap(forward: np.ndarray, backward: np.ndarray) -> tuple[float, float]:
    """Translation (m) and rotation (degrees) of the loop: the forward run's last-in-first pose composed with the
    backward run's first-in-last (the identity when both agree)."""
    loop = relative(forward) @ relative(backward)
    angle = np.degrees(np.arccos(np.clip((np.trace(loop[:3, :3]) - 1) / 2, -1.0, 1.0)))
    return float(np.linalg.norm(loop[:3, 3])), float(angle)


def measure(path: Path, kind: str, frames: int) -> dict:
    """One drive and kind: both runs, the forward run's final error and verdict, and the loop's gap."""
    from dcslam.io.drive_frames import drive_frames
    from dcslam.slam.config import SlamSettings, build_slam
    from dcslam.slam.drive import run_drive
    from dcslam.stages.slam import run_drive_file

    forward = run_drive_file(path, kind, build_slam(SlamSettings()), frames, colour=False)
    with drive_frames(path, kind, frames, colour=False) as drive:
        backward = run_drive(reversed_frames(drive), build_slam(SlamSettings()))
    health = forward.health()
    metres, degrees = gap(forward.T_world_cam, backward.T_world_cam)
    final = float(np.linalg.norm(forward.T_world_cam[-1, :3, 3] - forward.T_gt[-1, :3, 3]))
    back_final = float(np.linalg.norm(backward.T_world_cam[-1, :3, 3] - backward.T_gt[-1, :3, 3]))
    return {"drive": path.stem, "kind": kind, "final_m": final, "backward_final_m": back_final,
            "flagged": bool(health["suspect"]), "reasons": list(health["reasons"]),
            "backward_flagged": bool(backward.health()["suspect"]), "gap_m": metres, "gap_deg": degrees}


def separation(rows: list[dict], truth: float) -> None:
    """For thresholds on the gap: bad runs flagged and good runs flagged, by the gap alone and with the rule now."""
    bad = [r for r in rows if r["final_m"] > truth]
    good = [r for r in rows if r["final_m"] <= truth]
    print(f"\n{len(bad)} runs end more than {truth:g} m off, {len(good)} within; "
          f"the rule now flags {sum(r['flagged'] for r in bad)} and {sum(r['flagged'] for r in good)}")
    print("| gap threshold m | bad flagged by the gap | good flagged by the gap | bad flagged, rule or gap "
          "| good flagged, rule or gap |\n| --- | --- | --- | --- | --- |")
    for t in (0.1, 0.2, 0.3, 0.4, 0.5, 0.75, 1.0):
        def by(rs, either):
            return sum((r["gap_m"] > t) or (either and r["flagged"]) for r in rs)
        print(f"| {t:g} | {by(bad, False)} | {by(good, False)} | {by(bad, True)} | {by(good, True)} |")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("workspace", type=Path, nargs="+")
    p.add_argument("--frames", type=int, default=30, help="SLAM frames per drive")
    p.add_argument("--truth", type=float, default=0.5, help="a run ending further than this (m) is bad")
    p.add_argument("--kinds", default=",".join(KINDS), help="comma-separated sparse kinds")
    p.add_argument("--json", type=Path, help="write every row here")
    args = p.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    rows = []
    for ws in args.workspace:
        split = ws / "drives" / "splits.json"
        if not split.is_file():
            print(f"{ws}: no drives/splits.json (run slam_calibration.py first)", file=sys.stderr)
            return 1
        for drive in json.loads(split.read_text())["test"]:
            for kind in args.kinds.split(","):
                row = {"workspace": ws.name, **measure(ws / "drives" / f"{drive}.h5", kind, args.frames)}
                rows.append(row)
                print(f"{ws.name} {row['drive'][-9:-5]} {kind:9s} final {row['final_m']:.3f} back "
                      f"{row['backward_final_m']:.3f} gap {row['gap_m']:.3f} m {row['gap_deg']:.2f} deg "
                      f"{'FLAG ' + ' | '.join(row['reasons']) if row['flagged'] else '-'}", flush=True)
                if args.json:
                    args.json.write_text(json.dumps(rows, indent=1))
    separation(rows, args.truth)
    return 0


if __name__ == "__main__":
    sys.exit(main())
