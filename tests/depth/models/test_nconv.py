import pytest
import torch

from dcslam.depth.models import build_model
from dcslam.depth.models.nconv import NConv2d, NConvCNN, pool_by_confidence
from dcslam.errors import DcslamError


class TestNConv2d:
    def test_known_answer_weighted_average_and_confidence(self):
        layer = NConv2d(1, 1, 3, eps=0.0)
        with torch.no_grad():
            layer.weight.fill_(10.0)  # softplus(10) ≈ 10: equal weights
        x, c = torch.zeros(1, 1, 5, 5), torch.zeros(1, 1, 5, 5)
        x[0, 0, 2, 2], c[0, 0, 2, 2] = 4.0, 1.0
        x[0, 0, 2, 3], c[0, 0, 2, 3] = 8.0, 0.5
        x[0, 0, 0, 0] = 100.0  # no confidence: must not leak in
        y, c2 = layer(x, c)
        assert y[0, 0, 2, 2].item() == pytest.approx((4 + 0.5 * 8) / 1.5)
        assert c2[0, 0, 2, 2].item() == pytest.approx(1.5 / 9, rel=1e-4)
        assert y[0, 0, 1, 1].item() == pytest.approx(4.0)

    def test_gradcheck_float64(self):
        torch.manual_seed(0)
        layer = NConv2d(2, 2, 3).double()
        x = torch.rand(1, 2, 5, 6, dtype=torch.float64, requires_grad=True) + 0.5
        c = torch.rand(1, 2, 5, 6, dtype=torch.float64, requires_grad=True) * 0.9 + 0.05

        def call(x, c, w):
            y, c2 = torch.func.functional_call(layer, {"weight": w}, (x, c))
            return y, c2

        assert torch.autograd.gradcheck(call, (x, c, layer.weight))

    def test_pool_keeps_the_most_confident(self):
        x = torch.arange(16.0).view(1, 1, 4, 4)
        c = torch.zeros(1, 1, 4, 4)
        c[0, 0, 1, 0], c[0, 0, 3, 3] = 0.9, 0.4
        xs, cs = pool_by_confidence(x, c)
        assert xs.shape == cs.shape == (1, 1, 2, 2)
        assert xs[0, 0, 0, 0] == 4.0 and xs[0, 0, 1, 1] == 15.0 and cs[0, 0, 0, 0] == pytest.approx(0.9)


class TestNConvCNN:
    @pytest.mark.parametrize("batch, size", [(1, (16, 24)), (3, (37, 50))])
    def test_shapes_confidence_and_scale_equivariance(self, batch, size):
        torch.manual_seed(0)
        net = build_model("nconv")
        assert isinstance(net, NConvCNN) and sum(p.numel() for p in net.parameters()) < 1000
        x = torch.rand(batch, 1, *size) * 20 * (torch.rand(batch, 1, *size) > 0.9)
        depth, confidence = net.forward_with_confidence(x)
        assert depth.shape == confidence.shape == (batch, 1, *size)
        assert (confidence >= 0).all() and (confidence <= 1).all()
        assert torch.allclose(net(3 * x), 3 * depth, rtol=1e-4, atol=1e-4)

    def test_confidence_is_higher_where_the_input_is(self):
        torch.manual_seed(0)
        x = torch.zeros(1, 1, 32, 32)
        x[..., :16, :] = 5.0 * (torch.rand(1, 1, 16, 32) > 0.5)
        _, confidence = build_model("nconv").forward_with_confidence(x)
        assert confidence[..., :12, :].mean() > 3 * confidence[..., 20:, :].mean()

    def test_invariant_to_values_without_confidence(self):
        torch.manual_seed(0)
        net = build_model("nconv")
        x = torch.rand(1, 1, 16, 24) * 10
        m = (torch.rand(1, 1, 16, 24) > 0.8).float()
        assert torch.allclose(net(x, m), net(x + 50 * (1 - m) * torch.rand_like(x), m), atol=1e-5)

    def test_bad_input(self):
        with pytest.raises(DcslamError):
            NConvCNN()(torch.rand(1, 2, 8, 8), torch.ones(1, 1, 8, 8))
        with pytest.raises(DcslamError, match="odd"):
            NConv2d(1, 1, 4)
        with pytest.raises(DcslamError):
            build_model("nconv", channels=0)


class TestGuidedNConvCNN:
    def test_untrained_equals_the_unguided_network_and_checks_rgb(self):
        from dcslam.depth.models import is_guided
        from dcslam.depth.models.nconv import GuidedNConvCNN

        torch.manual_seed(0)
        net = build_model("nconv-guided")
        assert isinstance(net, GuidedNConvCNN) and is_guided("nconv-guided") and not is_guided("nconv")
        x = torch.rand(2, 1, 20, 30) * 20 * (torch.rand(2, 1, 20, 30) > 0.9)
        rgb = torch.rand(2, 3, 20, 30)
        depth, confidence = net.forward_with_confidence(x, None, rgb)
        plain, plain_confidence = net.nconv.forward_with_confidence(x)
        assert torch.allclose(depth, plain) and torch.allclose(confidence, plain_confidence * torch.sigmoid(
            torch.tensor(4.0)))
        assert torch.allclose(net(2 * x, None, rgb), 2 * depth, rtol=1e-4, atol=1e-4)
        with pytest.raises(DcslamError, match="needs the colour image"):
            net(x)
        with pytest.raises(DcslamError, match="rgb has shape"):
            net(x, None, torch.rand(2, 3, 20, 31))

    def test_gradients_reach_the_refinement(self):
        torch.manual_seed(0)
        net = build_model("nconv-guided").double()
        x = (torch.rand(1, 1, 12, 16) * 20 * (torch.rand(1, 1, 12, 16) > 0.8)).double()
        net(x, None, torch.rand(1, 3, 12, 16, dtype=torch.float64)).sum().backward()
        assert net.refine[-1].weight.grad.abs().sum() > 0 and net.nconv.out.weight.grad.abs().sum() > 0
