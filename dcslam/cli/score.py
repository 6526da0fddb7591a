"""`dcslam score`: depth errors, trajectory errors, map chamfer, and the thesis's Tables 5.1 / 5.2."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from dcslam.cli.app import ForceOption, WorkspaceOption, app, known_errors, summary

score_app = typer.Typer(help="Score depth layers, trajectories and maps; build Tables 5.1 and 5.2 under results/.",
                        no_args_is_help=True)
app.add_typer(score_app, name="score")

DriveOption = Annotated[Optional[list[str]], typer.Option(
    "--drive", help="Drive name (repeatable); default: the test split of splits.json.")]
OutOption = Annotated[Optional[Path], typer.Option("--out", help="CSV file to write (default under results/).")]


def print_table(table) -> None:
    """A :class:`dcslam.eval.tables.Table` as a rich table on stdout."""
    from rich.console import Console
    from rich.table import Table as RichTable

    shown = RichTable(title=table.title)
    for column in table.columns:
        shown.add_column(column.header)
    for row in table.rows:
        shown.add_row(*(table.cell(row, c) for c in table.columns))
    console = Console(width=200)
    console.print(shown)
    for note in table.notes:
        console.print(f"  {note}", highlight=False)


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-_+." else "_" for c in text)


def _file_or_layer_output(ws, kind: str, path: Optional[Path], gt: Optional[Path], layer: Optional[str],
                          out: Optional[Path], force: bool, usage: str) -> tuple[str, Path]:
    """The preamble of the commands that score either ``--<file> FILE --gt REFERENCE`` or ``--layer NAME``.

    Fails with ``usage`` unless exactly one of the two forms is given; returns the name the scores go by (the
    layer's, or the file's stem) and the CSV to write (``out``, or ``results/<kind>_<name>.csv``), checked not to
    exist unless ``force``.
    """
    from dcslam.errors import DcslamError
    from dcslam.eval.report import check_outputs

    if (path is None) == (layer is None) or (path is not None and gt is None):
        raise DcslamError(usage)
    name = _slug(layer) if layer else _slug(path.stem)
    out = out or ws.results / f"{kind}_{name}.csv"
    check_outputs([out], force)
    return name, out


@score_app.command("depth", help="MAE, RMSE (mm), iMAE, iRMSE (1/km) of a depth layer against the dense depth, "
                                 "as the KITTI devkit computes them (per image, then averaged).")
@known_errors
def depth_command(
    layer: Annotated[str, typer.Option(help="sparse, dense, a run or filter name, or a folder of layer files.")],
    drive: DriveOption = None,
    out: OutOption = None,
    raw: Annotated[bool, typer.Option("--raw", help="No devkit interpolation: score only the pixels where the "
                                                    "layer has depth.")] = False,
    workspace: WorkspaceOption = None,
    force: ForceOption = False,
) -> None:
    from dcslam.eval.layers import select_drives
    from dcslam.eval.report import check_outputs, depth_table, write_table_csv
    from dcslam.workspace import Workspace

    ws = Workspace.resolve(workspace)
    out = out or ws.results / f"depth_{_slug(Path(layer).name)}.csv"
    check_outputs([out], force)
    table = depth_table(ws, layer, select_drives(ws, drive), interpolate=not raw)
    write_table_csv(table, out, force=force)
    print_table(table)
    summary(f"wrote {out}")


@score_app.command("trajectory", help="Thesis localisation accuracy, ATE and RPE (as evo computes them) of "
                                      "estimated TUM trajectories: --est X.txt --gt drive.h5|Y.txt, or --layer "
                                      "NAME for slam/<layer>/<drive>.txt over the test drives.")
@known_errors
def trajectory_command(
    est: Annotated[Optional[Path], typer.Option(help="Estimated trajectory (TUM).")] = None,
    gt: Annotated[Optional[Path], typer.Option(help="Reference: a drive file (.h5) or a TUM file.")] = None,
    layer: Annotated[Optional[str], typer.Option(help="Score slam/<layer>/<drive>.txt against the drive "
                                                      "files.")] = None,
    drive: DriveOption = None,
    out: OutOption = None,
    workspace: WorkspaceOption = None,
    force: ForceOption = False,
) -> None:
    from dcslam.eval.layers import load_pair, score_layer_trajectories, select_drives
    from dcslam.eval.report import TRAJECTORY_SHOWN, trajectory_table, write_table_csv
    from dcslam.eval.tables import Table
    from dcslam.workspace import Workspace

    ws = Workspace.resolve(workspace)
    name, out = _file_or_layer_output(ws, "trajectory", est, gt, layer, out, force,
                                      "give either --est X.txt --gt REFERENCE, or --layer NAME")
    if layer:
        pairs = score_layer_trajectories(ws, layer, select_drives(ws, drive))
    else:
        pairs = {est.stem: load_pair(est, gt)}
    table = trajectory_table(pairs, f"trajectory errors of {name}")
    write_table_csv(table, out, force=force)
    brief = Table(table.title, [c for c in table.columns if c.key in ("trajectory", *TRAJECTORY_SHOWN)],
                        table.rows, table.notes)
    print_table(brief)
    summary(f"wrote {out}")


@score_app.command("map", help="Chamfer distance (the thesis's: mean squared nearest-neighbour distances, both "
                               "ways) between maps and ground-truth maps (PLY): --map X.ply --gt Y.ply, or "
                               "--layer NAME [--gt-layer dense] for slam/<layer>/<drive>.ply.")
@known_errors
def map_command(
    map_path: Annotated[Optional[Path], typer.Option("--map", help="Map (PLY).")] = None,
    gt: Annotated[Optional[Path], typer.Option(help="Ground-truth map (PLY).")] = None,
    layer: Annotated[Optional[str], typer.Option(help="Score slam/<layer>/<drive>.ply.")] = None,
    gt_layer: Annotated[str, typer.Option(help="Layer whose slam maps are the ground truth.")] = "dense",
    drive: DriveOption = None,
    out: OutOption = None,
    workspace: WorkspaceOption = None,
    force: ForceOption = False,
) -> None:
    from dcslam.eval.layers import select_drives
    from dcslam.eval.maps import score_map
    from dcslam.eval.report import map_table, write_table_csv
    from dcslam.workspace import Workspace

    ws = Workspace.resolve(workspace)
    name, out = _file_or_layer_output(ws, "map", map_path, gt, layer, out, force,
                                      "give either --map X.ply --gt Y.ply, or --layer NAME")
    if layer:
        scores = {d: score_map(ws.slam / layer / f"{d}.ply", ws.slam / gt_layer / f"{d}.ply")
                  for d in select_drives(ws, drive)}
    else:
        scores = {map_path.stem: score_map(map_path, gt)}
    table = map_table(scores, f"map of {name} against {gt_layer if layer else gt.name}")
    write_table_csv(table, out, force=force)
    print_table(table)
    summary(f"wrote {out}")


@score_app.command("tables", help="Tables 5.1 (validation of each recipe) and 5.2 (test drives) as Markdown and "
                                  "CSV under results/, with a trajectory plot per test drive and depth examples.")
@known_errors
def tables_command(
    drive: DriveOption = None,
    out_dir: Annotated[Optional[Path], typer.Option(help="Output folder (default: <workspace>/results).")] = None,
    workspace: WorkspaceOption = None,
    force: ForceOption = False,
) -> None:
    from dcslam.eval.layers import select_drives
    from dcslam.eval.report import build_report
    from dcslam.workspace import Workspace

    ws = Workspace.resolve(workspace)
    report = build_report(ws, select_drives(ws, drive), out_dir=out_dir, force=force)
    print_table(report.table_5_1)
    print_table(report.table_5_2)
    summary(f"wrote {len(report.written)} file(s) in {report.written[0].parent}")
