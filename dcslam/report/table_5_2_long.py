"""Table 5.2 over whole drives: SLAM of a few depth layers over every frame of each test drive, not only the first
30 the thesis scored, scored as the field scores odometry.

The thesis's Table 5.2 runs SLAM on the first 30 frames of each drive (about 30 m), too short for the KITTI odometry
devkit's drift (segments of 100 … 800 m). ``dcslam reproduce`` therefore also runs SLAM over whole test drives for
the layers its profile names, into ``slam-long/<layer>/<drive>.*`` (:attr:`dcslam.workspace.Workspace.slam_long`);
this table scores those runs: per row the number of drives, their frames and path length, failures, the thesis's
localisation (mean ± 95 % half-width, median), whether the row differs from sparse depth beyond the spread, ATE /
RPE (evo) and the KITTI drift where the drives are long enough; where they are not, the row says so. Depth errors
are not repeated here: they are the same layers' as in Table 5.2.
"""
from __future__ import annotations

import math
from pathlib import Path

from dcslam.eval.trajectory import EVO_MAX_TIME_DIFF_S
from dcslam.report.table_5_2 import (SEEDS_NOTE, TABLE_5_2_COLUMNS, SeedResults, annotate, csv_suffixes,
                                     most_common_settings, score_layer, seeded, settings_text, with_seed_columns)
from dcslam.report.tables import IP_BASIC, Column, RunSummary, Table
from dcslam.workspace import Workspace

_SHARED = {c.key: c for c in TABLE_5_2_COLUMNS}  # the columns this table shares with Table 5.2, as it heads them
LONG_COLUMNS = [_SHARED[k] for k in ("method", "layer", "drives")] + [
    Column("frames_text", "frames per drive"), Column("path_text", "path per drive (m)")] + [
    _SHARED[k] for k in ("failures", "localisation_text", "localisation_median_text", "vs_sparse", "ate_rmse_m_text",
                         "rpe_rmse_m_text", "rpe_rmse_deg_text", "kitti_t_rel_percent_text",
                         "kitti_r_rel_deg_per_100m_text", "slam_settings", "notes")]
FIGURES = ("localisation", "ate_rmse_m", "rpe_rmse_m", "rpe_rmse_deg", "kitti_t_rel_percent",
           "kitti_r_rel_deg_per_100m")


def long_layers(root: Path) -> list[str]:
    """The layers with SLAM outputs under ``root`` (``slam-long/``): sparse, dense, IP-Basic first, then by name."""
    if not root.is_dir():
        return []
    names = sorted(p.name for p in root.iterdir() if p.is_dir() and any(p.glob("*.txt")))
    first = ["sparse", "dense", *IP_BASIC]
    return [n for n in first if n in names] + [n for n in names if n not in first]


def layer_label(layer: str, runs: list[RunSummary]) -> str:
    """The row label of a layer, as Table 5.2 names it (a run by its recipe)."""
    fixed = {"sparse": "sparse depth", "dense": "dense depth", **{name: "IP-Basic" for name in IP_BASIC}}
    if layer in fixed:
        return fixed[layer]
    return next((run.recipe for run in runs if run.name == layer), layer)


def table_5_2_long_results(ws: Workspace, runs: list[RunSummary], drives: list[str],
                           max_time_diff: float = EVO_MAX_TIME_DIFF_S) -> list:
    """A :class:`LayerResult` (trajectories only) for every layer with whole-drive SLAM outputs in ``slam-long/``,
    the layers of the seeds of one run (:func:`dcslam.report.seeds.seed_groups`) as one :class:`SeedResults`; empty
    when there are none. A layer lacking some test drive is kept, with what is missing."""
    from dcslam.report.seeds import seed_groups

    settings = {run.name: run.settings for run in runs}
    seeds = {run.name: run.seed for run in runs}
    results = []
    for group in seed_groups(long_layers(ws.slam_long), name=lambda layer: layer,
                             settings=lambda layer: settings.get(layer, {"layer": layer})):
        scored = []
        for layer in group:
            result = score_layer(ws, layer_label(layer, runs), layer, drives, max_time_diff=max_time_diff,
                                 slam_root=ws.slam_long, depth=False)
            result.seed = seeds.get(layer)
            scored.append(result)
        results.append(scored[0] if len(scored) == 1 else SeedResults(scored[0].label, scored))
    return results


def _range_text(values: list[float], fmt: str) -> str | None:
    if not values:
        return None
    low, high = min(values), max(values)
    return fmt.format(low) if fmt.format(low) == fmt.format(high) else f"{fmt.format(low)}–{fmt.format(high)}"


def table_5_2_long(results: list, drives: list[str]) -> Table:
    """The long-drive table: one row per result, figures as mean ± the 95 % t-interval's half-width over the test
    drives (the CSV also holds std, interval and median); rows differ from sparse depth only beyond the paired
    interval; a row whose drives are all shorter than 100 m says so instead of a drift.

    A drive fails here only when its run was flagged (rejected or degraded steps): the thesis's error, a mean over
    poses from the start, grows with a drive's length, so Table 5.2's threshold on it (made for 30 frames) does not
    apply."""
    results = [r.with_failure_threshold(math.inf) for r in results]
    table = Table(f"Table 5.2, whole drives — {len(drives)} test drive(s), SLAM over every frame",
                  with_seed_columns(LONG_COLUMNS, seeded(results)))
    table.csv_columns = [Column(k, k) for k in ("method", "layer", "drives", *(("seeds",) if seeded(results) else ()),
                                                "frames_text", "path_text", "failures", "vs_sparse")] + [
        Column(f"{key}{suffix}", "") for key in FIGURES for suffix in csv_suffixes(seeded(results))
    ] + [Column(f"{k}_drives", "") for k in FIGURES[-2:]] + [
        Column("slam_settings", ""), Column("missing", ""), Column("notes", "")]
    reference = next((r for r in results if r.layer == "sparse"), None)
    settings = {id(r): r.run_settings() for r in results if r.pairs}
    common = most_common_settings(list(settings.values()))
    for result in results:
        row = result.row(reference)
        per_drive = [values for _, _, values in result.per_drive_rows()]
        row["frames_text"] = _range_text([r["poses"] for r in per_drive if "poses" in r], "{:d}")
        row["path_text"] = _range_text([r["path_m"] for r in per_drive if r.get("path_m") is not None], "{:.0f}")
        table.rows.append(annotate(row, result, settings.get(id(result)), common))
    table.notes += [
        "SLAM over every frame of each test drive (Table 5.2 runs the first 30, as the thesis did), for the layers "
        "the profile names; localisation accuracy: the thesis's metric (m + rad), which grows with a drive's length, "
        "so compare rows here, not with Table 5.2",
        "every figure: mean over the test drives ± the half-width of its 95 % t-interval; failed: drives whose SLAM "
        "run was flagged suspect (rejected or degraded steps, drift bound, a departure from the companion run on the "
        "measured pixels; no threshold on the thesis's error, which grows with "
        "length); vs sparse: paired t-interval of the per-drive localisation differences",
        "t_rel / r_rel: KITTI odometry devkit drift over 100–800 m segments from every 10th frame, averaged over the "
        "drives long enough; a drive shorter than 100 m has none (notes give the longest path)",
        f"SLAM settings of the rows (those of most rows; a row made otherwise says how in SLAM settings): "
        f"{settings_text(common) or 'none recorded'}"] + ([SEEDS_NOTE] if seeded(results) else [])
    return table
