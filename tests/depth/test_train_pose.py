"""Training with the pose loss (``--loss pose``): it lowers the pose error, logs its terms, validates by it, and
fine-tunes from another run (``init``)."""
import json

import pytest
import torch

from dcslam.depth.data import DriveFrames
from dcslam.depth.models import load_model
from dcslam.depth.recipes import recipe_label, run_name
from dcslam.depth.train import TrainConfig, initial_model, run_model
from dcslam.depth.train_pose import pose_loss_of
from dcslam.errors import DcslamError
from dcslam.stages.train import train


def _config(ws, **kw):
    drives = ws / "drives"
    base = dict(loss="pose", train_drives=[drives / "drive_a.h5"], val_drives=[], model="sparse-conv",
                device="cpu", pose_frames=3, pose_iterations=5)
    base.update(kw)
    return TrainConfig(**base)


def _rows(run):
    return [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]


def _pose_error(model, config, path) -> float:
    frames = DriveFrames(path, config.max_frames, 1, 1.0, 0, "sparse", "dense")
    try:
        batch = frames.load(range(len(frames)))
        with torch.no_grad():
            return float(pose_loss_of(config)(run_model(model, batch), batch.K, batch.T_world_cam)[0])
    finally:
        frames.close()


def test_pose_training_lowers_the_pose_error_on_its_frames(workspace):
    config = _config(workspace, epochs=4, lr=1e-3)
    torch.manual_seed(config.seed)
    before = _pose_error(initial_model(config), config, config.train_drives[0])
    result = train(workspace / "runs" / "pose", config)
    after = _pose_error(result.model, config, config.train_drives[0])
    assert result.steps == 4 * 2  # 6 frames: two windows of 3
    assert after < 0.97 * before, (before, after)


def test_pose_run_logs_its_terms_and_keeps_the_best_pose_checkpoint(workspace):
    drives = workspace / "drives"
    run = workspace / "runs" / "pose-mse"
    result = train(run, _config(workspace, epochs=2, pose_frames=4, mse_weight=0.5, val_drives=[drives / "drive_c.h5"]))
    rows = _rows(run)
    train_rows = [r for r in rows if r["kind"] == "train"]
    assert len(train_rows) == 2 * 2  # windows 0-3 and 4-5 of 6 frames, per epoch
    first = train_rows[0]
    assert {"pose", "mse", "pose_translation_m", "pose_rotation_rad", "pose_rejected"} <= set(first)
    assert first["loss"] == pytest.approx(first["pose"] + 0.5 * first["mse"], rel=1e-5)
    vals = [r for r in rows if r["kind"] == "val"]
    assert all({"pose", "pose_translation_m", "pose_rotation_rad", "mse", "chamfer"} <= set(v) for v in vals)
    _, meta = load_model(run / "model.pt")
    assert meta["selected_by"] == "pose" and meta["step"] == min(vals, key=lambda v: v["pose"])["step"]
    assert result.best["pose"] == min(v["pose"] for v in vals)
    settings = json.loads((run / "config.json").read_text())["settings"]
    assert settings["loss"] == "pose" and settings["mse_weight"] == 0.5 and settings["pose_frames"] == 4


def test_a_single_frame_window_is_skipped(workspace):
    result = train(workspace / "runs" / "p", _config(workspace, pose_frames=5))
    assert result.steps == 1  # windows 0-4 and 5: the lone frame has no pose to compare


def test_init_starts_from_the_other_run(workspace):
    drives = workspace / "drives"
    mse = train(workspace / "runs" / "mse-dense", TrainConfig(train_drives=[drives / "drive_a.h5"], device="cpu",
                                                              model="sparse-conv", max_frames=2))
    init = mse.run_dir / "model.pt"
    config = _config(workspace, init_model=init)
    start = initial_model(config).state_dict()
    saved, _ = load_model(init)
    assert all(torch.equal(start[k], v) for k, v in saved.state_dict().items())
    run = train(workspace / "runs" / "pose-from-mse-dense", config).run_dir
    settings = json.loads((run / "config.json").read_text())["settings"]
    assert settings["init"] == "runs/mse-dense/model.pt"  # relative to the workspace holding the run
    assert recipe_label(settings) == "pose, fine-tuned from mse-dense"
    assert recipe_label({"loss": "pose"}) == "pose from scratch"
    assert run_name("pose", "dense", 1, "chamfer-8") == "pose-from-chamfer-8" and run_name("pose", "dense", 1) == "pose"
    with pytest.raises(DcslamError, match="not nconv"):
        initial_model(_config(workspace, init_model=init, model="nconv"))
    with pytest.raises(DcslamError, match="not found"):
        initial_model(_config(workspace, init_model=workspace / "runs" / "none" / "model.pt"))


@pytest.mark.parametrize("bad", [dict(pose_frames=1), dict(pose_weight=-1.0), dict(mse_weight=float("nan")),
                                 dict(pose_iterations=0), dict(pose_grad_iterations=-1), dict(pose_max_sources=-1),
                                 dict(pose_rotation_weight=float("inf"))])
def test_bad_pose_options(workspace, bad):
    with pytest.raises(DcslamError, match="--pose|--mse"):
        _config(workspace, **bad)


def test_nconv_confidence_weights_the_icp(workspace):
    losses = {}
    for weights in ("confidence", "none"):
        run = workspace / "runs" / weights
        train(run, _config(workspace, model="nconv", max_frames=3, pose_weights=weights))
        losses[weights] = _rows(run)[0]["pose"]
    assert losses["confidence"] != pytest.approx(losses["none"], rel=1e-6)
    with pytest.raises(DcslamError, match="--pose-weights"):
        _config(workspace, pose_weights="depth")


def test_pose_validation_draws_its_pixel_subsets_from_a_fixed_seed(workspace):
    # pose_max_sources keeps a random subset of each frame's pixels: two validations of the same model must agree
    # (a model before and after fine-tuning is compared on the same pixels), and the caller's stream is untouched
    from dcslam.depth.train_pose import validate_pose

    config = _config(workspace, pose_max_sources=200)
    model = initial_model(config)
    frames = DriveFrames(config.train_drives[0], config.max_frames, 1, 1.0, 0, "sparse", "dense")
    try:
        torch.manual_seed(1)
        first = validate_pose(model, [frames], pose_loss_of(config), 3, torch.device("cpu"))
        after_first = torch.rand(3)
        torch.manual_seed(2)
        second = validate_pose(model, [frames], pose_loss_of(config), 3, torch.device("cpu"))
        torch.manual_seed(1)
        assert torch.equal(torch.rand(3), after_first)
    finally:
        frames.close()
    assert first == second


def test_pose_training_is_reproducible(workspace):
    """Same data, seed and code: bit-identical weights (the pose rows of Table 5.2 are single runs, so a second
    run must give the same network)."""
    config = _config(workspace, epochs=1, lr=1e-3)
    first = train(workspace / "runs" / "pose-a", config).model.state_dict()
    second = train(workspace / "runs" / "pose-b", config).model.state_dict()
    assert first.keys() == second.keys()
    assert all(torch.equal(first[k], second[k]) for k in first)
    torch.manual_seed(config.seed)  # the initialisation train() starts from
    start = initial_model(config).state_dict()
    assert not all(torch.equal(first[k], start[k]) for k in first)  # it trained
