"""Fill correction from a surface-preserving scaffold (``fill``: nearest, scanline, planefit) with a correction in
depth or in inverse depth (``fill_output``): the scaffold is its completer's output, the untrained network is the
scaffold's nearest fill exactly, the inverse-depth residual turns an affine correction into a plane, gradients check
in float64, the options are recorded only when not the default, and a tiny run trains, saves and predicts."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from dcslam.depth.models import build_model, load_model, save_model
from dcslam.depth.models.fill import FillCorrection, correction_options, depth_scale, nearest_fill
from dcslam.depth.models.planefit import complete_planefit
from dcslam.depth.models.scaffold import FILL_OUTPUTS, MAX_DEPTH_RATIO, inverse_residual, scaffold
from dcslam.depth.models.scanline import complete_scanline
from dcslam.errors import DcslamError
from tests.fixtures import depth as fixtures

CORRECTING = ("sparse-conv", "nconv", "nconv-guided")
H, W = 32, 64


def _street(b=2, seed=0, dtype=torch.float32) -> torch.Tensor:
    """(B, 1, H, W) sparse depth of the fixture's street: every 4th row below the top quarter, half of its pixels."""
    rng = np.random.default_rng(seed)
    K = fixtures.intrinsics(H, W)
    frames = []
    for i in range(b):
        exact = fixtures.cast_depth(K, H, W, cam_z=0.5 * i)
        sparse = np.zeros_like(exact)
        rows = np.arange(H // 4, H, 4)
        sparse[rows] = np.where(rng.random((len(rows), W)) < 0.5, exact[rows], 0)
        frames.append(sparse)
    return torch.from_numpy(np.stack(frames)[:, None]).to(dtype)


def _mask(x: torch.Tensor) -> torch.Tensor:
    return (x > 0).to(x.dtype)


def _run(net, x):
    rgb = (torch.rand(x.shape[0], 3, *x.shape[2:], dtype=x.dtype),) if getattr(net, "GUIDED", False) else ()
    return net(x, _mask(x), *rgb)


class TestScaffold:
    def test_nearest_is_the_input(self):
        x = _street()
        depth, mask = scaffold(x, _mask(x), "nearest")
        assert depth is x and torch.equal(mask, _mask(x))

    @pytest.mark.parametrize("fill, complete", [("scanline", complete_scanline), ("planefit", complete_planefit)])
    def test_is_the_completers_output_frame_by_frame(self, fill, complete):
        x = _street()
        depth, mask = scaffold(x, _mask(x), fill)
        for i in range(x.shape[0]):
            assert np.array_equal(depth[i, 0].numpy(), complete(x[i, 0].numpy()))
        assert torch.equal(mask, (depth > 0).float())
        assert torch.equal(depth[x > 0], x[x > 0])  # the returns keep their depth
        assert mask.sum() > 2 * _mask(x).sum()       # and the completer placed more than the returns

    def test_measured_depths_keep_their_gradient(self):
        x = _street(b=1, dtype=torch.float64).requires_grad_()
        depth, _ = scaffold(x, _mask(x.detach()), "scanline")
        depth.sum().backward()
        assert torch.equal(x.grad, _mask(x.detach()))  # the placed depths are a fixed function of the input

    def test_bad_inputs(self):
        x = _street()
        with pytest.raises(DcslamError, match="unknown fill 'bilinear'"):
            scaffold(x, _mask(x), "bilinear")
        with pytest.raises(DcslamError, match=r"expected \(B, 1, H, W\)"):
            scaffold(x[:, 0], _mask(x)[:, 0], "scanline")
        with pytest.raises(DcslamError, match="mask has shape"):
            scaffold(x, _mask(x)[..., :-1], "scanline")


class TestInverseResidual:
    def test_zero_correction_is_the_start_exactly(self):
        start = nearest_fill(_street())
        start[0, 0, :3] = 0  # no start: no depth
        scale = depth_scale(start, _mask(start))
        assert torch.equal(inverse_residual(start, torch.zeros_like(start), scale), start)

    def test_known_answer(self):
        start, correction, scale = (torch.tensor([2.0, 4.0]).view(2, 1, 1, 1), torch.tensor([0.5, -1.0])
                                    .view(2, 1, 1, 1), torch.tensor([10.0, 8.0]).view(2, 1, 1, 1))
        out = inverse_residual(start, correction, scale)  # 1 / (1/2 + 0.5/10) = 1.8181..., 1 / (1/4 - 1/8) = 8
        assert torch.allclose(out.flatten(), torch.tensor([1 / 0.55, 8.0]))

    def test_an_affine_correction_of_a_constant_start_is_a_plane(self):
        # the reason for the inverse-depth output: depth through a pinhole is a plane iff its inverse is affine in
        # (u, v); the same affine correction added to depth bends the surface
        K = torch.from_numpy(fixtures.intrinsics(H, W))
        v, u = torch.meshgrid(torch.arange(H, dtype=torch.float64), torch.arange(W, dtype=torch.float64),
                              indexing="ij")
        start = torch.full((1, 1, H, W), 10.0, dtype=torch.float64)
        scale = torch.full((1, 1, 1, 1), 10.0, dtype=torch.float64)
        correction = (0.3 + 0.01 * u - 0.02 * v)[None, None]

        def flatness_m(depth):
            rays = torch.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], torch.ones_like(u)], -1)
            points = (depth[0, 0, ..., None] * rays).reshape(-1, 3)
            centred = points - points.mean(0)
            return torch.linalg.svdvals(centred)[-1] / len(points) ** 0.5  # rms distance from the best plane

        assert flatness_m(inverse_residual(start, correction, scale)) < 1e-9
        assert flatness_m(start + scale * correction) > 1e-2

    def test_depth_is_at_most_the_ratio_times_the_start(self):
        start = torch.full((1, 1, 2, 2), 5.0)
        out = inverse_residual(start, torch.full_like(start, -1e3), torch.ones(1, 1, 1, 1))
        assert torch.allclose(out, start * MAX_DEPTH_RATIO)

    def test_gradcheck_float64(self):
        g = torch.Generator().manual_seed(0)
        start = (torch.rand(1, 1, 4, 5, generator=g, dtype=torch.float64) * 20 + 1).requires_grad_()
        correction = (torch.rand(1, 1, 4, 5, generator=g, dtype=torch.float64) - 0.5).requires_grad_()
        scale = torch.full((1, 1, 1, 1), 12.0, dtype=torch.float64, requires_grad=True)
        assert torch.autograd.gradcheck(inverse_residual, (start, correction, scale))


