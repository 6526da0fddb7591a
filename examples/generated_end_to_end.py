"""Generated data, end to end, one `dcslam` command per stage, then one small table of the scores.

    synth → prepare-kitti → train (one recipe) → predict → slam on sparse, dense and predicted depth
          → score depth and trajectory → table

Each stage is the command you would type; this script runs them in order in one workspace and reads the CSV files
that `dcslam score` writes. Needs nothing but dcslam (no dataset, no GPU). examples/real_kitti.py reuses it.

Usage:
    python examples/generated_end_to_end.py                       # 4 drives of 24 frames
    python examples/generated_end_to_end.py --recipe chamfer-8 --epochs 2 --workspace /tmp/ws --force
    python examples/generated_end_to_end.py --drives 2 --frames 12 --epochs 1 --max-frames 2 --scale 0.25 \\
        --slam-frames 2 --icp-iterations 2                        # a smoke run: the numbers mean nothing
"""
import argparse
import csv
import subprocess
import sys
from pathlib import Path

RECIPES = {  # the thesis's four training recipes as `dcslam train` options; ip-basic-* need no training
    "mse-dense": ["--loss", "mse", "--mask", "dense"], "mse-sparse": ["--loss", "mse", "--mask", "sparse"],
    "chamfer-1": ["--loss", "chamfer", "--map-frames", "1"], "chamfer-8": ["--loss", "chamfer", "--map-frames", "8"],
}


def dcslam(a, *args) -> None:
    """Run `dcslam ARGS --workspace WS [--force]`; stop the script (exit 1) if it fails."""
    args = [str(arg) for arg in args]
    print(f"\n$ dcslam {' '.join(args)}", flush=True)
    force = ["--force"] if a.force else []
    if subprocess.run([sys.executable, "-m", "dcslam", *args, "--workspace", str(a.workspace), *force]).returncode:
        sys.exit(f"stopped: `dcslam {' '.join(args)}` failed (its error is above)")


def options(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """The options of every stage after prepare-kitti (shared with examples/real_kitti.py)."""
    parser.add_argument("--workspace", type=Path, default=Path("workspace-example"), help="workspace folder")
    parser.add_argument("--recipe", choices=[*RECIPES, "ip-basic-fast"], default="mse-dense", help="what completes")
    parser.add_argument("--epochs", type=int, default=2)
    parser.add_argument("--max-frames", type=int, default=200, help="training frames per drive")
    parser.add_argument("--scale", type=float, default=0.5, help="training image scale (1, 0.5, 0.25)")
    parser.add_argument("--slam-frames", type=int, default=0, help="frames of each test drive fed to SLAM (0 = all)")
    parser.add_argument("--icp-iterations", type=int, default=20, help="ICP iterations per gate stage")
    parser.add_argument("--force", action="store_true", help="overwrite what an earlier run wrote")
    return parser


def complete_slam_score(a, slam: bool = True) -> None:
    """train → predict → slam on sparse, dense and predicted depth → scores → table, in ``a.workspace``."""
    run = a.recipe
    if run in RECIPES:  # runs/<recipe>/ (model.pt, metrics.jsonl, curves.png), then predictions/<recipe>/
        dcslam(a, "train", *RECIPES[run], "--name", run, "--epochs", a.epochs, "--max-frames", a.max_frames,
               "--scale", a.scale)
    dcslam(a, "predict", "--run", run)
    layers = {"sparse": ["sparse"], "dense": ["dense"], run: ["predicted", "--run", run]}
    for layer, depth in layers.items():  # one SLAM (PointFusion + point-to-plane ICP) per depth source
        if slam:                         # → slam/<layer>/<drive>.txt (TUM), .ply (map), .json (summary)
            dcslam(a, "slam", "--depth", *depth, "--frames", a.slam_frames, "--iterations", a.icp_iterations)
            dcslam(a, "score", "trajectory", "--layer", layer)  # → results/trajectory_<layer>.csv
        dcslam(a, "score", "depth", "--layer", layer)           # → results/depth_<layer>.csv

    # one line per depth source: depth errors over all test frames, trajectory errors averaged over the test drives
    print(f"\n{'depth source':<14}{'MAE mm':>9}{'RMSE mm':>9}{'iRMSE/km':>10}{'localisation':>14}{'ATE m':>8}")
    for layer in layers:
        with open(a.workspace / "results" / f"depth_{layer}.csv", newline="") as f:
            depth = list(csv.DictReader(f))[-1]  # the row "all"
        line = f"{layer:<14}{float(depth['mae_mm']):>9.1f}{float(depth['rmse_mm']):>9.1f}" \
               f"{float(depth['irmse_per_km']):>10.2f}"
        if slam:
            with open(a.workspace / "results" / f"trajectory_{layer}.csv", newline="") as f:
                drives = list(csv.DictReader(f))
            line += "".join(f"{sum(float(r[k]) for r in drives) / len(drives):>{w}.{p}f}"
                            for k, w, p in (("localisation", 14, 4), ("ate_rmse", 8, 3)))
        print(line)
    print(f"\nlocalisation: the thesis's accuracy (m + rad, lower is better); ATE unaligned; in {a.workspace}/results/")


def main() -> None:
    parser = options(argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter))
    parser.add_argument("--drives", type=int, default=4, help="generated drives (split like the thesis's 15/4/5)")
    parser.add_argument("--frames", type=int, default=24, help="raw frames per drive (depth for frames 5 … N-6)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the generated scenes")
    a = parser.parse_args()
    # KITTI-format drives (camera 2, LiDAR, OXTS, calibration) in kitti/, then drives/<drive>.h5 + splits.json
    dcslam(a, "synth", "--drives", a.drives, "--frames", a.frames, "--seed", a.seed)
    dcslam(a, "prepare-kitti")
    complete_slam_score(a)


if __name__ == "__main__":
    main()
