"""Depth denoising through the map (dcslam.depth.denoise, run by dcslam.stages.demo_icl): the noise model, the
denoiser wrapper, the frame split, and a short chamfer-only training that must beat the noisy input on frames of
another room."""
import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from dcslam.depth.denoise import MIN_NOISY_DEPTH_M, DenoiseConfig, DepthDenoiser, add_depth_noise, split_frames
from dcslam.stages.demo_icl import DemoIclConfig, demo_drives, drives_of, run, run_denoising
from dcslam.depth.models import build_model, load_model
from dcslam.errors import DcslamError
from dcslam.io.drive import DriveFrame, DriveWriter

H, W = 48, 64
K_ICL = np.array([[48.12, 0, 31.5], [0, -48.0, 23.5], [0, 0, 1.0]])  # ICL-NUIM's camera at 1/10 (fy < 0)


def _room_depth(T_world_cam: np.ndarray, boxes) -> np.ndarray:
    """(H, W) z-depth of a 5 × 3 × 5 m room (camera inside) with solid boxes, by ray casting."""
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    rays = np.stack([(u - K_ICL[0, 2]) / K_ICL[0, 0], (v - K_ICL[1, 2]) / K_ICL[1, 1], np.ones_like(u)], -1)
    d = rays @ T_world_cam[:3, :3].T
    o = T_world_cam[:3, 3]
    lo, hi = np.array([-2.5, -1.5, -2.5]), np.array([2.5, 1.5, 2.5])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.min(np.where(d > 0, (hi - o) / d, np.where(d < 0, (lo - o) / d, np.inf)), -1)
        for blo, bhi in boxes:
            t1, t2 = (np.array(blo) - o) / d, (np.array(bhi) - o) / d
            near, far = np.max(np.minimum(t1, t2), -1), np.min(np.maximum(t1, t2), -1)
            t = np.where((near < far) & (near > 0.1) & (near < t), near, t)
    return np.where(np.isfinite(t) & (t < 8), t, 0).astype(np.float32)


def write_room(path, n: int, seed: int, name: str, split: str = "train"):
    """A drive of ``n`` frames of a camera turning and drifting in a room with three random boxes (y up, fy < 0)."""
    rng = np.random.default_rng(seed)
    boxes = []
    for _ in range(3):
        centre = rng.uniform([-2, -1.5, -2], [2, 0, 2])
        half = rng.uniform(0.2, 0.6, 3)
        boxes.append((centre - half, centre + half))
    with DriveWriter(path, K_ICL, H, W, source="synthetic", date="", drive=name, split=split) as writer:
        for i in range(n):
            yaw = 2 * np.pi * i / n + seed
            c, s = np.cos(yaw), np.sin(yaw)
            T = np.eye(4)
            T[:3, :3] = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
            T[:3, 3] = [0.3 * np.sin(yaw), 0.2, 0.3 * np.cos(2 * yaw)]
            dense = _room_depth(T, boxes)
            dense[:3, :5] = 0  # a few pixels without depth
            writer.append(DriveFrame(rgb=np.zeros((H, W, 3), np.uint8), sparse=np.zeros_like(dense), dense=dense,
                                T_world_cam=T, timestamp=float(i), frame_id=i))
    return path


@pytest.fixture(scope="module")
def rooms(tmp_path_factory):
    """A drives folder: two training rooms and one test room, with splits.json."""
    root = tmp_path_factory.mktemp("rooms")
    splits = {"train": ["room_a", "room_b"], "val": [], "test": ["room_c"]}
    for seed, (split, name) in enumerate([("train", "room_a"), ("train", "room_b"), ("test", "room_c")]):
        write_room(root / f"{name}.h5", 12, seed, name, split)
    (root / "splits.json").write_text(json.dumps(splits))
    return root


