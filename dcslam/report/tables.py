"""Tables of dcslam (Markdown and CSV) and Tables 5.1 and 5.3 of the thesis (Table 5.2 is
:mod:`dcslam.report.table_5_2`).

* Table 5.1 — validation of each training recipe: for each run in ``runs/``, the validation record of its best
  checkpoint (the epoch with the lowest validation value of the loss it trained with: chamfer for chamfer runs,
  MSE for MSE runs — the checkpoint ``model.pt`` keeps), with chamfer (m²), MSE (m²), MAE and RMSE (mm).
* Table 5.3 — the model authors' own figures, quoted by the thesis.

The thesis's figures come from ``thesis_tables.json``.
"""
from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from dcslam.depth.models import IP_BASIC_NAMES
from dcslam.depth.recipes import recipe_label as recipe_of
from dcslam.depth.recipes import selection_key
from dcslam.errors import DcslamError
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
    csv_columns: list[Column] | None = None  # the CSV's columns when they differ from the Markdown's

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
        columns = self.csv_columns or self.columns
        writer.writerow([c.key for c in columns])
        for row in self.rows:
            writer.writerow(["" if row.get(c.key) is None else row.get(c.key) for c in columns])
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
    seed: int | None = None  # its training seed
    settings: dict = field(default_factory=dict)  # its `dcslam train` settings (config.json)


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
    return RunSummary(name=run_dir.name, recipe=recipe_of(_seed_free(run_dir.name, settings)), selected_by=key,
                      best=best, validations=len(validations), seed=settings.get("seed"), settings=settings)


def _seed_free(name: str, settings: dict) -> dict:
    """``settings`` of run ``name`` with the run it was fine-tuned from named as the recipe names it: the ``k``-th
    seed's run of a recipe (``<run>-s<k>``) starts from the ``k``-th seed's run of its source, which is the source
    recipe's run (``pose-from-chamfer-8-s1`` from ``chamfer-8-s1``: "pose, fine-tuned from chamfer-8")."""
    from pathlib import PurePath

    from dcslam.depth.recipes import init_run
    from dcslam.report.seeds import seed_base

    _, k = seed_base(name)
    source, source_k = seed_base(init_run(settings))
    if k == 0 or source_k != k:
        return settings
    init = PurePath(settings["init"])
    return {**settings, "init": str(init.parent.parent / source / init.name)}


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
    from dcslam.report.seeds import seed_groups

    figures = thesis.get("table_5_1", {}).get("rows", {})
    groups = seed_groups(runs)
    seeded = any(len(g) > 1 for g in groups)
    if seeded:  # one row per seed's run, then the recipe's mean ± std over its seeds
        columns.insert(2, Column("seed", "seed"))
    table = Table("Table 5.1 — validation of each training recipe (best checkpoint of each run)", columns)
    figures_5_1 = ("chamfer", "mse", "mae_mm", "rmse_mm")
    for recipe in RECIPES + tuple(sorted({r.recipe for r in runs} - set(RECIPES))):
        ours = [g for g in groups if g[0].recipe == recipe]
        theirs = {f"thesis_{k}": v for k, v in figures.get(recipe, {}).items()}
        if not ours:
            table.rows.append({"recipe": recipe, "run": "missing: no run", **theirs})
        for group in ours:
            for run in group:
                table.rows.append({"recipe": recipe, "run": run.name, "seed": run.seed if seeded else None,
                                   "epoch": run.best.get("epoch"),
                                   **{k: run.best.get(k) for k in figures_5_1}, **theirs})
            if len(group) > 1:
                table.rows.append({"recipe": recipe, "run": f"mean ± std of {len(group)} seeds",
                                   **{k: _mean_std_text([r.best.get(k) for r in group], columns, k)
                                      for k in figures_5_1}, **theirs})
    table.notes.append("best checkpoint: lowest validation chamfer for chamfer runs, lowest validation MSE for MSE "
                       "runs (the model.pt each run keeps)")
    table.notes.append(f"thesis columns: the thesis's own figures ({thesis.get('citation', 'thesis_tables.json')}); "
                       "— where the thesis did not compute it ('x')")
    if seeded:
        table.notes.append("a recipe trained with several seeds: one row per seed's run, then the mean ± the sample "
                           "std over its seeds' best checkpoints")
    return table


def _mean_std_text(values: list, columns: list[Column], key: str) -> str | None:
    """``mean ± std`` (sample std) of the numbers among ``values``, in column ``key``'s format; None without two."""
    numbers = [float(v) for v in values if isinstance(v, (int, float)) and not isinstance(v, bool)]
    if len(numbers) < 2:
        return None
    fmt = next(c.fmt for c in columns if c.key == key)
    mean = sum(numbers) / len(numbers)
    std = math.sqrt(sum((v - mean) ** 2 for v in numbers) / (len(numbers) - 1))
    return f"{fmt.format(mean)} ± {fmt.format(std)}"


def table_5_3(thesis: dict) -> Table:
    """Table 5.3 of the thesis: the model authors' own figures, printed as the thesis printed them."""
    section = thesis.get("table_5_3", {})
    columns = [Column("set", "set"), Column("mae", "MAE (mm)", "{:g}"), Column("rmse", "RMSE (mm)", "{:g}")]
    rows = [{"set": name, **values} for name, values in section.get("rows", {}).items()]
    table = Table(f"Table 5.3 — {section.get('title', 'the model authors’ figures')}", columns, rows)
    table.notes.append("quoted from the thesis, not computed by dcslam; — where the thesis did not compute it ('x')")
    return table
