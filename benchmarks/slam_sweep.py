"""How sensitive is localisation to each SLAM setting? Runs dcslam's SLAM over prepared drives once per variant and
prints one line per variant (mean / worst ATE, drives ending > 0.5 m off, how many of those were flagged, frames/s);
``--markdown`` also writes the per-drive tables.

Generate drives of a seed no test uses, then sweep::

    python -m dcslam synth --drives 8 --frames 110 --seed 2026 -w /tmp/slamsweep
    python -m dcslam prepare-kitti -w /tmp/slamsweep --all-drives
    python benchmarks/slam_sweep.py /tmp/slamsweep/drives --depth sparse --frames 60 \\
        --variant "" --variant "association=nn" --variant "voxel_size=0.2;gate_schedule=2,1"

A variant is ``key=value;...`` over :class:`dcslam.slam.config.SlamSettings` fields ("" = the defaults).
Not run by ``make bench`` (minutes per variant); ``bench_slam.py`` runs the references on the chosen defaults.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

from slam_drives import markdown_table, parse_settings, run_dcslam  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("drives", type=Path, help="folder of prepared drive files (.h5)")
    parser.add_argument("--depth", default="sparse",
                        help="sparse, sparse@<beams> (prepare-kitti --beams), dense, exact or a layer file")
    parser.add_argument("--frames", type=int, default=0, help="frames per drive (0 = all)")
    parser.add_argument("--max-drives", type=int, default=0)
    parser.add_argument("--variant", action="append", default=None, help="key=value;... (repeatable)")
    parser.add_argument("--steps", type=Path, help="write every step's evidence (JSON lines) to this file")
    parser.add_argument("--markdown", type=Path, help="append per-drive tables to this file")
    args = parser.parse_args()
    import torch

    torch.set_num_threads(1)
    paths = sorted(args.drives.glob("*.h5"))[:args.max_drives or None]
    if not paths:
        raise SystemExit(f"no drive files in {args.drives}: run `dcslam prepare-kitti` first")
    print(f"{len(paths)} drives x {args.frames or 'all'} frames, depth {args.depth}", flush=True)
    if args.markdown and not args.markdown.exists():
        import os
        import platform

        args.markdown.parent.mkdir(parents=True, exist_ok=True)
        args.markdown.write_text(
            f"# SLAM on generated drives\n\nMade by `python benchmarks/slam_sweep.py {' '.join(sys.argv[1:])}` on "
            f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores shared with other jobs, torch "
            f"{torch.__version__} on 1 thread. frames/s is wall-clock time of the SLAM steps only (no file "
            f"reading). ATE: RMSE of position errors without alignment (both start at the true first pose); RPE: "
            f"RMSE of frame-to-frame translation errors; final: position error at the last frame; degraded / "
            f"rejected: flagged steps; suspect: the run's health flag.\n\n")
    for variant in args.variant or [""]:
        settings = parse_settings(variant)
        steps = [] if args.steps else None
        rows = [run_dcslam(p, args.depth, settings, args.frames, steps=steps) for p in paths]
        if args.steps:
            with open(args.steps, "a") as f:
                for step in steps:
                    f.write(json.dumps({"variant": variant, **step}) + "\n")
        ate = np.array([r.ate_m for r in rows])
        bad = [r for r in rows if r.final_m > 0.5]
        print(f"{variant or 'defaults':55s} ATE mean {ate.mean():6.3f} max {ate.max():6.3f}  "
              f"final>0.5m {len(bad)} (flagged {sum(r.suspect for r in bad)})  "
              f"false flags {sum(r.suspect for r in rows if r.final_m <= 0.5)}  "
              f"fps {np.median([r.fps for r in rows]):5.2f} (CPU {np.median([r.cpu_fps for r in rows]):5.2f})  "
              f"per drive " + " ".join(f"{a:.2f}" for a in ate),
              flush=True)
        if args.markdown:
            with open(args.markdown, "a") as f:
                f.write(markdown_table(rows, f"{args.depth}: {variant or 'defaults'} "
                                       f"({settings.to_dict()})") + "\n")


if __name__ == "__main__":
    main()
