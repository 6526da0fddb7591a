"""`dcslam demo-icl`: depth denoising learnt through the map (a thin wrapper over dcslam.denoise.run_denoising)."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from dcslam.cli.app import ForceOption, WorkspaceOption, app, known_errors, summary

HELP = (
    "The thesis's appendix C.2 experiment: a DnCNN learns to remove Gaussian noise from depth images when trained "
    "only with the chamfer distance between the PointFusion map (ground-truth poses) of its output and that of the "
    "clean depth. Prints, for the noisy input and the denoised output on held-out frames, MAE / RMSE (mm) and PSNR "
    "against the clean depth and the chamfer distance of their maps to the clean map.\n\n"
    "Data: --drives (a drive file, or a folder with splits.json from `dcslam prepare-tum`: train and val drives "
    "train, test drives are held out), else indoor rooms generated in the ICL-NUIM layout and prepared under "
    "<workspace>/demo-icl/ (kept for the next run; the last room is held out).\n\n"
    "Writes <workspace>/results/demo-icl/: results.md, results.csv, results.json (settings, scores, frames, "
    "losses), denoising.png (noisy, denoised and clean depth of held-out frames, like the thesis's figure C.6) "
    "and model.pt. About 70 s with the defaults on two quiet CPU cores."
)


@app.command("demo-icl", help=HELP)
@known_errors
def demo_icl_command(
    sigma: Annotated[float, typer.Option(help="Standard deviation of the Gaussian depth noise, metres.")] = 0.05,
    steps: Annotated[int, typer.Option(help="Training steps (AdamW).")] = 200,
    lr: Annotated[float, typer.Option(help="AdamW learning rate (after a linear warm-up over 10 % of the "
                                           "steps).")] = 1e-3,
    batch_size: Annotated[int, typer.Option(help="Frames per step (single-frame maps).")] = 4,
    patch: Annotated[int, typer.Option(help="Train on random patch × patch windows (0 = whole images).")] = 64,
    map_frames: Annotated[int, typer.Option(help="Frames per chamfer map (1: one map per frame).")] = 1,
    scale: Annotated[float, typer.Option(help="Image scale, 1/integer (0.25: 640 × 480 → 160 × 120).")] = 0.25,
    features: Annotated[int, typer.Option(help="DnCNN feature channels.")] = 32,
    layers: Annotated[int, typer.Option(help="DnCNN layers.")] = 8,
    frames: Annotated[int, typer.Option(help="Frames per generated sequence.")] = 30,
    sequences: Annotated[int, typer.Option(help="Generated sequences (rooms); the last one is held out.")] = 4,
    drives: Annotated[Optional[Path], typer.Option(
        help="A drive file or a folder of drive files with splits.json, instead of generated rooms.")] = None,
    seed: Annotated[int, typer.Option(help="Seed of the generated rooms, the noise and training.")] = 0,
    device: Annotated[str, typer.Option(help="auto (a GPU if there is one), cpu or cuda.")] = "auto",
    workspace: WorkspaceOption = None,
    force: ForceOption = False,
) -> None:
    import time

    from dcslam.cli.score import print_table
    from dcslam.denoise import OUTPUT_FILES, DenoiseConfig, demo_drives, drives_of, run_denoising
    from dcslam.eval.report import check_outputs
    from dcslam.progress import Bar
    from dcslam.workspace import Workspace

    start = time.perf_counter()
    ws = Workspace.resolve(workspace)
    out_dir = ws.results / "demo-icl"
    config = DenoiseConfig(sigma_m=sigma, steps=steps, lr=lr, batch_size=batch_size, patch=patch,
                           map_frames=map_frames, scale=scale, features=features, layers=layers, seed=seed,
                           device=device)
    if drives is None:
        config.check()  # before the data is generated
        check_outputs([out_dir / name for name in OUTPUT_FILES], force)
        with Bar("indoor rooms", total=sequences * frames) as bar:
            drives = demo_drives(ws.root / "demo-icl", sequences=sequences, frames=frames, seed=seed, force=force,
                                 on_frame=bar.advance)
    config.train_drives, config.test_drives = drives_of(drives)
    result = run_denoising(out_dir, config, force=force)
    print_table(result.table)
    summary(f"results in {out_dir} (results.md, results.csv, results.json, denoising.png, model.pt); "
            f"{time.perf_counter() - start:.0f} s")
