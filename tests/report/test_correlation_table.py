"""The rank correlation of depth metrics with localisation, from per-drive figures stored in LayerResults (no SLAM
run): known answers (a metric in the order of the localisation error gives rho 1, the reverse -1), the pairs left
out and counted, the failed runs kept; the frames whose surface a table scores; and the beams builder writing the
correlation files from a tiny workspace's SLAM runs."""
import csv
import math

import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.eval.depth import DepthErrors
from dcslam.eval.surface import SurfaceErrors
from dcslam.report.correlation_table import METRICS, correlation_table
from dcslam.report.layers import surface_frames
from dcslam.report.results import LayerResult
from tests.fixtures.trajectories import offset_pair

DRIVES = ["d0", "d1", "d2", "d3"]



def _surface(value: float, flying: float = math.nan) -> SurfaceErrors:
    return SurfaceErrors(normal_mean_deg=value, normal_median_deg=value, p2p_mean_m=value, p2p_rmse_m=value,
                         flying_share=flying, normal_pixels=1, p2p_pixels=1, edge_pixels=0, flying_pixels=0)


def _row(name: str, offsets: list[float], mae: list[float], normal: list[float]) -> LayerResult:
    """A row whose drive i localises at ``offsets[i]`` with MAE ``mae[i]`` and every surface error ``normal[i]``."""
    def depth(m):
        return DepthErrors(mae_mm=m, rmse_mm=2 * m, imae_per_km=1.0, irmse_per_km=1.0, pixels=10, coverage=1.0)

    return LayerResult(label=name, layer=name, depth={d: depth(m) for d, m in zip(DRIVES, mae)},
                       pairs={d: offset_pair(o, 4) for d, o in zip(DRIVES, offsets)},
                       settings={d: {"suspect": False} for d in DRIVES},
                       surface={d: _surface(v) for d, v in zip(DRIVES, normal)},
                       surface_frames={d: 5 for d in DRIVES}, surface_target="exact")


def _rows():
    """Two rows × 4 drives: MAE grows with the localisation error, the surface errors shrink with it."""
    a = _row("a", [0.1, 0.2, 0.3, 0.4], mae=[10, 20, 30, 40], normal=[8, 7, 6, 5])
    b = _row("b", [0.5, 0.6, 0.7, 0.8], mae=[50, 60, 70, 80], normal=[4, 3, 2, 1])
    return [("a", a), ("b", b)]


def test_monotone_metric_gives_rho_one_and_the_reverse_minus_one():
    table = correlation_table(_rows(), "t", failure_threshold=1.0)
    rows = {r["key"]: r for r in table.rows}
    assert [r["key"] for r in table.rows] == [k for k, _ in METRICS]
    for key in ("mae_mm", "rmse_mm"):
        assert rows[key]["rho"] == pytest.approx(1.0) and rows[key]["pairs"] == 8
        assert rows[key]["ci_low"] <= rows[key]["rho"] <= rows[key]["ci_high"]
    for key in ("normal_median_deg", "p2p_mean_m"):
        assert rows[key]["rho"] == pytest.approx(-1.0)
        assert rows[key]["ci_low"] <= rows[key]["rho"] <= rows[key]["ci_high"]
    assert rows["mae_mm"]["rho_text"] == "+1.00 [+1.00, +1.00]"
    # the flying share is NaN on every drive (no reference edge): every pair left out, and counted
    assert rows["flying_share"]["pairs"] == 0 and rows["flying_share"]["left_out"] == 8
    assert rows["flying_share"]["rho"] is None and "fewer than 3" in rows["flying_share"]["rho_text"]
    assert table.rows == correlation_table(_rows(), "t", failure_threshold=1.0).rows  # seeded bootstrap


def test_a_noisy_metric_has_an_interval_around_its_rho():
    rng = np.random.default_rng(3)
    offsets = rng.uniform(0.1, 0.9, size=(5, 4))
    rows = [(f"r{i}", _row(f"r{i}", list(o), mae=list(o + rng.normal(0, 0.2, 4)), normal=list(rng.random(4))))
            for i, o in enumerate(offsets)]
    mae = next(r for r in correlation_table(rows, "t", 1.0).rows if r["key"] == "mae_mm")
    assert mae["pairs"] == 20 and 0.3 < mae["rho"] < 1.0 and mae["ci_low"] < mae["rho"] < mae["ci_high"]


def test_rows_without_localisation_and_pairs_without_a_metric_are_left_out_and_counted():
    rows = _rows()
    rows[1][1].surface.pop("d3")  # no sampled frame of d3 had a reference
    missing = LayerResult(label="c", layer="c", missing=["slam/c/ for 4 test drive(s)"])
    table = correlation_table([*rows, ("c (layer c)", missing)], "t", failure_threshold=1.0)
    by_key = {r["key"]: r for r in table.rows}
    assert by_key["mae_mm"]["pairs"] == 8 and by_key["mae_mm"]["left_out"] == 0
    assert by_key["normal_median_deg"]["pairs"] == 7 and by_key["normal_median_deg"]["left_out"] == 1
    assert by_key["normal_median_deg"]["rho"] == pytest.approx(-1.0)
    note = next(n for n in table.notes if n.startswith("left out"))
    assert "8 pairs with localisation" in note and "1 row(s) without localisation" in note and "c (layer c)" in note


