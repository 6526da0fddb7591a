"""Does the pose loss teach ICP which pixels to trust? nconv fine-tuned through the pose loss (its confidence as ICP
weights) against the same nconv before it, in SLAM with ``--confidence weights``; and what the beams experiment's
``nconv-pose`` row costs (CPU-seconds of its training, prediction and SLAM runs).

Run, in order (each step skips what a previous call made; the steps after ``drives`` may run in parallel processes)::

    python benchmarks/pose_beams.py drives --workspace WS            # the beams quick profile's drives (+ 16 beams)
    python benchmarks/pose_beams.py train --workspace WS --run nconv  # then --run nconv-pose [--lr 1e-2 --name N]
    python benchmarks/pose_beams.py slam --workspace WS --run nconv --beams 64 [--frames 30] [--drives 1004 1005]
    python benchmarks/pose_beams.py score --workspace WS --runs nconv nconv-pose --beams 64 16

Trainings use the beams quick profile's options (:data:`dcslam.stages.experiments.beams.PROFILES`), so ``nconv`` and
``nconv-pose`` are the runs the experiment makes. ``train`` prints the run's CPU-seconds and its validation pose error
(the pose loss's ICP over windows of 4 frames of the validation drive) with the validation pose error of the model it
started from; ``slam`` prints the CPU-seconds of each prediction and SLAM run. ``score`` prints, per beam count, each
run's thesis localisation metric and ATE RMSE per drive, their mean ± the half-width of the 95 % t-interval over the
drives, and the paired difference of each later run from the first.
"""
from __future__ import annotations

import argparse
import resource
import time
from pathlib import Path

QUICK = "quick"


def _cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def _timed(label: str, fn, *args, **kwargs):
    cpu, wall = _cpu(), time.perf_counter()
    out = fn(*args, **kwargs)
    print(f"{label}: {_cpu() - cpu:.1f} CPU-s, {time.perf_counter() - wall:.1f} s wall", flush=True)
    return out


def drives(ws) -> None:
    from dcslam.stages.experiments.common import make_drives
    from dcslam.stages.pipeline import Pipeline
    from dcslam.stages.experiments.beams import PROFILES

    profile = PROFILES[QUICK]
    _timed("drives", make_drives, Pipeline(ws, print), drives=profile.drives, frames=profile.frames,
           split=profile.split, seed=0, beams=(16,))


def _validation_pose(ws, model_file: Path, config) -> dict:
    """The pose error of ``model_file`` on the validation drives, as the training's validation computes it."""
    import torch

    from dcslam.depth.data import DriveFrames
    from dcslam.depth.models import load_model
    from dcslam.depth.train_pose import pose_loss_of, validate_pose
    from dcslam.io.drive import read_splits

    train_config = config.train_config([], [])
    model, _ = load_model(model_file)
    splits = read_splits(ws.splits)
    frames = [DriveFrames(ws.drives / f"{name}.h5", max_frames=config.max_frames, scale=config.scale)
              for name in splits["val"]]
    return validate_pose(model, frames, pose_loss_of(train_config), config.pose_frames, torch.device("cpu"))


def train(ws, run: str, lr: float | None, name: str | None) -> None:
    from dataclasses import replace

    from dcslam.stages import train as train_stage
    from dcslam.stages.experiments.beams import PROFILES

    config = PROFILES[QUICK].train_config(run, seed=0)
    if lr is not None:
        config = replace(config, lr=lr)
    if name is not None:
        config = replace(config, name=name)
    if not (ws.runs / config.run_name / "model.pt").exists():
        _timed(f"train {config.run_name} (lr {config.lr:g})", train_stage.run, ws, config)
    if config.loss == "pose":
        before = _validation_pose(ws, ws.runs / config.init / "model.pt", config)
        after = _validation_pose(ws, ws.runs / config.run_name / "model.pt", config)
        for label, v in (("before", before), ("after", after)):
            print(f"validation pose error {label}: {v['pose_translation_m'] * 1000:.1f} mm / "
                  f"{v['pose_rotation_rad'] * 1000:.2f} mrad per step (loss {v['pose']:.4f})")


