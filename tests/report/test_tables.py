"""The report package: the thesis's figures ship as package data, and run folders are read into Table 5.1."""
import json

from dcslam.report.results import LayerResult
from dcslam.report.table_5_2 import table_5_2
from dcslam.report.tables import RECIPES, THESIS_FIGURES, list_runs, recipe_of, table_5_1, table_5_3, thesis_figures
from dcslam.workspace import Workspace


def test_thesis_figures_are_package_data():
    assert THESIS_FIGURES.parent.name == "report" and THESIS_FIGURES.exists()
    figures = thesis_figures()
    assert {"table_5_1", "table_5_2"} <= set(figures)


def test_recipes_of_the_stage_settings():
    assert [recipe_of({"loss": "chamfer", "map_frames": 1}), recipe_of({"loss": "chamfer", "map_frames": 8}),
            recipe_of({"loss": "mse", "mask": "sparse"}), recipe_of({"loss": "mse", "mask": "dense"})] == list(RECIPES)


def test_table_5_1_from_run_folders(tmp_path):
    ws = Workspace(tmp_path)
    run = ws.runs / "mse-dense"
    run.mkdir(parents=True)
    (run / "config.json").write_text(json.dumps({"settings": {"loss": "mse", "mask": "dense", "map_frames": 1}}))
    rows = [{"kind": "val", "epoch": e, "step": e, "chamfer": 1.0, "mse": mse, "mae_mm": 10.0, "rmse_mm": 20.0}
            for e, mse in enumerate((0.5, 0.2, 0.3))]
    (run / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    runs = list_runs(ws)
    assert [(r.name, r.recipe, r.best["epoch"], r.validations) for r in runs] == [("mse-dense", "MSE dense mask", 1, 3)]
    table = table_5_1(runs, thesis_figures())
    assert "Table 5.1" in table.title and any("mse-dense" in str(row.values()) for row in table.rows)


def test_table_5_3_is_printed_from_the_thesis_figures():
    table = table_5_3(thesis_figures())
    assert [(r["set"], r["mae"], r["rmse"]) for r in table.rows] == [("validation", 680, 2010), ("testing", 540, 1810)]
    assert "| testing | 540 | 1810 |" in table.to_markdown() and "did not compute it ('x')" in table.to_markdown()


def test_table_5_2_says_why_a_cell_is_empty():
    """x: the thesis did not compute it; —: the thesis has no such row, or ours lacks inputs (the reason in 'why —')."""
    rows = [LayerResult(label="dense depth", layer="dense", missing=["slam/dense/ for 2 test drive(s) (dcslam slam)"]),
            LayerResult(label="IP-Basic", layer="ip-basic-fast")]
    table = table_5_2(rows, thesis_figures(), ["a", "b"])
    dense, ip_basic = table.rows
    assert dense["thesis_localisation_text"] == "3.76" and dense["thesis_mae_text"] == "x"
    assert dense["notes"].startswith("slam/dense/ for 2 test drive(s)")
    assert ip_basic["thesis_localisation_text"] is None and "no such row" in " ".join(table.notes)