class TestAddDepthNoise:
    def test_valid_pixels_get_gaussian_noise_and_holes_stay_empty(self):
        clean = torch.full((2, 1, 100, 100), 5.0)
        clean[:, :, :10] = 0
        noisy = add_depth_noise(clean, 0.1, torch.Generator().manual_seed(0))
        assert torch.equal(clean[:, :, :10], noisy[:, :, :10])
        noise = (noisy - clean)[:, :, 10:]
        assert abs(float(noise.mean())) < 0.005 and float(noise.std()) == pytest.approx(0.1, rel=0.03)
        assert torch.all(clean == torch.where(clean > 0, 5.0, 0.0))  # input untouched

    def test_depth_stays_positive_where_there_is_depth(self):
        clean = torch.full((1, 1, 50, 50), 0.05)
        noisy = add_depth_noise(clean, 1.0, torch.Generator().manual_seed(1))
        assert float(noisy.min()) == pytest.approx(MIN_NOISY_DEPTH_M) and bool((noisy > 0).all())

    def test_seeded(self):
        clean = torch.rand(1, 1, 8, 8) + 1
        a, b, c = (add_depth_noise(clean, 0.02, torch.Generator().manual_seed(s)) for s in (3, 3, 4))
        assert torch.equal(a, b) and not torch.equal(a, c)

    def test_bad_input(self):
        with pytest.raises(DcslamError, match=r"\(B, 1, H, W\)"):
            add_depth_noise(torch.ones(8, 8), 0.1)
        with pytest.raises(DcslamError, match="sigma"):
            add_depth_noise(torch.ones(1, 1, 8, 8), -0.1)


class TestDepthDenoiser:
    def test_only_pixels_with_depth_and_positive(self):
        model = DepthDenoiser(build_model("dncnn", features=8, depth=3), depth_scale_m=4.0).eval()
        noisy = torch.rand(2, 1, 12, 16) * 3 + 0.5
        noisy[:, :, :4] = 0
        out = model(noisy)
        assert out.shape == noisy.shape
        assert bool((out[:, :, :4] == 0).all()) and bool((out[:, :, 4:] > 0).all())

    def test_gradcheck_float64(self):
        torch.manual_seed(0)
        model = DepthDenoiser(build_model("dncnn", features=4, depth=3), depth_scale_m=2.0).double().eval()
        valid = torch.ones(1, 1, 6, 7, dtype=torch.bool)
        valid[0, 0, 0, :3] = False  # pixels without depth stay 0 (the mask is a step there: not checked)

        def denoise(depth_of_valid):
            noisy = torch.zeros(valid.shape, dtype=torch.float64).masked_scatter(valid, depth_of_valid)
            return model(noisy)

        depth = (torch.rand(int(valid.sum()), dtype=torch.float64) + 1.0).requires_grad_(True)
        assert torch.autograd.gradcheck(denoise, (depth,), eps=1e-6, atol=1e-5)


def test_held_out_frames_are_never_trained_on(rooms):
    config = DenoiseConfig(scale=1.0, train_drives=[rooms / "room_a.h5"], heldout_fraction=0.25)
    train, test = split_frames(config)
    assert train[0].frame_ids == list(range(9)) and test[0].frame_ids == [9, 10, 11]
    assert drives_of(rooms) == ([rooms / "room_a.h5", rooms / "room_b.h5"], [rooms / "room_c.h5"])
    assert drives_of(rooms / "room_a.h5") == ([rooms / "room_a.h5"], [])
    with pytest.raises(DcslamError, match="not found"):
        drives_of(rooms / "nowhere")