class TestScaffoldHead:
    @pytest.mark.parametrize("fill", ["scanline", "planefit"])
    @pytest.mark.parametrize("output", FILL_OUTPUTS)
    def test_untrained_head_is_the_nearest_fill_of_the_scaffold(self, fill, output):
        x = _street()
        head = FillCorrection(2, fill=fill, output=output)
        depth, gate = head(x, _mask(x), torch.rand(2, 2, H, W))
        placed, placed_mask = scaffold(x, _mask(x), fill)
        assert torch.equal(depth, nearest_fill(placed, placed_mask)) and torch.equal(depth[placed > 0],
                                                                                      placed[placed > 0])
        assert torch.allclose(gate, torch.full_like(gate, 4.0))

    def test_the_scaffold_mask_is_one_more_input_channel(self):
        assert FillCorrection(2).net[0].in_channels == 5  # the nearest fill's head as before: its model files load
        assert FillCorrection(2, fill="scanline").net[0].in_channels == 6
        with pytest.raises(DcslamError, match="expected a fill of nearest, scanline, planefit"):
            FillCorrection(2, fill="bilinear")

    def test_is_equivariant_to_the_scale_of_depth(self):
        torch.manual_seed(0)
        head = FillCorrection(1, fill="scanline", output="inverse-residual")
        torch.nn.init.normal_(head.net[-1].weight, std=0.05)
        x = _street()
        features = torch.rand(2, 1, H, W)  # scale-free already
        out = head(x, _mask(x), features)[0]
        assert not torch.equal(out, head.start(x, _mask(x))[0])
        assert torch.allclose(head(3 * x, _mask(x), features)[0], 3 * out, rtol=1e-4, atol=1e-4)

    @pytest.mark.parametrize("output", FILL_OUTPUTS)
    def test_gradcheck_float64(self, output):
        # gradients of the depth with respect to the network's features and the head's last layer (the scaffold
        # is a fixed function of the sparse input)
        torch.manual_seed(0)
        head = FillCorrection(1, width=3, fill="scanline", output=output).double()
        torch.nn.init.normal_(head.net[-1].weight, std=0.05)
        x = _street(b=1, dtype=torch.float64)[..., 8:20, 20:30]
        features = torch.rand(1, 1, 12, 10, dtype=torch.float64, requires_grad=True)
        names = ("net.6.weight", "net.6.bias")
        params = tuple(dict(head.named_parameters())[n].detach().clone().requires_grad_() for n in names)

        def depth(features, *last):
            return torch.func.functional_call(head, dict(zip(names, last)), (x, _mask(x), features))[0]

        assert torch.autograd.gradcheck(depth, (features, *params))


