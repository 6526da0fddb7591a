"""The pose loss's own figure on held-out drives: relative-pose error of differentiable frame-to-model ICP over windows
of consecutive frames, per drive, for trained runs and for the sparse and dense inputs.

Run: ``python benchmarks/pose_quality.py --workspace WS [--runs pose chamfer-8 ...] [--split test] [--frames 32]
[--window 4] [--scale 0.5]``.

Every run is scored with the pose loss's default ICP (``dcslam train --loss pose`` defaults: 10 LM iterations per
gate stage, 0.2 m source voxels, no step rejection), the depth layers ``sparse`` and ``dense`` the same way. Printed:
mean translation (mm) and rotation (mrad) error per step for each drive, and the mean ± half-width of the 95 %
t-interval over the drives. Figures depend on the drives: read them next to the workspace's description.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np


def t_half_width(values: list[float]) -> float:
    from scipy import stats

    n = len(values)
    return float(stats.t.ppf(0.975, n - 1) * np.std(values, ddof=1) / math.sqrt(n)) if n > 1 else math.nan


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workspace", type=Path, required=True)
    parser.add_argument("--runs", nargs="*", default=["chamfer-1", "chamfer-8", "mse-sparse", "mse-dense", "pose",
                                                      "pose-from-chamfer-8", "pose-from-mse-dense"])
    parser.add_argument("--split", default="test")
    parser.add_argument("--frames", type=int, default=32, help="first N frames of each drive")
    parser.add_argument("--window", type=int, default=4)
    parser.add_argument("--scale", type=float, default=0.5)
    args = parser.parse_args()

    import torch

    from dcslam.depth.data import DriveFrames, frame_windows
    from dcslam.depth.models import load_model
    from dcslam.depth.train import TrainConfig
    from dcslam.depth.train_pose import pose_loss_of, run_model_with_confidence
    from dcslam.io.drive import read_splits
    from dcslam.workspace import Workspace

    torch.set_num_threads(1)
    ws = Workspace(args.workspace)
    drives = [ws.drives / f"{name}.h5" for name in read_splits(ws.splits)[args.split]]
    loss = pose_loss_of(TrainConfig(loss="pose", train_drives=drives))
    sources = {"sparse": None, "dense": None}
    sources.update({run: load_model(ws.runs / run / "model.pt")[0] for run in args.runs
                    if (ws.runs / run / "model.pt").exists()})
    print(f"{len(drives)} {args.split} drives, first {args.frames} frames, windows of {args.window}, scale "
          f"{args.scale}; translation mm / rotation mrad per step")
    print(f"{'depth':<22}" + "".join(f"{p.stem[-9:-5]:>14}" for p in drives) + f"{'mean ± 95 %':>24}")
    for name, model in sources.items():
        t_per_drive, r_per_drive = [], []
        for path in drives:
            frames = DriveFrames(path, args.frames, 1, args.scale, 0, "sparse", "dense")
            t, r = [], []
            try:
                for window in frame_windows(len(frames), args.window):
                    if len(window) < 2:
                        continue
                    batch = frames.load(window)
                    with torch.no_grad():
                        if model is None:
                            depth, weight = getattr(batch, name), None
                        else:
                            depth, weight = run_model_with_confidence(model, batch)
                        _, details = loss(depth, batch.K, batch.T_world_cam, weight)
                    t += details["translation_m"].tolist()
                    r += details["rotation_rad"].tolist()
            finally:
                frames.close()
            t_per_drive.append(1000 * float(np.mean(t)))
            r_per_drive.append(1000 * float(np.mean(r)))
        cells = "".join(f"{t:>8.1f} /{r:>4.1f}" for t, r in zip(t_per_drive, r_per_drive))
        print(f"{name:<22}{cells}  {np.mean(t_per_drive):>7.1f} ± {t_half_width(t_per_drive):.1f} / "
              f"{np.mean(r_per_drive):.2f} ± {t_half_width(r_per_drive):.2f}", flush=True)


if __name__ == "__main__":
    main()
