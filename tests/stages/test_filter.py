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


@pytest.mark.parametrize("depth", ["sparse@16", "exact", "sparse"])
def test_any_depth_kind_of_the_drive_files(tmp_path, depth):
    """Every depth the drive files hold (sparse@<beams> from prepare-kitti --beams, exact from generated drives) is
    a filter input, as it is a SLAM input."""
    from dcslam.io.drive import DriveFile
    from dcslam.workspace import Workspace
    from tests.fixtures import depth as depth_fixtures

    ws = Workspace(depth_fixtures.write_workspace(tmp_path / "ws", n=3, extra=True))
    result = run(ws, FilterConfig(filters=["range:min=1,max=20"], depth=depth))
    assert result.out_dir == ws.filtered / f"{depth}+range" and result.source_layer == depth
    layer = read_layer(result.layers[0])
    with DriveFile(ws.drives / "drive_d.h5") as drive:
        source = drive.depth(depth, 0)
    expected = source * ((source >= 1) & (source <= 20))
    assert 0 < (layer.depth[0] > 0).sum() < (source > 0).sum() and (layer.depth[0] == expected).all()
    assert layer.config["source"] == depth


def test_layer_folder_and_file_paths(ws):
    first = run(ws, FilterConfig(filters=["range:min=1,max=3"], depth="dense", name="near"))
    by_folder = run(ws, FilterConfig(filters=["edges"], depth=str(first.out_dir), name="by-folder"))
    by_file = run(ws, FilterConfig(filters=["edges"], depth="filtered/near", name="by-ref"))
    assert (read_layer(by_folder.layers[0]).depth == read_layer(by_file.layers[0]).depth).all()


def test_unknown_depth_kind_is_one_clear_line(ws):
    with pytest.raises(DcslamError, match="holds no sparse@7 depth"):
        run(ws, FilterConfig(filters=["edges"], depth="sparse@7"))
    with pytest.raises(DcslamError, match="--depth is empty"):
        FilterConfig(filters=["edges"], depth="")
