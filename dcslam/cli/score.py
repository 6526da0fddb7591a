"""`dcslam score`: depth errors, trajectory errors, map chamfer, and the tables of the experiments (Tables 5.1 / 5.2,
the beams table)."""
from __future__ import annotations

from pathlib import Path

import typer

from dcslam.cli.app import app, summary
from dcslam.cli.options import stage_command
from dcslam.stages import score

score_app = typer.Typer(help="Score depth layers, trajectories and maps; build the experiments' tables (Tables 5.1 "
                             "and 5.2, the beams table) under results/.",
                        no_args_is_help=True)
app.add_typer(score_app, name="score", short_help="Score layers, runs and maps; build the tables")


#: The width tables are printed to: a terminal's, not the Markdown file's (which keeps every column).
WIDTH = 100

#: The columns printed of each table of ``score tables`` (by key; the files hold them all).
COMPACT = {
    "table_5_1": ("recipe", "run", "epoch", "chamfer", "mse", "mae_mm", "rmse_mm"),
    "table_5_2": ("method", "drives", "failures", "localisation_text", "vs_sparse", "mae_mm_text", "ate_rmse_m_text"),
    "table_5_2_long": ("method", "drives", "frames_text", "failures", "localisation_text", "vs_sparse",
                       "ate_rmse_m_text"),
    "depth": ("drive", "frames", "mae_mm", "rmse_mm", "normal_median_deg", "p2p_mean_m", "flying_share"),
}


def compact(table, keys: tuple[str, ...], full: str):
    """``table`` with only the columns of ``keys`` (those it has) and a note naming ``full``, the file with all."""
    from dcslam.report.tables import Table

    columns = [c for key in keys for c in table.columns if c.key == key]
    shown = Table(table.title, columns, table.rows, list(table.notes))
    shown.notes.insert(0, f"every column: {full}")
    return shown


def print_table(table) -> None:
    """A :class:`dcslam.report.tables.Table` as a rich table on stdout, at most :data:`WIDTH` characters wide."""
    from rich.console import Console
    from rich.table import Table as RichTable

    shown = RichTable(title=table.title)
    for column in table.columns:
        shown.add_column(column.header, overflow="fold")
    for row in table.rows:
        shown.add_row(*(table.cell(row, c) for c in table.columns))
    console = Console(width=WIDTH)
    console.print(shown)
    for note in table.notes:
        console.print(f"  {note}", highlight=False)


def report(result) -> None:
    shown = result.shown
    if any(c.key == "flying_share" for c in shown.columns):  # score depth: the devkit's and the surface errors
        shown = compact(shown, COMPACT["depth"], str(result.out))
    print_table(shown)
    summary(f"wrote {result.out}")


#: The tables of ``score tables`` printed, by the report's attribute → the file stem they are written to: Tables 5.1
#: to 5.3 (:class:`dcslam.report.scores.Report`) and the beams table (:class:`dcslam.report.table_beams.BeamsReport`).
SHOWN = {"table_5_1": "table_5_1", "table_5_2": "table_5_2", "table_5_2_long": "table_5_2_long",
         "table_5_2_correlation": "table_5_2_correlation", "table_5_3": "table_5_3", "table": "table_beams",
         "correlation": "table_beams_correlation"}


def report_tables(report) -> None:
    written = {p.stem: p for p in report.written if p.suffix == ".md"}
    for name, stem in SHOWN.items():
        table = getattr(report, name, None)
        if table is None:
            continue
        full = written.get(stem, stem + ".md")
        print_table(compact(table, COMPACT[name], str(full)) if name in COMPACT else table)
    if not report.written:
        return
    import os

    # named under their common folder, once: a line per file stays short however deep the workspace lies
    folder = Path(os.path.commonpath([str(p.parent) for p in report.written]))
    summary(f"wrote {len(report.written)} file(s) in {folder}:")
    for path in report.written:
        summary(f"  {Path(path).relative_to(folder)}")