@pytest.mark.slow  # 60 training steps
def test_chamfer_only_training_beats_the_noisy_input_on_another_room(rooms, tmp_path):
    """A short training (chamfer between single-frame maps only) must bring the held-out room's depth closer to
    the clean depth than the noisy input is: MAE, RMSE and chamfer down, PSNR up. An untrained DnCNN starts as
    the identity, so this fails unless training learnt to denoise."""
    train, test = drives_of(rooms)
    config = DenoiseConfig(sigma_m=0.05, scale=1.0, steps=60, batch_size=4, patch=0, lr=1e-3, features=16,
                           layers=5, device="cpu", train_drives=train, test_drives=test, examples=2)
    result = run_denoising(tmp_path / "out", config)
    noisy, denoised = result.scores["noisy"], result.scores["denoised"]
    assert result.scores["frames"] == 12
    assert noisy["mae_mm"] == pytest.approx(0.05 * math.sqrt(2 / math.pi) * 1000, rel=0.05)  # E|N(0, σ²)|
    assert denoised["mae_mm"] < 0.8 * noisy["mae_mm"]
    assert denoised["rmse_mm"] < 0.8 * noisy["rmse_mm"]
    assert denoised["chamfer_m2"] < noisy["chamfer_m2"] and denoised["psnr_db"] > noisy["psnr_db"] + 1.0
    assert {p.name for p in (tmp_path / "out").iterdir()} == {"model.pt", "results.json", "results.csv",
                                                            "results.md", "denoising.png"}
    record = json.loads((tmp_path / "out" / "results.json").read_text())
    assert record["stage"] == "denoise" and len(record["losses"]) == 60
    assert record["frames"]["test"] == {"room_c": list(range(12))}
    net, meta = load_model(tmp_path / "out" / "model.pt")
    assert meta["depth_scale_m"] == config.depth_scale_m and net.hparams["depth"] == 5
    with pytest.raises(DcslamError, match="--force"):
        run_denoising(tmp_path / "out", config)


def test_config_errors(rooms, tmp_path):
    for bad in (dict(scale=0.3), dict(steps=0), dict(sigma_m=0.0), dict(heldout_fraction=1.0)):
        with pytest.raises(DcslamError):
            DenoiseConfig(train_drives=[rooms / "room_a.h5"], **bad)
    with pytest.raises(DcslamError, match="no training drives"):
        run_denoising(tmp_path / "out", DenoiseConfig())
    assert not (tmp_path / "out").exists()


def test_demo_drives_refuses_other_settings_without_force(tmp_path):
    (tmp_path / "data.json").write_text(json.dumps({"settings": {"sequences": 3, "frames": 9, "seed": 0}}))
    with pytest.raises(DcslamError, match="other settings"):
        demo_drives(tmp_path, sequences=2, frames=4, seed=0)
    with pytest.raises(DcslamError, match="at least 2 sequences"):
        demo_drives(tmp_path, sequences=1, frames=4, seed=0, force=True)


def test_stage_config_maps_to_the_experiment_and_runs_on_given_drives(rooms, tmp_path):
    from dcslam.workspace import Workspace

    config = DemoIclConfig(sigma_m=0.02, steps=2, batch_size=2, patch=16, features=4, layers=3, scale=1.0,
                           drives=rooms, device="cpu")
    experiment = config.denoise_config()
    assert (experiment.sigma_m, experiment.steps, experiment.features, experiment.layers) == (0.02, 2, 4, 3)
    with pytest.raises(DcslamError, match="sigma"):
        DemoIclConfig(sigma_m=0)
    result = run(Workspace(tmp_path / "ws"), config)
    assert result.out_dir == tmp_path / "ws" / "results" / "demo-icl"
    settings = json.loads((result.out_dir / "results.json").read_text())["settings"]
    assert settings["sigma_m"] == 0.02 and settings["test_drives"] == [str(rooms / "room_c.h5")]


def test_the_stage_declares_only_the_data_it_runs_on():
    import dataclasses

    from dcslam.depth.config import DenoiseSettings

    names = lambda cls: {f.name for f in dataclasses.fields(cls)}  # noqa: E731
    own = names(DemoIclConfig) - names(DenoiseSettings)
    assert own == {"frames", "sequences", "drives"} and not own & names(DenoiseConfig)
    experiment = DemoIclConfig(sigma_m=0.03, seed=4).denoise_config([Path("a.h5")])
    assert type(experiment) is DenoiseConfig and (experiment.sigma_m, experiment.seed) == (0.03, 4)
    assert experiment.train_drives == [Path("a.h5")] and experiment.warmup_fraction == DenoiseConfig().warmup_fraction
