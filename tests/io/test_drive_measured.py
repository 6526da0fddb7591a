"""measured_kind: the LiDAR pixels behind a depth source, through predictions and filters."""
import numpy as np

from dcslam.io.drive import Layer, measured_kind, write_layer


def _layer(path, config):
    write_layer(path, Layer(depth=np.ones((2, 4, 5), np.float32), drive="d", made_by="x", config=config))
    return path


def test_drive_kinds():
    assert measured_kind("sparse") == "sparse"
    assert measured_kind("sparse@16") == "sparse@16"
    assert measured_kind("dense") == "sparse"
    assert measured_kind("exact") == "sparse"


def test_prediction_and_filter_of_it(tmp_path):
    pred = _layer(tmp_path / "predictions" / "run-sparse8" / "d.h5", {"input": "sparse@8"})
    assert measured_kind(pred) == "sparse@8"
    filtered = _layer(tmp_path / "filtered" / "f" / "d.h5", {"source": str(pred), "source_layer": "run-sparse8"})
    assert measured_kind(filtered) == "sparse@8"


def test_moved_workspace_follows_the_source_layer_by_name(tmp_path):
    _layer(tmp_path / "predictions" / "run-sparse16" / "d.h5", {"input": "sparse@16"})
    filtered = _layer(tmp_path / "filtered" / "f" / "d.h5",
                      {"source": "/elsewhere/predictions/run-sparse16/d.h5", "source_layer": "run-sparse16"})
    assert measured_kind(filtered) == "sparse@16"


def test_unknown_layer_says_none(tmp_path):
    assert measured_kind(_layer(tmp_path / "a.h5", {})) is None
    assert measured_kind(tmp_path / "missing.h5") is None
