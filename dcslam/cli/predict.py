"""`dcslam predict`: write a prediction layer per drive with a trained run or IP-Basic."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from dcslam.cli.app import ForceOption, WorkspaceOption, app, known_errors, summary


@app.command("predict", help="Complete the sparse depth of drives with a trained run (or IP-Basic) and write "
                             "predictions/<run>/<drive>.h5.")
@known_errors
def predict_command(
    run: Annotated[Optional[str], typer.Option(help="Run name under runs/ (or ip-basic-fast, ip-basic-multiscale).")]
    = None,
    model: Annotated[Optional[str], typer.Option(help="ip-basic, ip-basic-fast or ip-basic-multiscale: a model that "
                                                      "needs no run folder.")] = None,
    split: Annotated[str, typer.Option(help="Split whose drives to predict (train, val, test).")] = "test",
    drive: Annotated[Optional[list[Path]], typer.Option(help="Drive file(s) to predict instead of a split.")] = None,
    output: Annotated[Optional[Path], typer.Option(help="Output folder (default predictions/<run>/).")] = None,
    device: Annotated[str, typer.Option(help="auto, cpu or cuda.")] = "auto",
    workspace: WorkspaceOption = None,
    force: ForceOption = False,
) -> None:
    from dcslam.depth.models import IP_BASIC_NAMES
    from dcslam.depth.predict import ip_basic_predictor, predict_drive, run_predictor
    from dcslam.depth.train import resolve_device
    from dcslam.errors import DcslamError
    from dcslam.io.drive import read_splits
    from dcslam.workspace import Workspace, require

    ws = Workspace.resolve(workspace)
    if (run is None) == (model is None):
        raise DcslamError("give one of --run NAME or --model ip-basic[-fast|-multiscale]")
    if model is not None:
        if model not in ("ip-basic",) + IP_BASIC_NAMES:
            raise DcslamError(f"--model {model!r}: expected ip-basic, {', '.join(IP_BASIC_NAMES)} (or use --run)")
        predictor = ip_basic_predictor(model)
        folder = "ip-basic" if model == "ip-basic" else model
    elif run in IP_BASIC_NAMES:
        predictor, folder = ip_basic_predictor(run), run
    else:
        predictor = run_predictor(require(ws.runs / run, "dcslam train"), resolve_device(device))
        folder = run
    if drive:
        paths = list(drive)
    else:
        splits = read_splits(ws.splits)
        if split not in splits:
            raise DcslamError(f"unknown split {split!r}; expected train, val or test")
        paths = [require(ws.drives / f"{name}.h5", "dcslam prepare-kitti") for name in splits[split]]
        if not paths:
            raise DcslamError(f"split {split!r} of {ws.splits} has no drives")
    out_dir = output or ws.predictions / folder
    outputs = [out_dir / Path(p).name for p in paths]
    existing = [p for p in outputs if p.exists()]
    if existing and not force:
        raise DcslamError(f"{existing[0]} exists; pass --force to overwrite it")
    for path, out in zip(paths, outputs):
        predict_drive(predictor, path, out, force=force)
    summary(f"{len(outputs)} prediction layer(s) by {predictor.made_by} in {out_dir}")
