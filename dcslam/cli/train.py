"""`dcslam train`: train a depth-completion network (options: dcslam.stages.train)."""
from __future__ import annotations

from dcslam.cli.app import app, summary
from dcslam.cli.options import stage_command
from dcslam.stages import train

HELP = ("Train a depth-completion network with MSE (sparse/dense mask), chamfer (1- or multi-frame maps) or pose "
        "(relative-pose error of differentiable ICP) loss; writes runs/<name>/ (model.pt, config.json, "
        "metrics.jsonl, curves.png).")


def report(result) -> None:
    from dcslam.depth.distributed import is_main_process

    if not is_main_process():
        return
    best = result.best or {}
    summary(f"run {result.run_dir}: {result.steps} steps, {result.epochs} epochs; best validation "
            + (f"at step {best['step']}: chamfer {best['chamfer']:.4g} m², MAE {best['mae_mm']:.1f} mm, "
               f"RMSE {best['rmse_mm']:.1f} mm" if best else "none (no validation drives)"))


train_command = stage_command(app, "train", train.TrainStageConfig, train.run, report, help=HELP,
                              examples=("dcslam train --loss chamfer --map-frames 8 --scale 0.5 --epochs 3",
                                        "dcslam train --loss mse --mask dense --resume    # after Ctrl-C: continue "
                                        "from last.pt",
                                        "dcslam train --model nconv --correct-fill --input-mix sparse --input-mix "
                                        "sparse@16 --l1-weight 30 --lr 1e-3 --lr-schedule cosine --name nconv-cf    "
                                        "# correct a nearest-neighbour fill"))
