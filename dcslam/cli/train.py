"""`dcslam train`: train a depth-completion network (thin wrapper over :func:`dcslam.depth.train.train`)."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from dcslam.cli.app import ForceOption, WorkspaceOption, app, known_errors, summary


def _drive_paths(ws, names: list[str]) -> list[Path]:
    from dcslam.workspace import require

    return [require(ws.drives / f"{name}.h5", "dcslam prepare-kitti") for name in names]


@app.command("train", help="Train a depth-completion network with MSE (sparse/dense mask) or chamfer (1- or "
                           "multi-frame maps) loss; writes runs/<name>/ (model.pt, config.json, metrics.jsonl, "
                           "curves.png).")
@known_errors
def train_command(
    loss: Annotated[str, typer.Option(help="mse or chamfer.")] = "mse",
    mask: Annotated[str, typer.Option(help="MSE mask: dense (pixels with ground truth) or sparse (pixels with "
                                           "sparse input and ground truth).")] = "dense",
    map_frames: Annotated[int, typer.Option(help="Frames per chamfer map: 1, or windows of up to N frames "
                                                 "(the thesis: 8; its code: 7).")] = 1,
    model: Annotated[str, typer.Option(help="sparse-conv or dncnn.")] = "sparse-conv",
    epochs: Annotated[int, typer.Option(help="Passes over the training drives.")] = 1,
    lr: Annotated[float, typer.Option(help="AdamW learning rate.")] = 1e-3,
    weight_decay: Annotated[float, typer.Option(help="AdamW weight decay.")] = 0.01,
    max_frames: Annotated[int, typer.Option(help="At most this many frames per drive.")] = 200,
    stride: Annotated[int, typer.Option(help="Use every N-th frame.")] = 1,
    scale: Annotated[float, typer.Option(help="Image scale, 1/integer (1, 0.5, 0.25).")] = 1.0,
    crop: Annotated[int, typer.Option(help="Keep only the bottom N rows (0 = whole image).")] = 0,
    batch_size: Annotated[int, typer.Option(help="Frames per step (MSE and 1-frame chamfer).")] = 1,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    device: Annotated[str, typer.Option(help="auto (a GPU if there is one), cpu or cuda.")] = "auto",
    name: Annotated[Optional[str], typer.Option(help="Run name (default: mse-dense, mse-sparse, chamfer-1, ...).")]
    = None,
    resume: Annotated[bool, typer.Option("--resume", help="Continue an interrupted run from last.pt.")] = False,
    nproc: Annotated[int, typer.Option(help="Processes for distributed data-parallel training (launches torchrun).")]
    = 1,
    workspace: WorkspaceOption = None,
    force: ForceOption = False,
) -> None:
    if nproc > 1:
        from dcslam.depth.distributed import launch

        args = ["train", "--loss", loss, "--mask", mask, "--map-frames", str(map_frames), "--model", model,
                "--epochs", str(epochs), "--lr", str(lr), "--weight-decay", str(weight_decay),
                "--max-frames", str(max_frames), "--stride", str(stride), "--scale", str(scale), "--crop", str(crop),
                "--batch-size", str(batch_size), "--seed", str(seed), "--device", device]
        args += (["--name", name] if name else []) + (["--resume"] if resume else []) + (["--force"] if force else [])
        args += ["--workspace", str(workspace)] if workspace else []
        raise typer.Exit(launch(nproc, args))

    from dcslam.depth import distributed
    from dcslam.depth.train import TrainConfig, resolve_device, train
    from dcslam.io.drive import read_splits
    from dcslam.workspace import Workspace

    ws = Workspace.resolve(workspace)
    splits = read_splits(ws.splits)
    run_name = name or (f"{loss}-{mask}" if loss == "mse" else f"{loss}-{map_frames}")
    config = TrainConfig(loss=loss, mask=mask, map_frames=map_frames, model=model, epochs=epochs, lr=lr,
                         weight_decay=weight_decay, max_frames=max_frames, stride=stride, scale=scale, crop=crop,
                         batch_size=batch_size, seed=seed, device=device,
                         train_drives=_drive_paths(ws, splits["train"]), val_drives=_drive_paths(ws, splits["val"]))
    rank = 0
    if distributed.in_torchrun():
        rank, _ = distributed.init_from_env(resolve_device(device).type)
    try:
        result = train(ws.runs / run_name, config, force=force, resume=resume)
    finally:
        distributed.shutdown()
    if rank == 0:
        best = result.best or {}
        summary(f"run {result.run_dir}: {result.steps} steps, {result.epochs} epochs; best validation "
                + (f"at step {best['step']}: chamfer {best['chamfer']:.4g} m², MAE {best['mae_mm']:.1f} mm, "
                   f"RMSE {best['rmse_mm']:.1f} mm" if best else "none (no validation drives)"))