@pytest.mark.parametrize("arch", CORRECTING)
class TestScaffoldNetworks:
    @pytest.mark.parametrize("output", FILL_OUTPUTS)
    def test_untrained_network_is_the_scanline_scaffold_and_its_fill(self, arch, output):
        torch.manual_seed(0)
        x = _street()
        net = build_model(arch, correct_fill=True, fill="scanline", fill_output=output)
        assert torch.equal(_run(net, x), nearest_fill(*scaffold(x, _mask(x), "scanline")))
        assert net.hparams["fill"] == "scanline"
        assert net.hparams.get("fill_output", "depth") == output  # recorded only when not the default

    def test_defaults_are_not_recorded(self, arch):
        assert not {"fill", "fill_output"} & set(build_model(arch, correct_fill=True).hparams)
        assert not {"fill", "fill_output"} & set(build_model(arch).hparams)
        with pytest.raises(DcslamError, match="options of correct_fill"):
            build_model(arch, fill="scanline")

    def test_model_file_round_trip(self, arch, tmp_path):
        torch.manual_seed(0)
        net = build_model(arch, correct_fill=True, fill="planefit", fill_output="inverse-residual")
        with torch.no_grad():
            net.correction.net[-1].weight.normal_(0, 0.01)
        save_model(tmp_path / "m.pt", net)
        record = torch.load(tmp_path / "m.pt", weights_only=True)
        assert (record["hparams"]["fill"], record["hparams"]["fill_output"]) == ("planefit", "inverse-residual")
        back, _ = load_model(tmp_path / "m.pt")
        x = _street()
        torch.manual_seed(1)
        a = _run(net.eval(), x)
        torch.manual_seed(1)
        assert torch.equal(a, _run(back, x)) and not torch.equal(a, nearest_fill(*scaffold(x, _mask(x), "planefit")))

    def test_gradcheck_float64_inverse_residual_of_the_nearest_fill(self, arch):
        # with the nearest fill the whole network is differentiable with respect to the sparse depths
        torch.manual_seed(0)
        small = {"sparse-conv": {"channels": 2, "kernels": (3, 3, 1)}}.get(arch, {"channels": 1, "scales": 1})
        net = build_model(arch, correct_fill=True, fill_output="inverse-residual", **small).double()
        net.correction = FillCorrection(net.correction.features, width=2, output="inverse-residual").double()
        torch.nn.init.normal_(net.correction.net[-1].weight, std=0.05)
        g = torch.Generator().manual_seed(4)
        m = (torch.rand(1, 1, 8, 9, generator=g) < 0.3).double()
        rgb = (torch.rand(1, 3, 8, 9, dtype=torch.float64),) if arch == "nconv-guided" else ()
        v = (torch.rand(1, 1, 8, 9, generator=g, dtype=torch.float64) * 10 + 5).requires_grad_()
        assert torch.autograd.gradcheck(lambda v: net(v * m, m, *rgb), (v,))


def test_correction_options():
    assert correction_options(False) == {}
    assert correction_options(True) == {"correct_fill": True}
    assert correction_options(True, "planefit", "inverse-residual") == \
        {"correct_fill": True, "fill": "planefit", "fill_output": "inverse-residual"}
    with pytest.raises(DcslamError, match="options of correct_fill"):
        correction_options(False, fill_output="inverse-residual")
    with pytest.raises(DcslamError, match="expected a fill of"):
        correction_options(True, fill="bilinear")


def test_the_stage_checks_and_records_the_options():
    from dcslam.stages.train import TrainStageConfig

    config = TrainStageConfig(model="nconv", correct_fill=True, fill="scanline", fill_output="inverse-residual")
    assert config.model_hparams() == {"correct_fill": True, "fill": "scanline", "fill_output": "inverse-residual"}
    assert TrainStageConfig(model="nconv", correct_fill=True).model_hparams() == {"correct_fill": True}
    with pytest.raises(DcslamError, match="options of --correct-fill"):
        TrainStageConfig(model="nconv", fill="scanline")
    with pytest.raises(DcslamError, match="unknown --fill-output 'plane'"):
        TrainStageConfig(model="nconv", correct_fill=True, fill_output="plane")


def test_a_scaffold_run_trains_against_exact_depth_saves_and_predicts(cli, tmp_path):
    from dcslam.io.drive import DriveFile, read_layer

    ws = fixtures.write_workspace(tmp_path / "ws", n=2, extra=True)
    result = cli("train", "-w", ws, "--model", "sparse-conv", "--correct-fill", "--fill", "scanline",
                 "--fill-output", "inverse-residual", "--target", "exact", "--normal-weight", "1", "--max-frames", "2",
                 "--scale", "0.5", "--batch-size", "2", "--lr", "0.01", "--device", "cpu", "--name", "scaffold")
    assert result.exit_code == 0, result.output
    run = ws / "runs" / "scaffold"
    settings = json.loads((run / "config.json").read_text())["settings"]
    assert settings["model_hparams"] == {"correct_fill": True, "fill": "scanline", "fill_output": "inverse-residual"}
    rows = [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]
    assert all(np.isfinite(r["normal"]) for r in rows if r["kind"] == "train")
    record = torch.load(run / "model.pt", weights_only=True)
    assert record["hparams"]["fill"] == "scanline" and record["hparams"]["fill_output"] == "inverse-residual"
    # training moved the head off zero (untrained, the network is the scaffold's fill)
    assert record["state_dict"]["correction.net.6.weight"].abs().sum() > 0

    predicted = cli("predict", "-w", ws, "--run", "scaffold", "--device", "cpu")
    assert predicted.exit_code == 0, predicted.output
    layer = read_layer(ws / "predictions" / "scaffold" / "drive_d.h5")
    with DriveFile(ws / "drives" / "drive_d.h5") as drive:
        assert layer.depth.shape == drive.shape
    assert np.isfinite(layer.depth).all() and (layer.depth > 0).mean() > 0.5
