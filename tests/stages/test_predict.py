"""The predict stage: classical completers by registered name (aliases resolved), runs by name, config written."""
import json

import pytest
import torch

from dcslam.depth.models import build_model, save_model
from dcslam.errors import DcslamError
from dcslam.io.drive import read_layer
from dcslam.stages.predict import PredictConfig, run


def test_alias_writes_the_registered_name(ws):
    result = run(ws, PredictConfig(model="ip-basic"))
    assert result.made_by == "ip-basic-fast" and result.out_dir == ws.predictions / "ip-basic-fast"
    assert [p.name for p in result.layers] == ["drive_d.h5"]
    assert read_layer(result.layers[0]).made_by == "ip-basic-fast"
    from dcslam.io.drive import DriveFile

    with DriveFile(ws.drives / "drive_d.h5") as drive:
        assert read_layer(result.layers[0]).frame_ids.tolist() == drive.frame_ids.tolist()
    record = json.loads((result.out_dir / "config.json").read_text())
    assert record["stage"] == "predict" and record["settings"]["model"] == "ip-basic"
    with pytest.raises(DcslamError, match="--force"):
        run(ws, PredictConfig(model="ip-basic-fast"))


def test_trained_run_over_the_val_split(ws):
    torch.manual_seed(0)
    save_model(ws.runs / "r1" / "model.pt", build_model("sparse-conv", channels=4), meta={"scale": 1.0})
    result = run(ws, PredictConfig(run="r1", split="val", device="cpu"))
    assert result.out_dir == ws.predictions / "r1" and [p.name for p in result.layers] == ["drive_c.h5"]
    with pytest.raises(DcslamError, match="dcslam train"):
        run(ws, PredictConfig(run="missing"))


def test_input_of_fewer_beams(tmp_path):
    from dcslam.io.drive import DriveFile
    from dcslam.workspace import Workspace
    from tests.fixtures.depth import write_workspace

    ws = Workspace(write_workspace(tmp_path / "ws", extra=True))
    result = run(ws, PredictConfig(model="ip-basic", input="sparse@16"))
    assert result.out_dir == ws.predictions / "ip-basic-fast-sparse16"
    layer = read_layer(result.layers[0])
    assert layer.config["input"] == "sparse@16" and layer.config["input_beams"] == 16
    full = read_layer(run(ws, PredictConfig(model="ip-basic")).layers[0])
    assert full.config["input_beams"] == 64 and not (full.depth == layer.depth).all()
    with DriveFile(ws.drives / "drive_d.h5") as drive:  # fewer rows in: the completion changes
        assert (drive.depth("sparse@16", 0) > 0).sum() < (drive.depth("sparse", 0) > 0).sum()
    with pytest.raises(DcslamError, match="unknown depth kind"):
        PredictConfig(model="ip-basic", input="sparse@x")


def test_missing_beams_name_the_command(ws):
    with pytest.raises(DcslamError, match=r"holds no sparse@8 depth.*--beams 8"):
        run(ws, PredictConfig(model="ip-basic", input="sparse@8"))
    assert not ws.predictions.exists()  # refused before any folder is made: nothing for the rerun to trip over


def test_confidence_aware_run_writes_confidence(ws):
    torch.manual_seed(0)
    save_model(ws.runs / "nc" / "model.pt", build_model("nconv"), meta={"scale": 0.5})
    layer = read_layer(run(ws, PredictConfig(run="nc", device="cpu")).layers[0])
    assert layer.confidence is not None and layer.confidence.shape == layer.depth.shape
    assert (layer.confidence[layer.depth == 0] == 0).all() and layer.confidence.max() > 0
    save_model(ws.runs / "sc" / "model.pt", build_model("sparse-conv", channels=4), meta={"scale": 1.0})
    assert read_layer(run(ws, PredictConfig(run="sc", device="cpu")).layers[0]).confidence is None


def test_guided_run_reads_the_colour_image(ws):
    torch.manual_seed(0)
    save_model(ws.runs / "g" / "model.pt", build_model("nconv-guided"), meta={"scale": 0.5})
    layer = read_layer(run(ws, PredictConfig(run="g", device="cpu")).layers[0])
    assert layer.confidence is not None and (layer.depth > 0).mean() > 0.5
