"""Broken model and checkpoint files: one line naming the file and what to do, never a traceback."""
import pytest
import torch

from dcslam.depth.models import build_model, load_model, save_model
from dcslam.depth.train import read_checkpoint
from dcslam.errors import DcslamError


@pytest.fixture(scope="module")
def model_bytes(tmp_path_factory):
    path = tmp_path_factory.mktemp("m") / "model.pt"
    save_model(path, build_model("sparse-conv"))
    return path.read_bytes()


@pytest.mark.parametrize("keep", [0, 10, 0.5, -100])
def test_truncated_model_file(tmp_path, model_bytes, keep):
    path = tmp_path / "model.pt"
    n = int(len(model_bytes) * keep) if isinstance(keep, float) else (keep if keep >= 0 else len(model_bytes) + keep)
    path.write_bytes(model_bytes[:n])
    with pytest.raises(DcslamError, match=r"model.pt: not a readable model file \(.*\); retrain it"):
        load_model(path)


class _Evil:
    def __reduce__(self):
        return (print, ("pwned",))


@pytest.mark.parametrize("content", ["empty", "evil", "not-a-checkpoint", "wrong-weights"])
def test_broken_resume_checkpoint(tmp_path, content):
    path = tmp_path / "last.pt"
    model = build_model("sparse-conv")
    optimizer = torch.optim.AdamW(model.parameters())
    if content == "empty":
        path.write_bytes(b"")
    elif content == "evil":
        torch.save({"x": _Evil()}, path)
    elif content == "not-a-checkpoint":
        torch.save({"epoch": 1}, path)
    else:
        torch.save({"model": {"state_dict": {"w": torch.zeros(2)}}, "optimizer": {}}, path)
    with pytest.raises(DcslamError, match=r"last.pt: not a .*; start the run again with --force") as error:
        read_checkpoint(path, model, optimizer)
    assert "\n" not in str(error.value)