def slam(ws, run: str, beams: int, frames: int, only: list[str]) -> None:
    from dcslam.io.drive import read_splits
    from dcslam.report.table_beams import prediction_name, sparse_kind
    from dcslam.stages import predict
    from dcslam.stages import slam as slam_stage

    test = read_splits(ws.splits)["test"]
    layer = prediction_name(run, beams)
    if not (ws.predictions / layer / f"{test[-1]}.h5").exists():
        _timed(f"predict {layer}", predict.run, ws,
               predict.PredictConfig(run=run, input=sparse_kind(beams), output=ws.predictions / layer,
                                     drive=[ws.drives / f"{d}.h5" for d in test]))
    for drive in (d for d in test if not only or any(part in d for part in only)):
        if not (ws.slam / layer / f"{drive}.txt").exists():
            _timed(f"slam {layer} {drive} ({frames} frames)", slam_stage.run, ws,
                   slam_stage.SlamStageConfig(odometry="icp", depth=f"predicted/{layer}", drive=[drive],
                                              frames=frames, confidence="weights"))


def score(ws, runs: list[str], beams: list[int]) -> None:
    import numpy as np

    from dcslam.io.drive import read_splits
    from dcslam.report.spread import spread
    from dcslam.report.results import score_layer
    from dcslam.report.table_beams import prediction_name

    test = read_splits(ws.splits)["test"]

    def text(values) -> str:
        s = spread(values)
        half = "" if s.ci_high is None else f" ± {s.ci_high - s.mean:.4f}"
        return f"{s.mean:.4f}{half}"

    for b in beams:
        rows = {}
        for run in runs:
            result = score_layer(ws, run, prediction_name(run, b), test)
            if result.missing:
                print(f"{b} beams, {run}: missing {'; '.join(result.missing)}")
                continue
            rows[run] = result.per_drive()
        for run, per_drive in rows.items():
            loc = [per_drive[d]["localisation"] for d in test]
            ate = [per_drive[d]["ate_rmse_m"] for d in test]
            cells = " ".join(f"{d}: {lo:.4f}/{a:.3f}" for d, lo, a in zip(test, loc, ate))
            print(f"{b} beams {run}: {cells} | localisation {text(loc)} | ATE {text(ate)} | MAE "
                  f"{np.mean([per_drive[d]['mae_mm'] for d in test]):.0f} mm")
        names = list(rows)
        for run in names[1:]:
            for key in ("localisation", "ate_rmse_m"):
                diff = [rows[run][d][key] - rows[names[0]][d][key] for d in test]
                print(f"{b} beams {run} − {names[0]} ({key}, per drive): {[round(x, 4) for x in diff]} → "
                      f"{text(diff)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("step", choices=("drives", "train", "slam", "score"))
    parser.add_argument("--workspace", type=Path, required=True)
    parser.add_argument("--run", default="nconv")
    parser.add_argument("--runs", nargs="*", default=["nconv", "nconv-pose"])
    parser.add_argument("--name", default=None, help="train: run name other than --run's")
    parser.add_argument("--lr", type=float, default=None, help="train: learning rate other than the profile's")
    parser.add_argument("--beams", type=int, nargs="*", default=[64])
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--drives", nargs="*", default=[], help="slam: only the test drives whose names hold one "
                                                                 "of these (processes in parallel)")
    args = parser.parse_args()

    import torch

    from dcslam.workspace import Workspace

    torch.set_num_threads(1)
    ws = Workspace(args.workspace)
    if args.step == "drives":
        drives(ws)
    elif args.step == "train":
        train(ws, args.run, args.lr, args.name)
    elif args.step == "slam":
        for b in args.beams:
            slam(ws, args.run, b, args.frames, args.drives)
    else:
        score(ws, args.runs, args.beams)


if __name__ == "__main__":
    main()
