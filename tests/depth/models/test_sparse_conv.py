import pytest
import torch
import torch.nn.functional as F

from dcslam.depth.models.sparse_conv import SparseConv, SparseConvNet
from dcslam.errors import DcslamError


class TestSparseConv:
    def test_smoke_shapes(self, device, dtype):
        layer = SparseConv(1, 4, 5).to(device, dtype)
        x = torch.rand(2, 1, 12, 16, device=device, dtype=dtype)
        m = (torch.rand(2, 1, 12, 16, device=device) > 0.7).to(dtype)
        y, m2 = layer(x, m)
        assert y.shape == (2, 4, 12, 16) and m2.shape == (2, 1, 12, 16)
        assert y.device.type == device.type and y.dtype == m2.dtype == dtype
        assert (y >= 0).all()

    def test_known_answer_normalised_average(self):
        # one-channel layer, all weights 1, bias 0.5: output = mean of valid inputs in the window + bias
        layer = SparseConv(1, 1, 3, eps=0.0)
        with torch.no_grad():
            layer.weight.fill_(1.0)
            layer.bias.fill_(0.5)
        x = torch.zeros(1, 1, 5, 5)
        m = torch.zeros(1, 1, 5, 5)
        x[0, 0, 2, 2], m[0, 0, 2, 2] = 4.0, 1.0
        x[0, 0, 2, 3], m[0, 0, 2, 3] = 8.0, 1.0
        x[0, 0, 0, 0] = 100.0  # masked out: must not leak in
        y, m2 = layer(x, m)
        assert y[0, 0, 2, 2].item() == pytest.approx(6.5)
        assert y[0, 0, 1, 1].item() == pytest.approx(4.5)
        # mask propagation = 3x3 max pooling
        assert m2[0, 0, 1:4, 1:5].eq(1).all() and m2[0, 0, 0].eq(0).all()

    def test_invariant_to_values_outside_mask(self):
        torch.manual_seed(0)
        net = SparseConvNet()
        x = torch.rand(1, 1, 16, 24) * 10
        m = (torch.rand(1, 1, 16, 24) > 0.8).float()
        noise = torch.rand_like(x) * 100 * (1 - m)
        assert torch.allclose(net(x, m), net(x + noise, m), atol=1e-5)

    def test_gradcheck_float64(self):
        torch.manual_seed(0)
        layer = SparseConv(2, 2, 3).double()
        x = torch.rand(1, 2, 5, 6, dtype=torch.float64, requires_grad=True) + 0.5
        m = (torch.rand(1, 1, 5, 6) > 0.5).double()
        # no ReLU kinks: make the bias large so every output is positive
        with torch.no_grad():
            layer.bias.fill_(5.0)
        assert torch.autograd.gradcheck(lambda x, w, b: _call(layer, x, m, w, b), (x, layer.weight, layer.bias))

    def test_bad_shapes(self):
        net = SparseConvNet()
        with pytest.raises(DcslamError):
            net(torch.rand(1, 2, 8, 8), torch.ones(1, 1, 8, 8))
        with pytest.raises(DcslamError):
            net(torch.rand(1, 1, 8, 8), torch.ones(1, 1, 8, 9))
        with pytest.raises(DcslamError):
            SparseConv(1, 1, 4)


def _call(layer, x, m, w, b):
    return torch.func.functional_call(layer, {"weight": w, "bias": b}, (x, m))[0]


class TestSparseConvNet:
    def test_architecture_is_the_papers(self):
        net = SparseConvNet()
        assert [layer.kernel_size for layer in net.layers] == [11, 7, 5, 3, 3, 1]
        channels = [(layer.in_channels, layer.out_channels) for layer in net.layers]
        assert channels == [(1, 16)] + [(16, 16)] * 4 + [(16, 1)]

    @pytest.mark.parametrize("batch", [1, 3])
    def test_cardinality(self, batch):
        out = SparseConvNet()(torch.rand(batch, 1, 10, 14), None)
        assert out.shape == (batch, 1, 10, 14)


