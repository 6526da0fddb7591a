"""Table 5.2 of the thesis over the test drives, with the spread that makes its rows comparable.

For the four trained recipes, sparse and dense depth without a model, and beyond the thesis IP-Basic and each model
after its best filter (the filtered layer of that model with the lowest localisation accuracy): the thesis's
localisation accuracy, MAE / RMSE / iMAE / iRMSE (KITTI devkit, see :data:`dcslam.eval.depth.DEPARTURES_TEXT`),
ATE / RPE (evo) and KITTI drift, each as the mean over the test drives with its spread (:mod:`dcslam.report.spread`),
the median localisation, the failure count and whether the row differs from sparse depth beyond the spread. Every
row carries the settings of the SLAM runs behind it. Every number of ours is computed here from files; a row whose
inputs are missing is kept, with its values empty and a note naming what is missing.
"""
from __future__ import annotations

import json

from dcslam.errors import DcslamError
from dcslam.eval.trajectory import EVO_MAX_TIME_DIFF_S
from dcslam.report.layers import find_layer
from dcslam.report.results import (DRIFT_KEYS, FAILURE_THRESHOLD, SPREAD_COLUMNS, LayerResult, SeedResults,
                                   csv_suffixes, score_layer, seeded, surface_note, with_seed_columns)
from dcslam.report.seeds import seed_groups
from dcslam.report.spread import TWO_LEVEL_METHOD
from dcslam.report.tables import IP_BASIC, RECIPES, Column, RunSummary, Table
from dcslam.workspace import Workspace

#: The columns of Table 5.2's Markdown (its CSV holds every figure of :data:`dcslam.report.results.SPREAD_COLUMNS`).
TABLE_5_2_COLUMNS = [
    Column("method", "method"), Column("layer", "layer"), Column("drives", "drives"), Column("failures", "failed"),
    Column("localisation_text", "localisation accuracy"), Column("localisation_median_text", "median"),
    Column("thesis_localisation_text", "thesis"), Column("vs_sparse", "vs sparse"),
    Column("mae_mm_text", "MAE (mm)"), Column("thesis_mae_text", "thesis MAE"),
    Column("rmse_mm_text", "RMSE (mm)"), Column("thesis_rmse_text", "thesis RMSE"),
    Column("imae_per_km_text", "iMAE (1/km)"), Column("irmse_per_km_text", "iRMSE (1/km)"),
    Column("ate_rmse_m_text", "ATE RMSE (m)"), Column("rpe_rmse_m_text", "RPE RMSE (m)"),
    Column("rpe_rmse_deg_text", "RPE RMSE (°)"), Column("kitti_t_rel_percent_text", "t_rel (%)"),
    Column("kitti_r_rel_deg_per_100m_text", "r_rel (°/100 m)"), Column("slam_settings", "SLAM settings"),
    Column("notes", "why —")]
SEEDS_NOTE = ("rows over several training seeds (seeds: their number; layer: the first seed's run and the seeds): "
              "every figure is the mean over seeds × test drives with its 95 % interval [low, high] from a "
              f"{TWO_LEVEL_METHOD}; seed-to-seed std: the std of the per-seed mean localisations (the spread from "
              "training alone); failed: failed runs of all seeds × drives; vs sparse: whether the same two-level "
              "interval of the per-run differences from sparse depth (paired by drive) excludes zero. Rows without "
              "seeds: the t-interval over drives")


def filters_of(ws: Workspace, source_layer: str) -> list[str]:
    """Names of the filtered layers made from ``source_layer`` (by their ``config.json``)."""
    names = []
    if ws.filtered.is_dir():
        for folder in sorted(ws.filtered.iterdir()):
            config = folder / "config.json"
            if config.exists():
                try:
                    settings = json.loads(config.read_text()).get("settings", {})
                except json.JSONDecodeError:
                    raise DcslamError(f"{config}: not valid JSON") from None
                if settings.get("source_layer") == source_layer:
                    names.append(folder.name)
    return names


def imported_layers(ws: Workspace) -> list[str]:
    """Names of the layers ``dcslam import`` brought in (``predictions/<name>/config.json`` of stage ``import``)."""
    names = []
    for config in sorted(ws.predictions.glob("*/config.json")) if ws.predictions.is_dir() else []:
        try:
            stage = json.loads(config.read_text()).get("stage")
        except (json.JSONDecodeError, AttributeError):
            raise DcslamError(f"{config}: not a JSON object") from None
        if stage == "import":
            names.append(config.parent.name)
    return names


