"""Tables 5.1 and 5.2 of the thesis, assembled from whatever a workspace holds, as Markdown and CSV.

* Table 5.1 — validation of each training recipe: for each run in ``runs/``, the validation record of its best
  checkpoint (the epoch with the lowest validation value of the loss it trained with: chamfer for chamfer runs,
  MSE for MSE runs — the checkpoint ``model.pt`` keeps), with chamfer (m²), MSE (m²), MAE and RMSE (mm).
* Table 5.2 — over the test drives: the thesis's localisation accuracy (mean over drives of the per-drive mean),
  MAE / RMSE / iMAE / iRMSE (KITTI devkit, mean over all test images) and ATE / RPE (evo), for the four trained
  recipes, sparse and dense depth without a model, and beyond the thesis IP-Basic and each model after its best
  filter (the filtered layer of that model with the lowest localisation accuracy).

Every number of ours is computed here from files; the thesis's figures come from ``thesis_tables.json`` (``—``
where unknown). A row whose inputs are missing is kept, with its values empty and a note naming what is missing.
"""
from __future__ import annotations

import csv
import functools
import io
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from dcslam.depth.models import IP_BASIC_NAMES
from dcslam.depth.recipes import recipe_label as recipe_of
from dcslam.depth.recipes import selection_key
from dcslam.errors import DcslamError
from dcslam.eval.depth import DepthErrors, mean_errors
from dcslam.report.layers import TrajectoryPair, find_layer, score_layer_depth, score_layer_trajectories
from dcslam.workspace import Workspace

THESIS_FIGURES = Path(__file__).with_name("thesis_tables.json")
RECIPES = ("chamfer single-frame", "chamfer multi-frame", "MSE sparse mask", "MSE dense mask")
IP_BASIC = IP_BASIC_NAMES  # the classical completers that make the IP-Basic row


@dataclass(frozen=True)
class Column:
    key: str
    header: str
    fmt: str = "{:.4g}"


@dataclass
class Table:
    """Rows of values keyed by column; ``None`` prints as ``—``."""

    title: str
    columns: list[Column]
    rows: list[dict] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def cell(self, row: dict, column: Column) -> str:
        value = row.get(column.key)
        if value is None or value == "":
            return "—"
        if isinstance(value, float):
            return "inf" if math.isinf(value) else column.fmt.format(value)
        return str(value)

    def to_markdown(self) -> str:
        lines = [f"### {self.title}", "", "| " + " | ".join(c.header for c in self.columns) + " |",
                 "| " + " | ".join("---" for _ in self.columns) + " |"]
        lines += ["| " + " | ".join(self.cell(r, c).replace("|", "/") for c in self.columns) + " |" for r in self.rows]
        if self.notes:
            lines += [""] + [f"- {note}" for note in self.notes]
        return "\n".join(lines) + "\n"

    def to_csv(self) -> str:
        out = io.StringIO()
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow([c.key for c in self.columns])
        for row in self.rows:
            writer.writerow(["" if row.get(c.key) is None else row.get(c.key) for c in self.columns])
        return out.getvalue()


def thesis_figures(path: Path = THESIS_FIGURES) -> dict:
    try:
        return json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise DcslamError(f"{path}: cannot read the thesis's figures ({exc})") from None


# ---------------------------------------------------------------------------------------------------- runs


@dataclass(frozen=True)
class RunSummary:
    name: str
    recipe: str
    selected_by: str
    best: dict            # the validation record of the best checkpoint
    validations: int


def read_run(run_dir: Path) -> RunSummary:
    """Summarise one run folder. Fails when it has no config, no metrics or no validation record."""
    config_path, metrics_path = run_dir / "config.json", run_dir / "metrics.jsonl"
    for path in (config_path, metrics_path):
        if not path.exists():
            raise DcslamError(f"{path} not found; run `dcslam train` (to completion) first")
    try:
        settings = json.loads(config_path.read_text()).get("settings", {})
    except json.JSONDecodeError as exc:
        raise DcslamError(f"{config_path}: not valid JSON ({exc})") from None
    validations = []
    for number, line in enumerate(metrics_path.read_text().splitlines(), 1):
        if not line.strip():
            continue
        try:
            record = json.loads(line)
        except json.JSONDecodeError:
            raise DcslamError(f"{metrics_path}:{number}: not a JSON object") from None
        if record.get("kind") == "val":
            validations.append(record)
    if not validations:
        raise DcslamError(f"{metrics_path}: no validation metrics (no \"kind\": \"val\" line); train with "
                          "validation drives, for at least one epoch")
    key = selection_key(settings.get("loss"))
    usable = [r for r in validations if isinstance(r.get(key), (int, float))]
    if not usable:
        raise DcslamError(f"{metrics_path}: validation records have no {key!r} value")
    best = min(usable, key=lambda r: r[key])
    return RunSummary(name=run_dir.name, recipe=recipe_of(settings), selected_by=key, best=best,
                      validations=len(validations))


