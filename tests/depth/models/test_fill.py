"""The nearest-neighbour fill as a torch op and the fill-correcting networks (``correct_fill``)."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from dcslam.depth.models import build_model, load_model, save_model
from dcslam.depth.models.fill import FillCorrection, depth_scale, nearest_fill, nearest_indices
from dcslam.errors import DcslamError

CORRECTING = ("sparse-conv", "nconv", "nconv-guided")


def _sparse(b=2, h=20, w=30, density=0.06, seed=0, dtype=torch.float32):
    g = torch.Generator().manual_seed(seed)
    mask = torch.rand(b, 1, h, w, generator=g) < density
    x = torch.zeros(b, 1, h, w, dtype=dtype)
    x[mask] = (torch.rand(int(mask.sum()), generator=g, dtype=dtype) * 30 + 2)
    return x


def _run(net, x):
    rgb = (torch.rand(x.shape[0], 3, *x.shape[2:], dtype=x.dtype),) if getattr(net, "GUIDED", False) else ()
    return net(x, (x > 0).to(x.dtype), *rgb)


class TestNearestFill:
    def test_known_answer(self):
        x = torch.zeros(1, 1, 3, 6)
        x[0, 0, 0, 0], x[0, 0, 2, 5] = 1.0, 2.0
        expected = torch.tensor([[1, 1, 1, 2, 2, 2]] * 3, dtype=torch.float32)
        # e.g. (0, 2) is 2 from (0, 0) and 3.6 from (2, 5); (2, 2) is 2.83 from (0, 0) and 3 from (2, 5)
        assert torch.equal(nearest_fill(x)[0, 0], expected)

    def test_measured_pixels_keep_their_depth_and_every_pixel_takes_its_nearest(self):
        x = _sparse()
        y = nearest_fill(x)
        measured = x > 0
        assert torch.equal(y[measured], x[measured]) and (y > 0).all()
        # brute force: the distance to the pixel whose value was taken is the least distance to a measured pixel
        index, distance = nearest_indices((x > 0).float())
        w = x.shape[-1]
        for b in range(x.shape[0]):
            rows, cols = np.nonzero(x[b, 0].numpy())
            grid_r, grid_c = np.mgrid[:x.shape[2], :x.shape[3]]
            least = np.min((grid_r[..., None] - rows) ** 2 + (grid_c[..., None] - cols) ** 2, axis=-1)
            taken = index[b].numpy().reshape(x.shape[2:])
            assert np.array_equal((grid_r - taken // w) ** 2 + (grid_c - taken % w) ** 2, least)
            assert np.allclose(distance[b, 0].numpy(), np.sqrt(least))

    def test_matches_the_benchmarks_numpy_fill(self):
        from scipy.ndimage import distance_transform_edt

        x = _sparse(b=1, h=37, w=53, density=0.04, seed=3)[0, 0].numpy()
        _, (rows, cols) = distance_transform_edt(x == 0, return_indices=True)
        assert np.array_equal(nearest_fill(torch.from_numpy(x)[None, None])[0, 0].numpy(), x[rows, cols])

    def test_empty_frame_stays_empty(self):
        x = _sparse(b=2)
        x[1] = 0
        y = nearest_fill(x)
        assert y[1].eq(0).all() and (y[0] > 0).all()

    def test_gradcheck_float64(self):
        x = _sparse(b=1, h=6, w=7, density=0.3, seed=1, dtype=torch.float64)
        m = (x > 0).double()
        v = (torch.rand(1, 1, 6, 7, dtype=torch.float64) + 1).requires_grad_()
        assert torch.autograd.gradcheck(lambda v: nearest_fill(v * m, m), (v,))

    def test_bad_shapes(self):
        with pytest.raises(DcslamError, match=r"expected \(B, 1, H, W\)"):
            nearest_fill(torch.zeros(1, 2, 4, 4))
        with pytest.raises(DcslamError, match="mask has shape"):
            nearest_fill(torch.zeros(1, 1, 4, 4), torch.zeros(1, 1, 4, 5))
        with pytest.raises(DcslamError, match="mask has shape"):
            nearest_indices(torch.zeros(4, 4))


class TestFillCorrection:
    def test_untrained_head_returns_the_fill(self):
        x = _sparse()
        head = FillCorrection(2)
        depth, gate = head(x, (x > 0).float(), torch.rand(2, 2, 20, 30))
        assert torch.equal(depth, nearest_fill(x)) and torch.allclose(gate, torch.full_like(gate, 4.0))

    def test_is_equivariant_to_the_scale_of_depth(self):
        torch.manual_seed(0)
        head = FillCorrection(1)
        torch.nn.init.normal_(head.net[-1].weight, std=0.1)
        x = _sparse()
        m = (x > 0).float()
        features = torch.rand(2, 1, 20, 30)  # scale-free already
        assert torch.allclose(head(3 * x, m, features)[0], 3 * head(x, m, features)[0], rtol=1e-5, atol=1e-4)
        assert torch.allclose(depth_scale(3 * x, m), 3 * depth_scale(x, m))

    def test_wrong_features(self):
        x = _sparse()
        with pytest.raises(DcslamError, match="features have shape"):
            FillCorrection(2)(x, (x > 0).float(), torch.zeros(2, 3, 20, 30))

    def test_gradcheck_float64(self):
        torch.manual_seed(0)
        head = FillCorrection(1, width=3).double()
        torch.nn.init.normal_(head.net[-1].weight, std=0.3)
        x = _sparse(b=1, h=6, w=7, density=0.3, seed=2, dtype=torch.float64)
        m = (x > 0).double()
        v = (torch.rand(1, 1, 6, 7, dtype=torch.float64) + 1).requires_grad_()
        f = torch.rand(1, 1, 6, 7, dtype=torch.float64, requires_grad=True)
        assert torch.autograd.gradcheck(lambda v, f: head(v * m, m, f)[0], (v, f))


@pytest.mark.parametrize("arch", CORRECTING)
class TestCorrectingNetworks:
    def test_untrained_network_is_the_fill_and_the_option_is_recorded(self, arch):
        torch.manual_seed(0)
        x = _sparse()
        net = build_model(arch, correct_fill=True)
        assert torch.equal(_run(net, x), nearest_fill(x))
        assert net.hparams["correct_fill"] is True and "correct_fill" not in build_model(arch).hparams

    def test_model_file_round_trip(self, arch, tmp_path):
        torch.manual_seed(0)
        net = build_model(arch, correct_fill=True)
        with torch.no_grad():
            for p in net.parameters():
                p.add_(0.01 * torch.randn_like(p))
        save_model(tmp_path / "m.pt", net)
        back, _ = load_model(tmp_path / "m.pt")
        x = _sparse()
        torch.manual_seed(1)
        a = _run(net.eval(), x)
        torch.manual_seed(1)
        assert torch.equal(a, _run(back, x)) and not torch.equal(a, nearest_fill(x))

    def test_gradcheck_float64(self, arch):
        torch.manual_seed(0)
        small = {"sparse-conv": {"channels": 2, "kernels": (3, 3, 1)}}.get(arch, {"channels": 1, "scales": 1})
        net = build_model(arch, correct_fill=True, **small).double()
        net.correction = FillCorrection(net.correction.features, width=2).double()
        torch.nn.init.normal_(net.correction.net[-1].weight, std=0.3)
        x = _sparse(b=1, h=8, w=9, density=0.3, seed=4, dtype=torch.float64)
        m = (x > 0).double()
        rgb = (torch.rand(1, 3, 8, 9, dtype=torch.float64),) if arch == "nconv-guided" else ()
        v = (torch.rand(1, 1, 8, 9, dtype=torch.float64) + 1).requires_grad_()
        assert torch.autograd.gradcheck(lambda v: net(v * m, m, *rgb), (v,))


def test_nconv_confidence_is_gated_by_the_head():
    torch.manual_seed(0)
    net = build_model("nconv", correct_fill=True)
    x = _sparse()
    m = (x > 0).float()
    _, confidence = net.forward_with_confidence(x, m)
    with torch.no_grad():
        net.correction.net[-1].bias[1] = -20.0  # the head says: trust nothing
    assert (confidence > 0).any() and net.forward_with_confidence(x, m)[1].max() < 1e-6
