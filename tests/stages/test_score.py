"""The score stages: tables of layers and of the whole report, with the configuration written beside them."""
import json

import pytest

from dcslam.errors import DcslamError
from dcslam.stages import slam
from dcslam.stages.score import (ScoreDepthConfig, ScoreTablesConfig, ScoreTrajectoryConfig, run_depth, run_tables,
                                 run_trajectory)


def test_depth_trajectory_and_tables(ws):
    result = run_depth(ws, ScoreDepthConfig(layer="sparse", raw=True))
    assert result.out == ws.results / "depth_sparse.csv" and result.out.stat().st_size > 0
    record = json.loads((ws.results / "depth_sparse.json").read_text())
    assert record["stage"] == "score-depth" and record["settings"]["raw"] is True
    slam.run(ws, slam.SlamStageConfig(odometry="gt", frames=2))
    result = run_trajectory(ws, ScoreTrajectoryConfig(layer="dense"))
    assert result.out == ws.results / "trajectory_dense.csv"
    assert json.loads((ws.results / "trajectory_dense.json").read_text())["settings"]["layer"] == "dense"
    assert result.table.rows[0]["poses"] == 2
    report = run_tables(ws, ScoreTablesConfig())
    assert (ws.results / "table_5_2.md").exists()
    record = json.loads((ws.results / "score-tables.json").read_text())
    assert record["stage"] == "score-tables" and record["settings"] == {
        "drive": [], "out_dir": None, "devkit_exact": False, "max_time_diff": 0.01, "failure_threshold": 1.0,
        "table": "5.2"}
    assert any(row["layer"] == "dense" for row in report.table_5_2.rows)
    assert (ws.results / "table_5_2_correlation.csv").exists() and report.table_5_2_correlation.rows


def test_usage(ws):
    with pytest.raises(DcslamError, match="give either"):
        run_trajectory(ws, ScoreTrajectoryConfig())
    with pytest.raises(DcslamError, match="give --layer"):
        ScoreDepthConfig()


def test_depth_against_exact_and_of_fewer_beams(tmp_path):
    from dcslam.workspace import Workspace
    from tests.fixtures.depth import write_workspace

    ws = Workspace(write_workspace(tmp_path / "ws", extra=True))
    exact = run_depth(ws, ScoreDepthConfig(layer="exact", target="exact", raw=True))
    assert exact.out == ws.results / "depth_exact_vs_exact.csv"
    assert exact.table.rows[-1]["mae_mm"] == 0 and exact.table.rows[-1]["coverage"] == 1
    sixteen = run_depth(ws, ScoreDepthConfig(layer="sparse@16", target="exact", raw=True)).table.rows[-1]
    assert sixteen["mae_mm"] == pytest.approx(0, abs=1e-3) and 0 < sixteen["coverage"] < 0.1
    dense = run_depth(ws, ScoreDepthConfig(layer="dense", target="exact", raw=True)).table.rows[-1]
    assert 0.5 < dense["coverage"] < 0.8  # the annotated depth lacks the top quarter of the rows
    bare = Workspace(write_workspace(tmp_path / "bare"))
    with pytest.raises(DcslamError, match="holds no exact depth"):
        run_depth(bare, ScoreDepthConfig(layer="dense", target="exact"))