def list_runs(ws: Workspace) -> list[RunSummary]:
    """Every run folder of the workspace (those with a ``config.json``), sorted by name."""
    if not ws.runs.is_dir():
        return []
    return [read_run(d) for d in sorted(ws.runs.iterdir()) if d.is_dir() and (d / "config.json").exists()]


def table_5_1(runs: list[RunSummary], thesis: dict) -> Table:
    columns = [Column("recipe", "recipe"), Column("run", "run"), Column("epoch", "best epoch"),
               Column("chamfer", "chamfer (m²)"), Column("thesis_chamfer", "thesis chamfer"),
               Column("mse", "MSE (m²)"), Column("thesis_mse", "thesis MSE"),
               Column("mae_mm", "MAE (mm)", "{:.1f}"), Column("thesis_mae", "thesis MAE"),
               Column("rmse_mm", "RMSE (mm)", "{:.1f}"), Column("thesis_rmse", "thesis RMSE")]
    figures = thesis.get("table_5_1", {}).get("rows", {})
    table = Table("Table 5.1 — validation of each training recipe (best checkpoint of each run)", columns)
    for recipe in RECIPES + tuple(sorted({r.recipe for r in runs} - set(RECIPES))):
        ours = [r for r in runs if r.recipe == recipe]
        theirs = {f"thesis_{k}": v for k, v in figures.get(recipe, {}).items()}
        if not ours:
            table.rows.append({"recipe": recipe, "run": "missing: no run", **theirs})
        for run in ours:
            table.rows.append({"recipe": recipe, "run": run.name, "epoch": run.best.get("epoch"),
                               **{k: run.best.get(k) for k in ("chamfer", "mse", "mae_mm", "rmse_mm")}, **theirs})
    table.notes.append("best checkpoint: lowest validation chamfer for chamfer runs, lowest validation MSE for MSE "
                       "runs (the model.pt each run keeps)")
    return table


# ---------------------------------------------------------------------------------------------- Table 5.2


@dataclass
class LayerResult:
    """Scores of one depth layer over the test drives (``None`` where its inputs are missing)."""

    label: str
    layer: str
    depth: DepthErrors | None = None
    pairs: dict[str, TrajectoryPair] = field(default_factory=dict)
    missing: list[str] = field(default_factory=list)

    @functools.cached_property
    def scores(self) -> list:
        """:class:`~dcslam.eval.trajectory.TrajectoryScores` of each drive (in ``pairs`` order)."""
        return [p.score() for p in self.pairs.values()]

    @property
    def localisation(self) -> float | None:
        if not self.pairs:
            return None
        return sum(s.localisation for s in self.scores) / len(self.scores)

    def row(self) -> dict:
        row = {"method": self.label, "layer": self.layer, "localisation": self.localisation,
               "missing": "; ".join(self.missing) or None}
        if self.depth is not None:
            row.update(mae_mm=self.depth.mae_mm, rmse_mm=self.depth.rmse_mm, imae_per_km=self.depth.imae_per_km,
                       irmse_per_km=self.depth.irmse_per_km)
        if self.pairs:
            scores = self.scores
            aligned = [s.ate_aligned.rmse for s in scores if s.ate_aligned is not None]
            row["ate_rmse_m"] = sum(aligned) / len(aligned) if len(aligned) == len(scores) else None
            rpe = [s.rpe_trans_m.rmse for s in scores if s.rpe_trans_m is not None]
            row["rpe_rmse_m"] = sum(rpe) / len(rpe) if len(rpe) == len(scores) else None
            rot = [s.rpe_rot_deg.rmse for s in scores if s.rpe_rot_deg is not None]
            row["rpe_rmse_deg"] = sum(rot) / len(rot) if len(rot) == len(scores) else None
        return row


