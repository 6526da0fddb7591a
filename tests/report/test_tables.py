"""The report package: the thesis's figures ship as package data, and run folders are read into Table 5.1."""
import json

from dcslam.report.tables import RECIPES, THESIS_FIGURES, list_runs, recipe_of, table_5_1, thesis_figures
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
