"""The one depth-layer resolver (dcslam.workspace.find_layer / resolve_layer) and drive selection."""
import json
import os

import pytest

from dcslam.errors import DcslamError
from dcslam.workspace import (LayerRef, Workspace, drive_file, find_layer, layer_reference, resolve_layer,
                              select_drives)


@pytest.fixture
def ws(tmp_path):
    ws = Workspace(tmp_path / "ws")
    for folder in (ws.predictions / "mse-dense", ws.predictions / "ip-basic-fast", ws.filtered / "mse-dense+edges"):
        folder.mkdir(parents=True)
        (folder / "d.h5").write_bytes(b"")
    os.utime(ws.predictions / "mse-dense", (1_000_000, 1_000_000))  # ip-basic-fast is the most recent
    ws.drives.mkdir()
    (ws.drives / "d.h5").write_bytes(b"")
    ws.splits.write_text(json.dumps({"train": [], "val": [], "test": ["d"]}))
    return ws


def test_grammar(ws, tmp_path):
    assert find_layer(ws, "sparse") == LayerRef("sparse") and find_layer(ws, "dense").source("d") == "dense"
    assert find_layer(ws, "sparse@16") == LayerRef("sparse@16") and find_layer(ws, "exact").source("d") == "exact"
    assert find_layer(ws, "sparse@x") is None
    assert find_layer(ws, "predicted/mse-dense") == LayerRef("mse-dense", ws.predictions / "mse-dense",
                                                             made_by="dcslam predict")
    assert find_layer(ws, "filtered/mse-dense+edges").source("d") == ws.filtered / "mse-dense+edges" / "d.h5"
    assert find_layer(ws, "mse-dense+edges").made_by == "dcslam filter"  # a bare name: predictions/, then filtered/
    assert find_layer(ws, "predicted").name == "ip-basic-fast"  # alone: the most recent
    assert find_layer(ws, str(ws.filtered / "mse-dense+edges")).name == "mse-dense+edges"  # a folder
    one = find_layer(ws, str(ws.predictions / "mse-dense" / "d.h5"))  # one file, for every drive
    assert one.name == "d" and one.source("other") == ws.predictions / "mse-dense" / "d.h5"
    assert find_layer(ws, "predicted/none") is None and find_layer(ws, "none") is None


def test_failures_name_the_maker(ws, tmp_path):
    with pytest.raises(DcslamError, match="predictions/none not found; run `dcslam predict` first"):
        resolve_layer(ws, "predicted/none")
    with pytest.raises(DcslamError, match="filtered/none not found; run `dcslam filter` first"):
        resolve_layer(ws, "filtered/none")
    with pytest.raises(DcslamError, match="no depth layer 'none'"):
        resolve_layer(ws, "none")
    with pytest.raises(DcslamError, match="no layers in"):
        resolve_layer(Workspace(tmp_path / "empty"), "filtered")
    with pytest.raises(DcslamError, match="d2.h5 not found; run `dcslam predict` first"):
        resolve_layer(ws, "mse-dense").require("d2")


def test_depth_and_run_options_make_one_reference(ws):
    assert layer_reference("predicted", "x") == "predicted/x" and layer_reference("filtered", None) == "filtered"
    assert layer_reference("dense", "x") == "dense"
    assert layer_reference("predicted", str(ws.predictions / "mse-dense")) == str(ws.predictions / "mse-dense")


def test_drives(ws):
    assert select_drives(ws) == ["d"] and select_drives(ws, ["a", "b"]) == ["a", "b"]
    assert drive_file(ws, "d") == ws.drives / "d.h5"
    with pytest.raises(DcslamError, match="drive file .* not found; run `dcslam prepare-kitti` first"):
        drive_file(ws, "missing")
