import numpy as np
import pytest
import torch

from dcslam.depth.models import build_model, save_model
from dcslam.depth.predict import NetworkCompleter, ip_basic_predictor
from dcslam.stages.predict import predict_drive, run_predictor
from dcslam.errors import DcslamError
from dcslam.io.drive import DriveFile, read_layer


def test_ip_basic_layer(drive_path, tmp_path):
    out = predict_drive(ip_basic_predictor("ip-basic"), drive_path, tmp_path / "p" / "drive.h5")
    layer = read_layer(out)
    with DriveFile(drive_path) as drive:
        assert layer.depth.shape == drive.shape and layer.depth.dtype == np.float32
        dense = drive.depth("dense", 0)
    assert layer.made_by == "ip-basic-fast" and layer.config["variant"] == "fast" and layer.drive == "drive.h5"
    valid = dense > 0
    assert np.median(np.abs(layer.depth[0][valid] - dense[valid])) < 1.0
    with pytest.raises(DcslamError, match="--force"):
        predict_drive(ip_basic_predictor("ip-basic-fast"), drive_path, out)
    predict_drive(ip_basic_predictor("ip-basic-multiscale"), drive_path, out, force=True)
    assert read_layer(out).made_by == "ip-basic-multiscale"
    with pytest.raises(DcslamError):
        ip_basic_predictor("ip-basic-slow")


def test_run_predictor_rebuilds_from_file(drive_path, tmp_path):
    torch.manual_seed(0)
    model = build_model("sparse-conv", channels=4)
    run = tmp_path / "runs" / "r"
    save_model(run / "model.pt", model, meta={"scale": 0.5, "epoch": 0, "step": 3})
    predictor = run_predictor(run, "cpu")
    assert predictor.completer.factor == 2 and predictor.config["checkpoint"] == {"epoch": 0, "step": 3}
    out = predict_drive(predictor, drive_path, tmp_path / "out.h5")
    with DriveFile(drive_path) as drive:
        assert read_layer(out).depth.shape == drive.shape
    with pytest.raises(DcslamError, match="dcslam train"):
        run_predictor(tmp_path / "runs" / "missing", "cpu")


def test_network_completer_full_resolution():
    model = build_model("sparse-conv", channels=4).eval()
    sparse = np.zeros((20, 30), np.float32)
    sparse[::3, ::2] = 7.0
    out = NetworkCompleter(model, "cpu", scale=1.0)(sparse)
    assert out.shape == (20, 30) and (out >= 0).all()
    assert NetworkCompleter(model, "cpu", scale=0.5)(sparse).shape == (20, 30)


class _Constant(torch.nn.Module):
    """A stand-in network whose output is a fixed map, to test what the completer does with it."""

    def __init__(self, out):
        super().__init__()
        self.out = torch.as_tensor(out)

    def forward(self, x, mask):
        return self.out[None, None].to(x.dtype)


def test_network_completer_turns_near_zero_depth_into_holes():
    out = np.array([[0.0, 0.0002, 0.0999], [0.1, 5.0, float("nan")]], np.float32)
    sparse = np.zeros((2, 3), np.float32)
    pred = NetworkCompleter(_Constant(out), "cpu")(sparse)
    np.testing.assert_array_equal(pred, np.array([[0, 0, 0], [0.1, 5.0, 0]], np.float32))
