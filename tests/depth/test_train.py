import json

import pytest
import torch

from dcslam.depth.maps import stacked_points_map
from dcslam.depth.models import load_model
from dcslam.depth.train import TrainConfig
from dcslam.device import resolve_device
from dcslam.stages.train import train
from dcslam.errors import DcslamError


def _config(ws, **kw):
    drives = ws / "drives"
    base = dict(train_drives=[drives / "drive_a.h5", drives / "drive_b.h5"], val_drives=[drives / "drive_c.h5"],
                model_hparams={"channels": 4}, batch_size=2, device="cpu")
    base.update(kw)
    return TrainConfig(**base)


def _rows(run):
    return [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]


def test_mse_dense_run_writes_everything(workspace):
    run = workspace / "runs" / "mse-dense"
    result = train(run, _config(workspace, epochs=2))
    for name in ("model.pt", "last.pt", "config.json", "metrics.jsonl", "curves.png"):
        assert (run / name).stat().st_size > 0
    rows = _rows(run)
    train_rows = [r for r in rows if r["kind"] == "train"]
    val_rows = [r for r in rows if r["kind"] == "val"]
    assert len(train_rows) == 2 * 2 * 3 and result.steps == 12  # 2 epochs x 2 drives x 3 batches of 2 frames
    assert set(train_rows[0]) == {"kind", "epoch", "step", "drive", "loss", "lr"}
    assert [r["drive"] for r in train_rows[:6]] == ["drive_a"] * 3 + ["drive_b"] * 3  # drives in turn
    assert len(val_rows) == 2 and set(val_rows[0]) == {"kind", "epoch", "step", "chamfer", "mse", "mae_mm", "rmse_mm"}
    assert val_rows[0]["rmse_mm"] == pytest.approx(1000 * val_rows[0]["mse"] ** 0.5)
    config = json.loads((run / "config.json").read_text())
    assert config["settings"]["loss"] == "mse" and config["settings"]["mask"] == "dense"
    assert config["settings"]["lr"] == 1e-3 and config["settings"]["weight_decay"] == 0.01
    model, meta = load_model(run / "model.pt")
    best = min(val_rows, key=lambda r: r["mse"])
    assert meta["step"] == best["step"]  # the best validation checkpoint is the one kept


@pytest.mark.parametrize("model, lr", [("sparse-conv", 1e-3), ("nconv", 1e-2), ("nconv-guided", 1e-2)])
def test_training_reduces_the_loss(workspace, model, lr):
    run = workspace / "runs" / model
    train(run, _config(workspace, epochs=4, model=model, model_hparams={}, lr=lr))
    rows = _rows(run)
    first = [r["loss"] for r in rows if r["kind"] == "train" and r["epoch"] == 0]
    last = [r["loss"] for r in rows if r["kind"] == "train" and r["epoch"] == 3]
    assert sum(last) < 0.95 * sum(first)
    vals = [r for r in rows if r["kind"] == "val"]
    assert vals[-1]["rmse_mm"] < vals[0]["rmse_mm"]


def test_chamfer_multi_frame(workspace):
    run = workspace / "runs" / "chamfer-8"
    train(run, _config(workspace, loss="chamfer", map_frames=8, max_frames=4))
    rows = _rows(run)
    assert sum(r["kind"] == "train" for r in rows) == 2  # one window of 4 frames per drive
    assert all(r["loss"] > 0 for r in rows if r["kind"] == "train")


def test_refuses_to_overwrite_and_resume_matches_uninterrupted(workspace):
    straight = workspace / "runs" / "straight"
    train(straight, _config(workspace, epochs=2, loss="chamfer"), map_builder=stacked_points_map)

    run = workspace / "runs" / "interrupted"
    calls = {"n": 0}

    def flaky(depth, K, T):
        calls["n"] += 1
        if calls["n"] == 4 * 4 + 1:  # 2 frames x 2 maps (pred, gt) per step: dies in step 4, inside drive_b
            raise KeyboardInterrupt
        return stacked_points_map(depth, K, T)

    with pytest.raises(KeyboardInterrupt):
        train(run, _config(workspace, epochs=2, loss="chamfer"), map_builder=flaky)
    with pytest.raises(DcslamError, match="--force"):
        train(run, _config(workspace, epochs=2, loss="chamfer"), map_builder=stacked_points_map)
    result = train(run, _config(workspace, epochs=2, loss="chamfer"), resume=True, map_builder=stacked_points_map)
    assert result.steps == 12
    a = torch.load(straight / "last.pt", weights_only=True)["model"]["state_dict"]
    b = torch.load(run / "last.pt", weights_only=True)["model"]["state_dict"]
    assert all(torch.allclose(a[k], b[k], atol=1e-6) for k in a)
    assert [r["step"] for r in _rows(run) if r["kind"] == "train"] == list(range(12))
    train(run, _config(workspace, epochs=1), force=True)
    assert len(_rows(run)) == 6 + 1


def test_bad_options(workspace, tmp_path):
    with pytest.raises(DcslamError, match="nothing to resume"):
        train(tmp_path / "none", _config(workspace), resume=True)
    for bad in (dict(loss="l1"), dict(mask="half"), dict(model="unet"), dict(scale=0.3), dict(epochs=0),
                dict(train_drives=[])):
        with pytest.raises(DcslamError):
            train(tmp_path / "bad", _config(workspace, **bad))
    with pytest.raises(DcslamError):
        resolve_device("tpu")
    assert resolve_device("auto").type in ("cpu", "cuda")

