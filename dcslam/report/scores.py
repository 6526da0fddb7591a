"""What ``dcslam score`` computes and writes: per-layer depth / trajectory / map tables, and the full report
(Tables 5.1 and 5.2 as Markdown and CSV, the rank correlation of Table 5.2's depth metrics with localisation, a
trajectory plot per test drive, a figure of depth examples).

Every output is checked before anything is written: an existing file without ``force`` fails the whole call with
nothing overwritten, and so does bad input (a layer whose frame count does not match its drive, trajectories of
different lengths or with unsorted timestamps, a run without validation metrics).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from dcslam.errors import DcslamError
from dcslam.eval.depth import METRICS, mean_errors
from dcslam.report.layers import (TrajectoryPair, drive_file, resolve_layer, score_layer_depth,
                                  score_layer_surface)
from dcslam.eval.maps import MapScores
from dcslam.report.results import FAILURE_THRESHOLD, LayerResult, seed_layer, surface_note
from dcslam.report.table_5_2 import table_5_2, table_5_2_results
from dcslam.report.table_5_2_long import table_5_2_long, table_5_2_long_results
from dcslam.report.tables import Column, Table, list_runs, table_5_1, table_5_3, thesis_figures
from dcslam.eval.trajectory import EVO_MAX_TIME_DIFF_S
from dcslam.io.atomic import write_text_atomic
from dcslam.workspace import Workspace


def check_outputs(paths: list[Path], force: bool) -> None:
    """Fail, before anything is written, when an output exists and ``force`` is false."""
    for path in paths:
        if Path(path).is_dir():
            raise DcslamError(f"--out {path} is a folder; pass a file name such as {Path(path) / 'scores.csv'}")
    existing = [str(p) for p in paths if Path(p).exists()]
    if existing and not force:
        raise DcslamError(f"{existing[0]} exists{f' (and {len(existing) - 1} more)' if len(existing) > 1 else ''}; "
                          "pass --force to overwrite")


def depth_table(ws: Workspace, layer_name: str, drives: list[str], interpolate: bool = True,
                devkit_exact: bool = False, target: str = "dense") -> Table:
    """Depth errors and surface errors (:mod:`dcslam.eval.surface`) of a layer against the drives' ``target`` depth
    (``dense`` or ``exact``): one row per drive (mean over its frames) and a row ``all`` (mean over all frames)."""
    from dcslam.eval.surface import SURFACE_METRICS, mean_surface_errors

    layer = resolve_layer(ws, layer_name)
    per_drive = score_layer_depth(ws, layer, drives, interpolate, devkit_exact, target)
    surface = score_layer_surface(ws, layer, drives, target)
    columns = [Column("drive", "drive"), Column("frames", "frames"), Column("mae_mm", "MAE (mm)", "{:.1f}"),
               Column("rmse_mm", "RMSE (mm)", "{:.1f}"), Column("imae_per_km", "iMAE (1/km)", "{:.2f}"),
               Column("irmse_per_km", "iRMSE (1/km)", "{:.2f}"), Column("coverage", "coverage", "{:.3f}"),
               Column("normal_mean_deg", "normal mean (°)", "{:.1f}"),
               Column("normal_median_deg", "normal median (°)", "{:.1f}"),
               Column("p2p_mean_m", "p2p mean (m)", "{:.3f}"),
               Column("p2p_rmse_m", "p2p RMSE (m)", "{:.3f}"),
               Column("flying_share", "flying share", "{:.3f}")]
    table = Table(f"depth errors of {layer.name}" + (f" against {target} depth" if target != "dense" else ""),
                  columns)

    def row(name: str, frames: list, surfaces: list) -> dict:
        mean, shape = mean_errors(frames), mean_surface_errors(surfaces)
        return {"drive": name, "frames": len(frames), **{m: getattr(mean, m) for m in METRICS},
                "coverage": mean.coverage, **{m: getattr(shape, m) for m in SURFACE_METRICS}}

    for drive, frames in per_drive.items():
        table.rows.append(row(drive, frames, surface[drive]))
    table.rows.append(row("all", [e for frames in per_drive.values() for e in frames],
                          [e for frames in surface.values() for e in frames]))
    table.notes.append("exactly as the KITTI devkit (no departures)" if devkit_exact else
                       "KITTI devkit (holes of the prediction filled by background interpolation) with dcslam's two "
                       "departures (see --devkit-exact)" if interpolate else
                       "no interpolation: only pixels where the prediction has depth")
    table.notes.append("surface errors of the layer as SLAM takes it (no interpolation; its points and normals): "
                       "angle between its normals and the reference's, distance of its points from the reference "
                       "surface, share of pixels near reference depth edges that lie off both sides "
                       "(dcslam.eval.surface)")
    return table


TRAJECTORY_SHOWN = ("poses", "localisation", "ate_aligned_rmse", "ate_rmse", "rpe_trans_m_rmse", "rpe_rot_deg_rmse")


#: Readable headers of the trajectory scores (the CSV keeps the keys): a prefix of a key → its words and unit.
TRAJECTORY_WORDS = {"ate_aligned_": ("ATE aligned", "m"), "ate_": ("ATE", "m"), "rpe_trans_m_": ("RPE trans", "m"),
                    "rpe_rot_deg_": ("RPE rot", "°")}
TRAJECTORY_HEADERS = {"trajectory": "trajectory", "poses": "poses", "localisation": "localisation (m + rad)",
                      "localisation_thesis_clamp": "localisation, thesis clamp",
                      "kitti_t_rel_percent": "KITTI drift (%)",
                      "kitti_r_rel_deg_per_100m": "KITTI rot. drift (°/100 m)", "kitti_segments": "KITTI segments"}


def trajectory_header(key: str) -> str:
    """The header a person reads for the trajectory score ``key``: ``ate_aligned_rmse`` → ``ATE aligned rmse (m)``."""
    if key in TRAJECTORY_HEADERS:
        return TRAJECTORY_HEADERS[key]
    for prefix, (words, unit) in TRAJECTORY_WORDS.items():
        if key.startswith(prefix):
            return f"{words} {key[len(prefix):]} ({unit})"
    return key.replace("_", " ")


def trajectory_table(pairs: dict[str, TrajectoryPair], title: str) -> Table:
    """Every trajectory score of each pair (``{name: pair}``), one row each (evo's full statistics in the CSV)."""
    rows = [{"trajectory": name, **pair.score().flat()} for name, pair in pairs.items()]
    keys = [k for k in rows[0] if k != "trajectory"] if rows else list(TRAJECTORY_SHOWN)
    table = Table(title, [Column("trajectory", "trajectory")] + [Column(k, trajectory_header(k)) for k in keys], rows)
    table.notes.extend(f"{name}: {pair.left_out()}" for name, pair in pairs.items() if pair.left_out())
    table.notes.append("localisation: thesis accuracy (m + rad, ‖t_X‖ + acos((tr R_X − 1)/2), the angle computed "
                       "as atan2(|sin|, cos), exact near 0 and π); localisation_thesis_clamp: acos argument "
                       "clamped to [0, 1] as the thesis's code did (errors above 90° count as π/2)")
    table.notes += [f"{name}: {pair.summary()}" for name, pair in pairs.items()]
    for name, pair in pairs.items():
        drift = pair.score().drift
        if drift is not None and drift.overall is None:
            table.notes.append(f"{name}: {drift.note}")
    return table


def map_table(scores: dict[str, MapScores], title: str) -> Table:
    columns = [Column("map", "map"), Column("chamfer_m2", "chamfer (m²)"), Column("accuracy_m", "accuracy (m)"),
               Column("completeness_m", "completeness (m)"), Column("map_points", "map points"),
               Column("gt_points", "gt points")]
    return Table(title, columns, [{"map": name, **s.as_dict()} for name, s in scores.items()])


def write_table_csv(table: Table, path: Path, force: bool = False) -> Path:
    check_outputs([path], force)
    return write_text_atomic(path, table.to_csv(), force=True)


@dataclass
class Report:
    table_5_1: Table
    table_5_2: Table
    written: list[Path]
    table_5_3: Table | None = None
    per_drive: Table | None = None
    table_5_2_long: Table | None = None  # SLAM over whole drives (slam-long/), when there is any
    table_5_2_correlation: Table | None = None  # which depth metric of Table 5.2's rows predicts localisation


PER_DRIVE_KEYS = ("poses", "failed", "localisation", "ate_rmse_m", "rpe_rmse_m", "rpe_rmse_deg", "kitti_t_rel_percent",
                  "kitti_r_rel_deg_per_100m", "path_m", "mae_mm", "rmse_mm", "imae_per_km", "irmse_per_km",
                  "normal_mean_deg", "normal_median_deg", "p2p_mean_m", "p2p_rmse_m", "flying_share", "surface_frames",
                  "frames", "odometry", "mapper", "solver", "association", "voxel_size", "beams", "pairing")


def per_drive_table(results: list) -> Table:
    """Every figure of every row of Table 5.2 on every test drive and training seed (``seed``: that of the run
    behind the layer, empty for layers without one; ``results/table_5_2_per_drive.csv``)."""
    columns = [Column("method", "method"), Column("layer", "layer"), Column("seed", "seed"),
               Column("drive", "drive")] + [Column(k, k) for k in PER_DRIVE_KEYS]
    rows = [{"method": r.label, "layer": seed_layer(r, seed), "seed": seed, "drive": drive, **values}
            for r in results for seed, drive, values in r.per_drive_rows()]
    return Table("Table 5.2 per drive", columns, rows)


def _depth_example_rows(ws: Workspace, results: list[LayerResult], drive: str):
    """(rgb, rows) for the middle frame of ``drive``: one row per model layer that has depth."""
    from dcslam.io.drive import DriveFile, read_layer_for

    models = [r for r in results if r.depth and r.layer not in ("sparse", "dense")]
    if not models:
        return None, []
    rows = []
    with DriveFile(drive_file(ws, drive)) as d:
        i = len(d) // 2
        rgb, sparse, dense = d.rgb(i), d.depth("sparse", i), d.depth("dense", i)
        for result in models:
            layer = resolve_layer(ws, result.layer)
            pred = read_layer_for(d, layer.source(drive)).depth[i]
            rows.append((f"{result.label} ({result.layer})", sparse, pred, dense))
    return rgb, rows


def table_5_2_correlation(results: list, drives: list[str], failure_threshold: float = FAILURE_THRESHOLD) -> Table:
    """The rank correlation of each depth metric with localisation over every (row, drive) pair of Table 5.2
    (:func:`dcslam.report.correlation_table.correlation_table`)."""
    from dcslam.report.correlation_table import correlation_table

    return correlation_table(
        [(f"{r.label} ({r.layer})", r) for r in results],
        f"Table 5.2: depth metrics against localisation over rows × {len(drives)} test drive(s)", failure_threshold,
        depth_note="MAE / RMSE: against the annotated depth over every frame; " + (
            surface_note(results) or "no surface errors scored"))


def build_report(ws: Workspace, drives: list[str], out_dir: Path | None = None, force: bool = False,
                 devkit_exact: bool = False, max_time_diff: float = EVO_MAX_TIME_DIFF_S,
                 failure_threshold: float = FAILURE_THRESHOLD) -> Report:
    """Compute Tables 5.1, 5.2 (with its per-drive table), 5.2 over whole drives (when ``slam-long/`` holds SLAM runs;
    its Markdown follows Table 5.2's in ``table_5_2.md``), the rank correlation of Table 5.2's depth metrics with
    localisation (``table_5_2_correlation``) and 5.3 over ``drives`` and write them (Markdown + CSV) with the
    figures."""
    from dcslam.report.plots import plot_depth_examples, plot_trajectories
    from dcslam.io.drive import DriveFile

    out_dir = Path(out_dir) if out_dir else ws.results
    thesis = thesis_figures()
    runs = list_runs(ws)
    t51 = table_5_1(runs, thesis)
    results = table_5_2_results(ws, runs, drives, devkit_exact, max_time_diff, failure_threshold)
    t52 = table_5_2(results, thesis, drives, devkit_exact)
    t53, per_drive = table_5_3(thesis), per_drive_table(results)
    ranks = table_5_2_correlation(results, drives, failure_threshold)
    rgb, examples = _depth_example_rows(ws, results, drives[0])
    tables = {"table_5_1": t51, "table_5_2": t52, "table_5_2_per_drive": per_drive, "table_5_2_correlation": ranks,
              "table_5_3": t53}
    long_results = table_5_2_long_results(ws, runs, drives, max_time_diff)
    t52_long = table_5_2_long(long_results, drives) if long_results else None
    if t52_long is not None:  # printed after Table 5.2 in its Markdown file; CSVs of its own
        tables.update(table_5_2_long=t52_long, table_5_2_long_per_drive=per_drive_table(long_results))
    outputs = [out_dir / f"{name}.{ext}" for name in tables for ext in ("md", "csv")]
    plots = [out_dir / f"trajectories_{drive}.png" for drive in drives]
    examples_path = out_dir / "depth_examples.png"
    check_outputs(outputs + plots + ([examples_path] if examples else []), force)

    written = []
    for name, table in tables.items():
        markdown = table.to_markdown()
        if name == "table_5_2" and t52_long is not None:
            markdown += "\n" + t52_long.to_markdown()
        written.append(write_text_atomic(out_dir / f"{name}.md", markdown, force=True))
        written.append(write_text_atomic(out_dir / f"{name}.csv", table.to_csv(), force=True))
    for drive, path in zip(drives, plots):
        with DriveFile(drive_file(ws, drive)) as d:
            T_gt = d.poses
        estimates = {f"{r.label} ({r.layer})": r.pairs[drive].T_est for r in results if drive in r.pairs}
        written.append(plot_trajectories(path, T_gt, estimates, title=f"{drive}: top view", force=True))
    if examples:
        written.append(plot_depth_examples(examples_path, examples, rgb=rgb, force=True))
    return Report(table_5_1=t51, table_5_2=t52, written=written, table_5_3=t53, per_drive=per_drive,
                  table_5_2_long=t52_long, table_5_2_correlation=ranks)

