import json
import os

import pytest
import torch

from dcslam.depth.models import build_model, save_model
from dcslam.io.drive import DriveFile, read_layer
from tests.fixtures import depth as fixtures


@pytest.fixture
def ws(tmp_path):
    return fixtures.write_workspace(tmp_path / "ws", n=3)


def test_predict_ip_basic_default_test_split(cli, ws):
    """``ip-basic`` is an alias: the layer goes by the registered name, the one `score tables` looks for."""
    result = cli("predict", "-w", ws, "--model", "ip-basic")
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
    again = cli("predict", "-w", ws, "--model", "ip-basic")
    assert again.exit_code == 1 and "--force" in again.output
    assert cli("predict", "-w", ws, "--model", "ip-basic", "--force").exit_code == 0


def test_predict_variants_split_and_drive(cli, ws, tmp_path):
    assert cli("predict", "-w", ws, "--run", "ip-basic-multiscale", "--split", "val").exit_code == 0
    assert read_layer(ws / "predictions" / "ip-basic-multiscale" / "drive_c.h5").made_by == "ip-basic-multiscale"
    out = tmp_path / "out"
    result = cli("predict", "-w", ws, "--model", "ip-basic-fast", "--drive", ws / "drives" / "drive_a.h5",
                 "--output", out)
    assert result.exit_code == 0, result.output
    assert (out / "drive_a.h5").exists()


def test_predict_trained_run(cli, ws):
    torch.manual_seed(0)
    save_model(ws / "runs" / "r1" / "model.pt", build_model("sparse-conv", channels=4), meta={"scale": 1.0})
    result = cli("predict", "-w", ws, "--run", "r1", "--device", "cpu")
    assert result.exit_code == 0, result.output
    layer = read_layer(ws / "predictions" / "r1" / "drive_d.h5")
    assert layer.made_by == "r1" and layer.config["arch"] == "sparse-conv"


def test_predict_errors(cli, ws):
    assert cli("predict", "-w", ws).exit_code == 1
    result = cli("predict", "-w", ws, "--run", "missing")
    assert result.exit_code == 1 and "dcslam train" in result.output
    assert cli("predict", "-w", ws, "--model", "unet").exit_code == 2  # unknown choices are usage errors
    assert cli("predict", "-w", ws, "--model", "ip-basic", "--split", "nope").exit_code == 2
    assert not (ws / "predictions").exists()


def test_classical_completion_its_filters_and_devkit_pngs_run_without_torch(ws, tmp_path):
    """Classical completers, filters and the devkit PNGs are NumPy's and OpenCV's work: commands started as users
    start them (one fresh process, here running each in turn) write their layers without importing torch, whose
    import alone costs 2-3 s of CPU, more than IP-Basic takes for a drive."""
    import subprocess
    import sys

    from dcslam.depth.models import CLASSICAL

    commands = [["predict", "--model", name] for name in CLASSICAL]
    commands += [["filter", "--depth", "predicted", "--run", "planefit", "--filter", "edges", "--filter", "outlier"],
                 ["export", "--depth", "predicted/scanline", "--out", str(tmp_path / "png")],
                 ["import", "--src", str(tmp_path / "png"), "--name", "scanline-again"]]
    code = ("import json, sys\nfrom dcslam.cli import main\ncommands, ws = json.loads(sys.argv[1]), sys.argv[2]\n"
            "for args in commands:\n    sys.argv = ['dcslam', *args, '-w', ws]\n    try:\n        main()\n"
            "    except SystemExit as e:\n        assert not e.code, (args, e.code)\nprint('torch' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code, json.dumps(commands), str(ws)], capture_output=True,
                          text=True, env={**os.environ, "DCSLAM_PROGRESS": "0"})
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "False"
    for name in (*CLASSICAL, "scanline-again"):
        assert read_layer(ws / "predictions" / name / "drive_d.h5").depth.shape[-2:] == DriveFile(
            ws / "drives" / "drive_d.h5").shape[-2:], name
    assert (ws / "filtered" / "planefit+edges+outlier" / "drive_d.h5").is_file()