def score_layer(ws: Workspace, label: str, layer_name: str, drives: list[str]) -> LayerResult:
    """Depth and trajectory scores of a layer over ``drives``; missing inputs are recorded, bad ones fail."""
    result = LayerResult(label=label, layer=layer_name)
    layer = find_layer(ws, layer_name)
    if layer is None:
        result.missing.append(f"no layer {layer_name!r} (dcslam predict / filter)")
    else:
        absent = [d for d in drives if layer.folder is not None and not Path(layer.source(d)).exists()]
        if absent:
            result.missing.append(f"depth of {len(absent)} test drive(s) in {layer.folder}")
        else:
            per_drive = score_layer_depth(ws, layer, drives)
            result.depth = mean_errors(e for frames in per_drive.values() for e in frames)
    absent = [d for d in drives if not (ws.slam / layer_name / f"{d}.txt").exists()]
    if absent:
        result.missing.append(f"slam/{layer_name}/ for {len(absent)} test drive(s) (dcslam slam)")
    else:
        result.pairs = score_layer_trajectories(ws, layer_name, drives)
    return result


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


def table_5_2_results(ws: Workspace, runs: list[RunSummary], drives: list[str]) -> list[LayerResult]:
    """Every row of Table 5.2 as a :class:`LayerResult` (models, no model, IP-Basic, models after best filter)."""
    results = []
    for recipe in RECIPES:
        ours = [r for r in runs if r.recipe == recipe]
        if not ours:
            results.append(LayerResult(label=recipe, layer="—", missing=[f"no run trained as {recipe}"]))
        results += [score_layer(ws, recipe, run.name, drives) for run in ours]
    results.append(score_layer(ws, "sparse depth", "sparse", drives))
    results.append(score_layer(ws, "dense depth", "dense", drives))
    found = [name for name in IP_BASIC if find_layer(ws, name) is not None]
    results += [score_layer(ws, "IP-Basic", name, drives) for name in found] or [
        LayerResult(label="IP-Basic", layer="—", missing=[f"no layer {' or '.join(IP_BASIC)} (dcslam predict)"])]
    for run in runs:
        candidates = [score_layer(ws, f"{run.recipe} + best filter", name, drives) for name in filters_of(ws, run.name)]
        scored = [c for c in candidates if c.localisation is not None and c.depth is not None]
        if scored:
            results.append(min(scored, key=lambda c: c.localisation))
        else:
            what = "filtered layers with slam results" if candidates else "filtered layer"
            results.append(LayerResult(label=f"{run.recipe} + best filter", layer="—",
                                       missing=[f"no {what} of {run.name} (dcslam filter, dcslam slam)"]))
    return results


def table_5_2(results: list[LayerResult], thesis: dict, drives: list[str]) -> Table:
    columns = [Column("method", "method"), Column("layer", "layer"),
               Column("localisation", "localisation accuracy", "{:.4f}"), Column("thesis_localisation", "thesis"),
               Column("mae_mm", "MAE (mm)", "{:.1f}"), Column("thesis_mae", "thesis MAE"),
               Column("rmse_mm", "RMSE (mm)", "{:.1f}"), Column("thesis_rmse", "thesis RMSE"),
               Column("imae_per_km", "iMAE (1/km)", "{:.2f}"), Column("irmse_per_km", "iRMSE (1/km)", "{:.2f}"),
               Column("ate_rmse_m", "ATE RMSE (m)", "{:.3f}"), Column("rpe_rmse_m", "RPE RMSE (m)", "{:.3f}"),
               Column("rpe_rmse_deg", "RPE RMSE (°)", "{:.3f}"), Column("missing", "missing inputs")]
    figures = thesis.get("table_5_2", {}).get("rows", {})
    table = Table(f"Table 5.2 — test drives ({', '.join(drives)})", columns)
    for result in results:
        theirs = figures.get(result.label, {})
        table.rows.append({**result.row(), **{f"thesis_{k}": v for k, v in theirs.items()}})
    table.notes += [
        "localisation accuracy: mean over poses of ‖t_X‖ + acos((tr R_X − 1)/2), X = T_gt⁻¹ T_est (m + rad), "
        "averaged over the test drives; lower is better",
        "MAE, RMSE, iMAE, iRMSE: KITTI devkit (prediction holes filled by its background interpolation), "
        "per image, averaged over all test images",
        "ATE: evo APE translation after SE(3) Umeyama alignment; RPE: evo, consecutive frames; RMSE averaged over "
        "the test drives",
        "thesis columns: the thesis's own figures (dcslam/report/thesis_tables.json; — where not filled in)"]
    return table
