"""The thesis's own figures (dcslam/report/thesis_tables.json), as its readers see them."""
import math

from dcslam.report.tables import THESIS_FIGURES, thesis_figures


def test_structure_every_row_has_every_unit():
    figures = thesis_figures()
    assert "Czech Technical University" in figures["citation"]
    for table in ("table_5_1", "table_5_2", "table_5_3"):
        units = figures[table]["units"]
        for row in figures[table]["rows"].values():
            assert set(row) == set(units)
            assert all(v is None or (isinstance(v, (int, float)) and math.isfinite(v)) for v in row.values())


def test_figures_as_printed():
    figures = thesis_figures(THESIS_FIGURES)
    t51, t52, t53 = (figures[t]["rows"] for t in ("table_5_1", "table_5_2", "table_5_3"))
    assert t51["chamfer single-frame"] == {"chamfer": 1.93, "mse": None, "mae": 471, "rmse": 1206}
    assert t51["MSE sparse mask"]["mse"] == 34.73 and t51["MSE dense mask"]["rmse"] == 1316
    assert [t52[r]["localisation"] for r in ("chamfer single-frame", "chamfer multi-frame", "MSE sparse mask",
                                             "MSE dense mask", "sparse depth", "dense depth")] == [
        10.36, 10.34, 10.31, 10.29, 9.447, 3.76]
    assert t52["dense depth"]["mae"] is None and t52["sparse depth"]["rmse"] == 19524
    assert t53 == {"validation": {"mae": 680, "rmse": 2010}, "testing": {"mae": 540, "rmse": 1810}}
    assert figures["test_drives"]["text"] == 5 and figures["test_drives"]["code"] == 6
