"""`dcslam prepare-tum`: TUM RGB-D / ICL-NUIM sequences (real or generated) → drive files + splits.json."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from dcslam.cli.app import ForceOption, WorkspaceOption, app, known_errors, summary

HELP = (
    "Convert TUM RGB-D or ICL-NUIM sequences (real, or from `dcslam synth --indoor`) into one HDF5 drive file each "
    "plus splits.json, the format `dcslam slam`, `train` and `score` read.\n\n"
    "A sequence folder holds associations.txt (ICL-NUIM: 't depth/N.png t rgb/N.png') or rgb.txt and depth.txt "
    "(TUM: associated by nearest timestamp, at most 0.02 s apart), 16-bit depth PNGs (5000 = 1 m) and a TUM "
    "trajectory (groundtruth.txt or *.gt.freiburg, also looked for in the parent folder). Poses are interpolated "
    "at each depth timestamp; frames without one are dropped.\n\n"
    "Intrinsics: --intrinsics, else the folder's intrinsics.txt, else TUM's ROS default (525, 525, 319.5, 239.5) or "
    "ICL-NUIM's (481.2, -480, 319.5, 239.5): its negative fy is real (the camera's y axis points up) and is kept.\n\n"
    "depth/dense is the sensor depth; depth/sparse keeps every --sparse-stride-th row and column of it "
    "(LiDAR-like, 4 % of pixels at 5)."
)


def parse_intrinsics_option(text: str | None):
    """``fx,fy,cx,cy`` → (3, 3) K, or None."""
    if text is None:
        return None
    from dcslam.io.tum_rgbd import parse_intrinsics

    return parse_intrinsics(text, "--intrinsics")


@app.command("prepare-tum", help=HELP)
@known_errors
def prepare_tum_command(
    tum: Annotated[Optional[Path], typer.Option(
        "--tum", help="A sequence folder, or a folder of sequence folders.", show_default="<workspace>/tum")] = None,
    out: Annotated[Optional[Path], typer.Option(
        "--out", "-o", help="Folder for drive files and splits.json.", show_default="<workspace>/drives")] = None,
    intrinsics: Annotated[Optional[str], typer.Option(
        "--intrinsics", help="fx,fy,cx,cy in pixels for every sequence (fy may be negative).",
        show_default="intrinsics.txt, else the format's default")] = None,
    sparse_stride: Annotated[int, typer.Option(
        "--sparse-stride", min=1, help="depth/sparse keeps every k-th row and column of the depth (1/k² of the "
                                       "pixels).")] = 5,
    max_frames: Annotated[Optional[int], typer.Option(
        "--max-frames", min=1, help="Keep at most this many frames (after --stride) per sequence.")] = None,
    stride: Annotated[int, typer.Option("--stride", min=1, help="Keep every k-th frame.")] = 1,
    splits: Annotated[Optional[Path], typer.Option(
        "--splits", help='A {"train": [...], "val": [...], "test": [...]} JSON file of sequence names.',
        show_default="15/4/5 proportion by name; one sequence goes to test")] = None,
    workspace: WorkspaceOption = None,
    force: ForceOption = False,
) -> None:
    from dcslam.prepare_tum import prepare_tum
    from dcslam.workspace import Workspace

    ws = Workspace.resolve(workspace)
    K = parse_intrinsics_option(intrinsics)
    result = prepare_tum(tum or ws.root / "tum", out or ws.drives, intrinsics=K, sparse_stride=sparse_stride,
                         max_frames=max_frames, stride=stride, splits_file=splits, force=force)
    for note in result.notes:
        typer.echo(f"note: {note}", err=True)
    lines = [f"{d.name}: {d.frames} frames, split {d.split or '-'} -> {d.path}" for d in result.drives]
    lines.append("splits: " + ", ".join(f"{k} {len(v)}" for k, v in result.splits.items())
                 + f" -> {result.splits_path}")
    summary("\n".join(lines))