def test_failed_runs_are_kept_and_also_left_out_in_their_own_column():
    a = _row("a", [0.1, 0.2, 0.3, 5.0], mae=[10, 20, 30, 40], normal=[1, 2, 3, 4])
    b = _row("b", [0.5, 0.6, 0.7, 3.0], mae=[35, 36, 37, 50], normal=[5, 6, 7, 8])
    mae = next(r for r in correlation_table([("a", a), ("b", b)], "t", 1.0).rows if r["key"] == "mae_mm")
    assert mae["pairs"] == 8 and mae["failed"] == 2 and mae["pairs_without_failed"] == 6
    assert mae["rho"] < 1.0 and mae["rho_without_failed"] == pytest.approx(1.0)


def test_the_surface_frames_are_evenly_spaced_with_the_first_and_the_last():
    assert surface_frames(32) == [0, 8, 16, 23, 31]
    assert surface_frames(32, 2) == [0, 31] and surface_frames(32, 1) == [15]
    assert surface_frames(5) == [0, 1, 2, 3, 4] and surface_frames(3) == [0, 1, 2]
    assert surface_frames(11, 3) == [0, 5, 10]
    with pytest.raises(DcslamError, match=">= 1"):
        surface_frames(10, 0)


def test_per_drive_figures_hold_the_surface_errors_but_not_an_undefined_one():
    figures = _rows()[0][1].per_drive()["d1"]
    assert figures["normal_median_deg"] == 7 and figures["p2p_mean_m"] == 7 and figures["surface_frames"] == 5
    assert "flying_share" not in figures  # NaN on that drive: no value rather than a NaN
    row = _rows()[0][1].row()
    assert row["normal_median_deg"] == pytest.approx(6.5) and "flying_share" not in row


def test_the_beams_builder_writes_the_correlation_files(tmp_path):
    """A tiny workspace (one test drive of 6 frames, 32 × 64, with sparse@16 and exact depth): SLAM on ground-truth
    odometry for the drive-file layers, the other rows missing."""
    from dcslam.report.table_beams import build_beams_report
    from dcslam.stages import slam
    from dcslam.workspace import Workspace
    from tests.fixtures.depth import write_workspace

    ws = Workspace(write_workspace(tmp_path / "ws", n=6, extra=True))
    for depth in ("sparse", "sparse@16", "dense", "exact"):
        slam.run(ws, slam.SlamStageConfig(odometry="gt", frames=2, depth=depth, drive=["drive_d"]))
    report = build_beams_report(ws, [64, 16], ["drive_d"], out_dir=tmp_path / "out")
    for name in ("table_beams_correlation.md", "table_beams_correlation.csv"):
        assert (tmp_path / "out" / name).stat().st_size > 0, name
    with open(tmp_path / "out" / "table_beams_correlation.csv") as f:
        rows = {r["key"]: r for r in csv.DictReader(f)}
    assert set(rows) == {k for k, _ in METRICS}
    assert rows["mae_mm"]["pairs"] == "4"  # sparse at 64 and 16 beams, dense, exact on the one drive
    text = (tmp_path / "out" / "table_beams_correlation.md").read_text()
    assert "16 row(s) without localisation" in text  # the depth rows only: 2 beam counts x 8 completed inputs
    assert "measured-source rows" in text and "IP-Basic, measured sources" not in text
    assert report.correlation.rows[0]["metric"] == "MAE (mm)"
    # the surface errors, against the exact depth on 5 of the 6 frames: the row means in the CSV, each drive's in
    # the per-drive CSV; exact depth against itself has none
    with open(tmp_path / "out" / "table_beams.csv") as f:
        exact = next(r for r in csv.DictReader(f) if r["input"] == "exact")
    assert float(exact["normal_median_deg"]) == pytest.approx(0, abs=1e-6) and float(exact["p2p_mean_m"]) < 1e-6
    with open(tmp_path / "out" / "table_beams_per_drive.csv") as f:
        sparse = next(r for r in csv.DictReader(f) if r["layer"] == "sparse@16")
    assert sparse["surface_frames"] == "5" and float(sparse["p2p_mean_m"]) >= 0
    assert "against the exact (the generator's) depth, on 5 evenly spaced" in report.table.to_markdown()


def test_reproduce_prints_the_correlation_table_after_its_table(tmp_path, capsys):
    from dcslam.cli.reproduce import report

    (tmp_path / "table_beams.md").write_text("### The beams experiment\n\n| input | localisation |\n| --- | --- |\n"
                                             "| sparse | 0.1 |\n")
    report((tmp_path / "table_beams.md", 60.0))
    assert "rank correlations" not in capsys.readouterr().out  # a table without one (Table 5.1) prints alone
    (tmp_path / "table_beams_correlation.md").write_text("### depth metrics against localisation\n\n"
                                                         "| depth metric | rho |\n| --- | --- |\n| MAE (mm) | +0.3 |\n")
    report((tmp_path / "table_beams.md", 60.0))
    out = capsys.readouterr().out
    assert out.index("sparse") < out.index("full table") < out.index("MAE (mm)") < out.index("rank correlations")