def score_runs(ws: Workspace, label: str, runs: list[RunSummary], drives: list[str], suffix: str = "",
               **options) -> "LayerResult | SeedResults":
    """The row of ``runs`` (the seeds of one run, :func:`dcslam.report.seeds.seed_groups`): layer
    ``<run name><suffix>`` of each run scored by :func:`score_layer` (``options``), one :class:`LayerResult` for a
    single run, a :class:`SeedResults` over several."""
    scored = []
    for run in runs:
        result = score_layer(ws, label, f"{run.name}{suffix}", drives, **options)
        result.seed = run.seed
        scored.append(result)
    return scored[0] if len(scored) == 1 else SeedResults(label, scored)


def table_5_2_results(ws: Workspace, runs: list[RunSummary], drives: list[str], devkit_exact: bool = False,
                      max_time_diff: float = EVO_MAX_TIME_DIFF_S,
                      failure_threshold: float = FAILURE_THRESHOLD) -> list:
    """Every row of Table 5.2 as a :class:`LayerResult` (models, no model, IP-Basic, models after best filter); the
    runs of one recipe trained with several seeds (:func:`dcslam.report.seeds.seed_groups`) as one
    :class:`SeedResults`."""
    options = dict(devkit_exact=devkit_exact, max_time_diff=max_time_diff, failure_threshold=failure_threshold)

    def score(label, name):
        return score_layer(ws, label, name, drives, devkit_exact, max_time_diff, failure_threshold)

    groups = seed_groups(runs)
    results = []
    for recipe in RECIPES:
        ours = [g for g in groups if g[0].recipe == recipe]
        if not ours:
            results.append(LayerResult(label=recipe, layer="—", missing=[f"no run trained as {recipe}"]))
        results += [score_runs(ws, recipe, group, drives, **options) for group in ours]
    results += [score_runs(ws, g[0].recipe, g, drives, **options)  # e.g. the pose loss
                for g in groups if g[0].recipe not in RECIPES]
    results.append(score("sparse depth", "sparse"))
    results.append(score("dense depth", "dense"))
    found = [name for name in IP_BASIC if find_layer(ws, name) is not None]
    results += [score("IP-Basic", name) for name in found] or [
        LayerResult(label="IP-Basic", layer="—", missing=[f"no layer {' or '.join(IP_BASIC)} (dcslam predict)"])]
    results += [score(f"{name} (imported)", name) for name in imported_layers(ws)]  # other methods' predictions
    for group in groups:
        run, label = group[0], f"{group[0].recipe} + best filter"
        names = filters_of(ws, run.name)
        if len(group) == 1:
            candidates = [score(label, name) for name in names]
            for candidate in candidates:
                candidate.seed = run.seed
        else:  # a filter every seed's run went through, named after the run (<run><suffix>)
            suffixes = [name[len(run.name):] for name in names if name.startswith(run.name)]
            suffixes = [x for x in suffixes if all(f"{r.name}{x}" in filters_of(ws, r.name) for r in group[1:])]
            candidates = [score_runs(ws, label, group, drives, suffix, **options) for suffix in suffixes]
        if not candidates and run.recipe not in RECIPES:
            continue  # recipes beyond the thesis's (the pose loss) are not filtered by the reproduction
        scored = [c for c in candidates if c.localisation is not None and c.depth]
        if scored:
            results.append(min(scored, key=lambda c: c.localisation))
        else:
            what = "filtered layers with slam results" if candidates else "filtered layer"
            results.append(LayerResult(label=label, layer="—",
                                       missing=[f"no {what} of {run.name} (dcslam filter, dcslam slam)"]))
    return results


def most_common_settings(rows: list[dict]) -> dict:
    """For each setting, the value most rows were made with (the first row's on a tie)."""
    common = {}
    for key in sorted(set().union(*rows)) if rows else []:
        values = [repr(r.get(key)) for r in rows]
        best = max(values, key=values.count)
        common[key] = next(r.get(key) for r in rows if repr(r.get(key)) == best)
    return {k: v for k, v in common.items() if v is not None}


def settings_text(settings: dict) -> str:
    return ", ".join(f"{k}={settings[k]}" for k in sorted(settings))


