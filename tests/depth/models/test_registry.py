import pytest
import torch

from dcslam.depth.models import build_model, load_model, save_model
from dcslam.errors import DcslamError


@pytest.mark.parametrize("arch,hparams", [("sparse-conv", {"channels": 4}), ("dncnn", {"depth": 4, "features": 8})])
def test_round_trip(tmp_path, arch, hparams):
    torch.manual_seed(0)
    model = build_model(arch, **hparams).eval()
    path = save_model(tmp_path / "m.pt", model, meta={"run": "x"})
    loaded, meta = load_model(path)
    assert meta == {"run": "x"} and loaded.hparams == model.hparams
    x = torch.rand(1, 1, 8, 12)
    assert torch.equal(loaded(x, (x > 0.5).float()), model(x, (x > 0.5).float()))


def test_malformed_files(tmp_path):
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(DcslamError):
        load_model(bad)
    torch.save({"something": torch.zeros(1)}, tmp_path / "other.pt")
    with pytest.raises(DcslamError, match="not a dcslam model"):
        load_model(tmp_path / "other.pt")
    with pytest.raises(DcslamError, match="not found"):
        load_model(tmp_path / "missing.pt")


def test_mismatched_weights(tmp_path):
    path = save_model(tmp_path / "m.pt", build_model("sparse-conv", channels=4))
    record = torch.load(path, weights_only=True)
    record["hparams"]["channels"] = 8
    torch.save(record, path)
    with pytest.raises(DcslamError, match="do not fit"):
        load_model(path)


def test_unknown_arch():
    with pytest.raises(DcslamError):
        build_model("resnet")
    with pytest.raises(DcslamError):
        build_model("sparse-conv", width=3)
