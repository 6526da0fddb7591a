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
        "drive": [], "out_dir": None, "devkit_exact": False, "max_time_diff": 0.01, "failure_threshold": 1.0}
    assert any(row["layer"] == "dense" for row in report.table_5_2.rows)


def test_usage(ws):
    with pytest.raises(DcslamError, match="give either"):
        run_trajectory(ws, ScoreTrajectoryConfig())
    with pytest.raises(DcslamError, match="give --layer"):
        ScoreDepthConfig()