def annotate(row: dict, result: LayerResult, settings: dict | None, common: dict) -> dict:
    """Complete a table row of ``result``: ``slam_settings`` (how its SLAM ``settings`` differ from the ``common``
    ones; absent without settings) and ``notes`` (what is missing, why there is no drift or aligned ATE)."""
    if settings is not None:
        own = {k: settings.get(k) for k in set(common) | set(settings) if common.get(k) != settings.get(k)}
        row["slam_settings"] = "as the others" if not own else "differs: " + settings_text(own)
    notes = [n for n in (row.get("missing"), row.get("drift_note")) if n]
    if result.pairs and row.get("ate_rmse_m") is None:
        notes.append("aligned ATE undefined on some drive (degenerate positions)")
    row["notes"] = "; ".join(notes) or None
    return row


def table_5_2(results: list[LayerResult], thesis: dict, drives: list[str], devkit_exact: bool = False) -> Table:
    """Table 5.2: one row per result, each figure as mean ± the 95 % t-interval's half-width over the test drives,
    with the median localisation, the failure count and whether the row differs from sparse depth beyond the
    spread; the CSV holds every mean, std, interval and median. Rows whose SLAM runs were made with other settings
    than the others show the difference in ``SLAM settings``; a row whose drives were run differently fails."""
    figures = thesis.get("table_5_2", {}).get("rows", {})
    table = Table(f"Table 5.2 — {len(drives)} test drive(s) ({', '.join(drives)})",
                  with_seed_columns(TABLE_5_2_COLUMNS, seeded(results)))
    table.csv_columns = [Column(k, k) for k in ("method", "layer", "drives", *(("seeds",) if seeded(results) else ()),
                                                "failures", "vs_sparse")] + [
        Column(f"{c.key}{suffix}", "") for c in SPREAD_COLUMNS for suffix in csv_suffixes(seeded(results))] + [
        Column(f"{k}_drives", "") for k in DRIFT_KEYS] + [
        Column(f"thesis_{k}", "") for k in ("localisation", "mae", "rmse")] + [
        Column("slam_settings", ""), Column("missing", ""), Column("notes", "")]
    reference = next((r for r in results if r.layer == "sparse"), None)
    settings = {id(r): r.run_settings() for r in results if r.pairs}
    common = most_common_settings(list(settings.values()))
    for result in results:
        theirs = figures.get(result.label, {})
        row = {**result.row(reference), **{f"thesis_{k}": v for k, v in theirs.items()}}
        for k in ("localisation", "mae", "rmse"):
            row.setdefault(f"thesis_{k}_text", "x" if k in theirs and theirs[k] is None else
                           (None if theirs.get(k) is None else f"{theirs[k]:g}"))
        table.rows.append(annotate(row, result, settings.get(id(result)), common))
    threshold = results[0].failure_threshold if results else FAILURE_THRESHOLD
    single_runs = all(sum(r.label == recipe for r in results) <= 1 for recipe in RECIPES)
    table.notes += [  # short on purpose: how each column is computed is in docs/metrics.md
        "localisation accuracy: the thesis's metric (m + rad, lower is better); every figure: mean over the test "
        "drives ± the half-width of its 95 % t-interval (std, interval and median in the CSV)",
        f"failed: drives flagged suspect by the SLAM (its step verdicts, its drift bound, or for completed depth a "
        f"companion run on the measured LiDAR pixels it departs from) or with a localisation error above "
        f"{threshold:g}; vs sparse: "
        "paired 95 % t-interval of the per-drive differences",
        "MAE, RMSE, iMAE, iRMSE: " + ("exactly as the KITTI devkit" if devkit_exact else
                                     "KITTI devkit with two departures (--devkit-exact removes them)"),
        "ATE, RPE: as evo computes them; t_rel / r_rel: KITTI odometry devkit over 100-800 m segments",
        (SEEDS_NOTE if seeded(results) else
         "trained rows: one training run per recipe, so their spread is across test drives only" if single_runs
         else "trained rows: each training run of a recipe is its own row"),
        "thesis columns: the thesis's figures (dcslam/report/thesis_tables.json); x: not computed there; —: no "
        "such row",
        surface_note(results),
        "how each column is computed, and where dcslam departs from the thesis and the devkits: docs/metrics.md",
        f"SLAM settings of the rows (those of most rows; a row made otherwise says how in SLAM settings): "
        f"{settings_text(common) or 'none recorded'}"]
    table.notes = [n for n in table.notes if n]
    return table
