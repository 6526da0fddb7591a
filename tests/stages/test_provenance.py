"""Provenance between stages: a prediction records its model, a filtered layer its source layer, a SLAM output its
depth layer; the stages and the tables refuse an output made from an input that changed after it."""
import json

import pytest

from dcslam.errors import DcslamError
from dcslam.stages.predict import PredictConfig
from dcslam.stages.predict import run as predict
from dcslam.stages.slam import SlamStageConfig
from dcslam.stages.slam import run as slam
from dcslam.stages.train import TrainStageConfig
from dcslam.stages.train import run as train

TINY = dict(max_frames=2, scale=0.5, device="cpu", batch_size=2)
SLAM = SlamStageConfig(depth="predicted", run="mse-dense", odometry="gt", frames=2, voxel_size=0.1,
                       evidence="none")


def test_a_retrained_and_repredicted_run_is_not_scored_beside_its_old_slam_run(ws, cli):
    from dcslam.report.layers import score_layer_trajectories

    train(ws, TrainStageConfig(**TINY))
    predict(ws, PredictConfig(run="mse-dense", device="cpu"))
    slam(ws, SLAM)
    made_from = json.loads((ws.slam / "mse-dense" / "drive_d.json").read_text())["made_from"]
    assert made_from["depth"]["path"] == "../../predictions/mse-dense/drive_d.h5"
    assert score_layer_trajectories(ws, "mse-dense", ["drive_d"])  # fresh: scored

    train(ws, TrainStageConfig(**TINY, seed=1), force=True)  # another model under the same run name
    with pytest.raises(DcslamError, match=r"predictions/mse-dense is stale: it was made from .*runs/mse-dense/"
                                          r"model\.pt, which changed after it was made; rerun `dcslam predict "
                                          r"--run mse-dense --force`"):
        slam(ws, SLAM, force=True)
    predict(ws, PredictConfig(run="mse-dense", device="cpu"), force=True)
    with pytest.raises(DcslamError, match=r"slam/mse-dense/drive_d\.json is stale: it was made from .*predictions/"
                                          r"mse-dense/drive_d\.h5, which changed after it was made; rerun `dcslam "
                                          r"slam --depth mse-dense --force`"):
        score_layer_trajectories(ws, "mse-dense", ["drive_d"])
    result = cli("score", "tables", "-w", ws.root)
    assert result.exit_code == 1 and result.output.count("\n") == 1
    assert "is stale" in result.output and "rerun `dcslam slam --depth mse-dense --force`" in result.output
    assert not (ws.results / "table_5_2.csv").exists()

    slam(ws, SLAM, force=True)  # the rerun the message names
    assert score_layer_trajectories(ws, "mse-dense", ["drive_d"])


def test_a_filtered_layer_records_its_source_and_is_refused_once_the_source_changes(ws):
    from dcslam.io.drive import DriveFile, Layer, write_layer
    from dcslam.stages.filter import FilterConfig
    from dcslam.stages.filter import run as filter_layer

    def layer(scale):
        with DriveFile(ws.drives / "drive_d.h5") as drive:
            depth = drive.depth("dense", 0)[None].repeat(len(drive), 0) * scale
            write_layer(ws.predictions / "mine" / "drive_d.h5",
                        Layer(depth, drive=drive.name, made_by="mine", frame_ids=drive.frame_ids), force=True)

    layer(1.0)
    config = FilterConfig(filters=["range:min=0.5,max=50"], depth="predicted", run="mine", drive=["drive_d"])
    result = filter_layer(ws, config)
    record = json.loads((result.out_dir / "config.json").read_text())
    assert record["made_from"]["drive_d"]["path"] == "../../predictions/mine/drive_d.h5"
    slam(ws, SlamStageConfig(depth="filtered", run=result.out_dir.name, odometry="gt", frames=2, voxel_size=0.1,
                             evidence="none", drive=["drive_d"]))
    layer(1.01)  # the source remade after the filter ran
    with pytest.raises(DcslamError, match=r"filtered/mine\+range.* is stale: .*predictions/mine/drive_d\.h5, which "
                                          r"changed after it was made; rerun `dcslam filter --name mine\+range"):
        slam(ws, SlamStageConfig(depth="filtered", run=result.out_dir.name, odometry="gt", frames=2,
                                 voxel_size=0.1, evidence="none", drive=["drive_d"]), force=True)
    from dcslam.report.layers import slam_trajectory

    with pytest.raises(DcslamError, match="is stale"):
        slam_trajectory(ws, result.out_dir.name, "drive_d")


def test_a_model_of_another_architecture_than_the_run_s_config_is_refused(ws):
    from dcslam.depth.models import build_model, save_model

    train(ws, TrainStageConfig(**TINY))
    save_model(ws.runs / "mse-dense" / "model.pt", build_model("dncnn"))  # placed there by hand
    with pytest.raises(DcslamError, match=r"model\.pt holds a dncnn network but .*config\.json says the run trained "
                                          r"sparse-conv"):
        predict(ws, PredictConfig(run="mse-dense", device="cpu"))
    assert not (ws.predictions / "mse-dense").exists()
