"""The filter stage: a layer reference in, a filtered layer and its config.json out."""
import json

import pytest

from dcslam.errors import DcslamError
from dcslam.io.drive import read_layer
from dcslam.stages import predict
from dcslam.stages.filter import FilterConfig, run


def test_filter_dense_and_a_prediction(ws):
    result = run(ws, FilterConfig(filters=["range:min=1,max=3"], depth="dense"))
    assert result.out_dir == ws.filtered / "dense+range" and result.source_layer == "dense"
    layer = read_layer(result.layers[0])
    assert layer.depth.max() <= 3 + 1e-5 and layer.made_by == "dense+range"
    record = json.loads((result.out_dir / "config.json").read_text())
    assert record["settings"]["options"]["filters"] == ["range:min=1,max=3"]

    predict.run(ws, predict.PredictConfig(model="ip-basic"))
    result = run(ws, FilterConfig(filters=["edges"], depth="predicted", run="ip-basic-fast", name="ipb"))
    assert result.out_dir == ws.filtered / "ipb" and result.source_layer == "ip-basic-fast"
    again = run(ws, FilterConfig(filters=["edges"], depth="filtered", run="ipb"))
    assert again.out_dir == ws.filtered / "ipb+edges"


def test_missing_input_names_its_maker(ws):
    with pytest.raises(DcslamError, match="run `dcslam predict` first"):
        run(ws, FilterConfig(filters=["edges"], depth="predicted", run="nothing"))
    assert not ws.filtered.exists()