stage_command(score_app, "depth", score.ScoreDepthConfig, score.run_depth, report,
              help="MAE, RMSE (mm), iMAE, iRMSE (1/km) of a depth layer against the dense depth, as the KITTI devkit "
                   "computes them (per image, then averaged), and the surface it builds as SLAM sees it: normal "
                   "angle error (mean, median; degrees), point-to-plane distance of its points from the reference "
                   "surface (mean, RMSE; m), and the share of pixels near reference depth edges that lie off both "
                   "sides (flying pixels).",
              examples=("dcslam score depth --layer mse-dense", "dcslam score depth --layer dense --drive DRIVE",
                        "dcslam score depth --layer ip-basic-fast --target exact    # generated drives"))
stage_command(score_app, "trajectory", score.ScoreTrajectoryConfig, score.run_trajectory, report,
              help="Thesis localisation accuracy, ATE and RPE (as evo computes them) of estimated TUM trajectories: "
                   "--est X.txt --gt drive.h5|Y.txt, or --layer NAME for slam/<layer>/<drive>.txt over the test "
                   "drives.",
              examples=("dcslam score trajectory --layer dense",
                        "dcslam score trajectory --est slam/dense/DRIVE.txt --gt drives/DRIVE.h5"))
stage_command(score_app, "map", score.ScoreMapConfig, score.run_map, report,
              help="Chamfer distance (the thesis's: mean squared nearest-neighbour distances, both ways) between maps "
                   "and ground-truth maps (PLY): --map X.ply --gt Y.ply, or --layer NAME [--gt-layer dense] for "
                   "slam/<layer>/<drive>.ply.",
              examples=("dcslam score map --layer mse-dense --gt-layer dense",
                        "dcslam score map --map a.ply --gt b.ply"))
stage_command(score_app, "tables", score.ScoreTablesConfig, score.run_tables, report_tables,
              help="Tables 5.1 (validation of each recipe) and 5.2 (test drives) as Markdown and CSV under results/, "
                   "with a trajectory plot per test drive and depth examples; when slam-long/ holds SLAM runs over "
                   "whole drives (dcslam reproduce), Table 5.2 over whole drives too. Table 5.2's rows carry surface "
                   "errors of 5 frames per drive, and table_5_2_correlation says which depth metric (MAE, RMSE, "
                   "normal error, point-to-plane, flying share) orders the rows' localisation best (Spearman's rho "
                   "over rows x drives, bootstrap interval). With --table NAME, the tables of that experiment of "
                   "`dcslam reproduce` instead (beams: the beams table, its per-drive table, correlation and plot).",
              examples=("dcslam score tables", "dcslam score tables --force    # after rerunning a stage",
                        "dcslam score tables --table beams --force    # the beams tables of dcslam reproduce "
                        "--table beams"))


def report_page(result) -> None:
    if result.written:
        summary(f"rewrote {len(result.changed)} of {result.regions} table region(s) in {result.page}")
    else:
        summary(f"{result.page}: {result.regions} table region(s), all as their results files")


def report_collect(result) -> None:
    summary(f"copied {len(result.files)} file(s) into {result.dest} (commit {result.provenance['commit']})")


stage_command(score_app, "page", score.ScorePageConfig, score.run_page, report_page, force=False,
              help="Rewrite the result tables of a Markdown page from committed results files: every region between "
                   "<!-- table: FILE --> and <!-- /table --> gets FILE's table and its provenance line; "
                   "columns=\"a,b\", rows=\"x,y\" (first cells) and index=N in the marker keep only those columns "
                   "and rows, in that order, of the file's N-th table.",
              examples=("dcslam score page RESULTS.md", "dcslam score page README.md --check"))
stage_command(score_app, "collect", score.ScoreCollectConfig, score.run_collect, report_collect,
              help="Copy a workspace's results (the .md and .csv files of results/) into results/<name>/ of the "
                   "repository with a provenance.json (commit, date, profile, command, machine).",
              examples=("dcslam score collect --name table_5_2 --profile quick --command 'make reproduce-table-5-2'",
                        "dcslam score collect --name beams -w ws-beams --force"))
