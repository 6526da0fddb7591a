
import pytest
import torch
from typer.testing import CliRunner

from dcslam.cli import app
from dcslam.depth.models import build_model, save_model
from dcslam.io.drive import DriveFile, read_layer
from tests.fixtures import depth as fixtures


@pytest.fixture
def ws(tmp_path):
    return fixtures.write_workspace(tmp_path / "ws", n=3)


def _run(*args):
    return CliRunner().invoke(app, list(args))


def test_predict_ip_basic_default_test_split(ws):
    """``ip-basic`` is an alias: the layer goes by the registered name, the one `score tables` looks for."""
    result = _run("predict", "-w", str(ws), "--model", "ip-basic")
    assert result.exit_code == 0, result.output
    layer = read_layer(ws / "predictions" / "ip-basic-fast" / "drive_d.h5")
    assert layer.made_by == "ip-basic-fast"
    with DriveFile(ws / "drives" / "drive_d.h5") as drive:
        assert layer.depth.shape == drive.shape
    assert not (ws / "predictions" / "ip-basic-fast" / "drive_a.h5").exists()
    assert not (ws / "predictions" / "ip-basic").exists()
    from dcslam.report.tables import IP_BASIC
    from dcslam.workspace import Workspace, find_layer

    assert [name for name in IP_BASIC if find_layer(Workspace(ws), name)] == ["ip-basic-fast"]
    again = _run("predict", "-w", str(ws), "--model", "ip-basic")
    assert again.exit_code == 1 and "--force" in again.output
    assert _run("predict", "-w", str(ws), "--model", "ip-basic", "--force").exit_code == 0


def test_predict_variants_split_and_drive(ws, tmp_path):
    assert _run("predict", "-w", str(ws), "--run", "ip-basic-multiscale", "--split", "val").exit_code == 0
    assert read_layer(ws / "predictions" / "ip-basic-multiscale" / "drive_c.h5").made_by == "ip-basic-multiscale"
    out = tmp_path / "out"
    result = _run("predict", "-w", str(ws), "--model", "ip-basic-fast", "--drive", str(ws / "drives" / "drive_a.h5"),
                  "--output", str(out))
    assert result.exit_code == 0, result.output
    assert (out / "drive_a.h5").exists()


def test_predict_trained_run(ws):
    torch.manual_seed(0)
    save_model(ws / "runs" / "r1" / "model.pt", build_model("sparse-conv", channels=4), meta={"scale": 1.0})
    result = _run("predict", "-w", str(ws), "--run", "r1", "--device", "cpu")
    assert result.exit_code == 0, result.output
    layer = read_layer(ws / "predictions" / "r1" / "drive_d.h5")
    assert layer.made_by == "r1" and layer.config["arch"] == "sparse-conv"


def test_predict_errors(ws):
    assert _run("predict", "-w", str(ws)).exit_code == 1
    result = _run("predict", "-w", str(ws), "--run", "missing")
    assert result.exit_code == 1 and "dcslam train" in result.output
    assert _run("predict", "-w", str(ws), "--model", "unet").exit_code == 2  # unknown choices are usage errors
    assert _run("predict", "-w", str(ws), "--model", "ip-basic", "--split", "nope").exit_code == 2
    assert not (ws / "predictions").exists()
