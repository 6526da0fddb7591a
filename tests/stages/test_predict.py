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