class TestFillFromCoarser:
    def test_known_answer_and_valid_pixels_kept(self):
        from dcslam.depth.models.sparse_conv import fill_from_coarser

        x = torch.zeros(1, 1, 4, 4)
        m = torch.zeros(1, 1, 4, 4)
        x[0, 0, 0, 0], m[0, 0, 0, 0] = 2.0, 1.0
        x[0, 0, 3, 3], m[0, 0, 3, 3] = 6.0, 1.0
        y, filled = fill_from_coarser(x, m)
        assert filled.eq(1).all()
        assert y[0, 0, 0, 0] == 2.0 and y[0, 0, 3, 3] == 6.0
        assert y[0, 0, 1, 1] == 2.0 and y[0, 0, 2, 2] == 6.0  # its own 2 x 2 block
        assert y[0, 0, 0, 3] == 4.0  # a block without data: the mean of the whole image one level up

    def test_no_valid_pixel_stays_empty(self):
        from dcslam.depth.models.sparse_conv import fill_from_coarser

        y, filled = fill_from_coarser(torch.ones(2, 3, 5, 7), torch.zeros(2, 1, 5, 7))
        assert y.shape == (2, 3, 5, 7) and y.eq(0).all() and filled.eq(0).all()

    def test_gradcheck_float64(self):
        from dcslam.depth.models.sparse_conv import fill_from_coarser

        torch.manual_seed(0)
        x = torch.rand(1, 2, 5, 6, dtype=torch.float64, requires_grad=True)
        m = (torch.rand(1, 1, 5, 6) > 0.7).double()
        assert torch.autograd.gradcheck(lambda x: fill_from_coarser(x, m)[0], (x,))

    def test_network_with_filling_leaves_no_hole_below_the_data_and_keeps_its_output_elsewhere(self):
        torch.manual_seed(0)
        plain = SparseConvNet()
        filled = SparseConvNet(fill_holes=True)
        filled.load_state_dict(plain.state_dict())
        x = torch.zeros(1, 1, 40, 60)
        x[0, 0, 5, 5] = 3.0
        x[0, 0, 30, ::4] = 7.0  # a scan line across every column
        inside = torch.zeros(1, 1, 40, 60, dtype=torch.bool)
        inside[..., 5:18, :11] = True  # within the receptive field (about 13 pixels) of the first input, below it
        y, y_filled = plain(x), filled(x)
        assert (y_filled[..., 30:, :] > 0).all() and torch.equal(y[inside], y_filled[inside])
        assert plain.hparams.get("fill_holes") is None and filled.hparams["fill_holes"] is True

    def test_filling_stops_above_the_topmost_measurement_of_each_column(self):
        from dcslam.depth.models.sparse_conv import fill_from_coarser

        torch.manual_seed(0)
        net = SparseConvNet(fill_holes=True)
        x = torch.zeros(1, 1, 48, 64)
        x[0, 0, 20, ::3] = 9.0  # the top scan line: nothing measured above row 20
        x[0, 0, 40, 1::3] = 4.0
        y = net(x)
        assert y[..., :20, :].eq(0).all()  # the sky stays empty, the network's own output above the line included
        assert (y[..., 20:, :] > 0).all()  # below the line, no hole
        plain = SparseConvNet()
        plain.load_state_dict(net.state_dict())
        # the filled part is the fill of the network's output, unchanged
        reference = plain(x)
        m = (x > 0).float()
        for layer in plain.layers:
            m = F.max_pool2d(m, layer.kernel_size, stride=1, padding=layer.kernel_size // 2)
        assert torch.equal(y[..., 20:, :], fill_from_coarser(reference, m)[0][..., 20:, :])

    def test_network_with_filling_gradcheck_float64(self):
        torch.manual_seed(0)
        net = SparseConvNet(channels=2, kernels=(3, 3, 1), fill_holes=True).double()
        m = torch.zeros(1, 1, 8, 9, dtype=torch.float64)
        m[0, 0, 3, ::2] = 1
        m[0, 0, 6, 1::3] = 1
        x = (torch.rand(1, 1, 8, 9, dtype=torch.float64) + 1).requires_grad_()
        assert torch.autograd.gradcheck(lambda x: net(x * m, m), (x,))


class TestBelowTopmost:
    def test_known_answer(self):
        from dcslam.depth.models.sparse_conv import below_topmost

        m = torch.zeros(2, 1, 5, 4)
        m[0, 0, 2, 0] = m[0, 0, 4, 0] = m[0, 0, 0, 2] = m[0, 0, 3, 3] = 1
        m[1, 0, 1, 1] = 1
        out = below_topmost(m)
        assert out[0, 0, :, 0].tolist() == [0, 0, 1, 1, 1]
        assert out[0, 0, :, 1].eq(0).all()  # a column without data stays empty
        assert out[0, 0, :, 2].eq(1).all() and out[0, 0, :, 3].tolist() == [0, 0, 0, 1, 1]
        assert out[1, 0, :, 1].tolist() == [0, 1, 1, 1, 1] and out[1, 0, :, [0, 2, 3]].eq(0).all()

    def test_width_widens_each_measurement_across_columns(self):
        from dcslam.depth.models.sparse_conv import below_topmost

        m = torch.zeros(1, 1, 4, 7)
        m[0, 0, 1, 3] = 1
        out = below_topmost(m, width=3)
        assert out[0, 0, :, 2:5].tolist() == [[0, 0, 0], [1, 1, 1], [1, 1, 1], [1, 1, 1]]
        assert out[0, 0, :, [0, 1, 5, 6]].eq(0).all()

    def test_bad_input(self):
        from dcslam.depth.models.sparse_conv import below_topmost

        with pytest.raises(DcslamError, match="expected \\(B, 1, H, W\\)"):
            below_topmost(torch.zeros(1, 2, 4, 4))
        with pytest.raises(DcslamError, match="odd"):
            below_topmost(torch.zeros(1, 1, 4, 4), width=2)
