import json

import numpy as np
import pytest

from dcslam.io.drive import DriveFrame, DriveWriter, Layer, read_layer, write_layer

K = np.array([[20.0, 0, 12], [0, 20.0, 8], [0, 0, 1]])


def make_workspace(root, drives=("d0", "d1"), n=3, h=16, w=24):
    rng = np.random.default_rng(0)
    (root / "drives").mkdir(parents=True)
    for name in drives:
        with DriveWriter(root / "drives" / f"{name}.h5", K, h, w, source="synthetic", date="2011_09_26",
                         drive=name) as writer:
            for i in range(n):
                dense = rng.uniform(2, 30, (h, w)).astype(np.float32)
                sparse = np.where(rng.random((h, w)) < 0.3, dense, 0).astype(np.float32)
                writer.append(DriveFrame(rgb=np.zeros((h, w, 3), np.uint8), sparse=sparse, dense=dense,
                                    T_world_cam=np.eye(4), timestamp=0.1 * i, frame_id=i))
    (root / "drives" / "splits.json").write_text(json.dumps({"train": [], "val": [], "test": list(drives)}))
    for name in drives:
        write_layer(root / "predictions" / "mse-dense" / f"{name}.h5",
                    Layer(depth=rng.uniform(1, 40, (n, h, w)).astype(np.float32), drive=name, made_by="mse-dense"))
    return root


def test_filter_predicted_chain(cli, tmp_path):
    ws = make_workspace(tmp_path / "ws")
    result = cli("filter", "-w", ws, "--run", "mse-dense", "--filter", "range:min=5,max=20",
                 "--filter", "thesis-bilateral")
    assert result.exit_code == 0, result.output
    out = ws / "filtered" / "mse-dense+range+bilateral"
    for drive in ("d0", "d1"):
        layer = read_layer(out / f"{drive}.h5", expect_frames=3)
        valid = layer.depth[layer.depth > 0]
        assert valid.min() >= 5 - 1e-4 and valid.max() <= 20 + 1e-4
        assert [f["filter"] for f in layer.config["filters"]] == ["range", "bilateral"]
        assert layer.config["filters"][0]["min_m"] == 5.0 and layer.config["filters"][1]["sigma_color"] == 80.0
        assert layer.made_by == "mse-dense+range+bilateral" and layer.drive == drive
    config = json.loads((out / "config.json").read_text())
    assert config["stage"] == "filter" and config["settings"]["source_layer"] == "mse-dense"


def test_filter_sparse_named_one_drive_and_no_overwrite(cli, tmp_path):
    ws = make_workspace(tmp_path / "ws")
    args = ("filter", "-w", ws, "--depth", "sparse", "--filter", "thesis-range", "--name", "lidar-5-15",
            "--drive", "d1")
    assert cli(*args).exit_code == 0
    out = ws / "filtered" / "lidar-5-15"
    assert sorted(p.name for p in out.iterdir()) == ["config.json", "d1.h5"]
    before = (out / "d1.h5").stat().st_mtime_ns
    again = cli(*args)
    assert again.exit_code == 1 and "--force" in again.output
    assert (out / "d1.h5").stat().st_mtime_ns == before
    assert cli(*args, "--force").exit_code == 0


@pytest.mark.parametrize("spec", ["nonsense", "range:min=abc", "range:lo=3", "range:min=20,max=5",
                                  "bilateral:ignore_holes=maybe"])
def test_bad_filter_spec_is_a_usage_error(cli, tmp_path, spec):
    ws = make_workspace(tmp_path / "ws", drives=("d0",))
    result = cli("filter", "-w", ws, "--depth", "dense", "--filter", spec)
    assert result.exit_code == 2
    assert not (ws / "filtered").exists()


def test_layer_with_wrong_frame_count_fails_cleanly(cli, tmp_path):
    ws = make_workspace(tmp_path / "ws", drives=("d0",))
    write_layer(ws / "predictions" / "short" / "d0.h5",
                Layer(depth=np.ones((2, 16, 24), np.float32), drive="d0", made_by="short"))
    result = cli("filter", "-w", ws, "--run", "short", "--filter", "edges")
    assert result.exit_code == 1
    assert "2 frames but its drive has 3" in result.output
    assert not (ws / "filtered" / "short+edges" / "d0.h5").exists()


def test_missing_run(cli, tmp_path):
    ws = make_workspace(tmp_path / "ws", drives=("d0",))
    result = cli("filter", "-w", ws, "--run", "nope", "--filter", "outlier")
    assert result.exit_code == 1 and "dcslam predict" in result.output
    result = cli("filter", "-w", ws, "--filter", "outlier")
    assert result.exit_code == 1 and "--run" in result.output
