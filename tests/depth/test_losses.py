import math

import pytest
import torch

from dcslam.depth.losses import MaskedMSE, batch_depth_errors, masked_l1, masked_mse, supervision_mask
from dcslam.errors import DcslamError


def _pair(device="cpu", dtype=torch.float32):
    dense = torch.zeros(1, 1, 2, 3, device=device, dtype=dtype)
    dense[0, 0, 0] = torch.tensor([1.0, 2.0, 3.0])  # bottom row: no ground truth
    sparse = torch.zeros(1, 1, 2, 3, device=device, dtype=dtype)
    sparse[0, 0, 0, 0] = 1.0
    sparse[0, 0, 1, 1] = 7.0  # sparse value without ground truth
    pred = torch.full((1, 1, 2, 3), 2.0, device=device, dtype=dtype, requires_grad=True)
    return pred, sparse, dense


def test_dense_mask_ignores_pixels_without_ground_truth(device, dtype):
    pred, sparse, dense = _pair(device, dtype)
    loss = MaskedMSE("dense")(pred, sparse, dense)
    assert loss.item() == pytest.approx((1 + 0 + 1) / 3)  # not diluted, not trained on the zero targets
    assert loss.device.type == device.type and loss.dtype == dtype
    (grad,) = torch.autograd.grad(loss, pred)
    assert grad[0, 0, 1].eq(0).all()


def test_masked_mse_gradcheck_float64():
    pred, sparse, dense = _pair(dtype=torch.float64)
    mask = supervision_mask(sparse, dense, "dense")
    assert torch.autograd.gradcheck(lambda p: masked_mse(p, dense, mask), (pred,))


def test_sparse_mask():
    pred, sparse, dense = _pair()
    mask = supervision_mask(sparse, dense, "sparse")
    assert mask.sum() == 1
    assert MaskedMSE("sparse")(pred, sparse, dense).item() == pytest.approx(1.0)


def test_not_the_theses_defect():
    # masking after reduction would give mean over all 6 pixels including zero targets
    pred, sparse, dense = _pair()
    defect = torch.nn.MSELoss()(pred, dense).item()
    assert MaskedMSE("dense")(pred, sparse, dense).item() != pytest.approx(defect)


def test_empty_mask_is_zero_with_zero_gradient():
    pred = torch.ones(1, 1, 2, 2, requires_grad=True)
    loss = masked_mse(pred, torch.zeros(1, 1, 2, 2), torch.ones(1, 1, 2, 2, dtype=torch.bool))
    assert loss.item() == 0
    loss.backward()
    assert pred.grad.eq(0).all()


def test_batch_depth_errors(device, dtype):
    pred, _, dense = _pair(device, dtype)
    e = batch_depth_errors(pred.detach(), dense)
    assert e["pixels"] == 3 and e["mae_mm"] == pytest.approx(2000 / 3)
    assert e["rmse_mm"] == pytest.approx(math.sqrt(2 / 3) * 1000)
    assert math.isnan(batch_depth_errors(pred.detach(), torch.zeros_like(dense))["mae_mm"])


def test_bad_input():
    with pytest.raises(DcslamError):
        MaskedMSE("both")
    with pytest.raises(DcslamError):
        masked_mse(torch.zeros(1, 2, 2), torch.zeros(1, 2, 2), torch.zeros(1, 2, 2, dtype=torch.bool))


def test_l1_term_adds_the_mean_absolute_error():
    pred, sparse, dense = _pair()
    mse = MaskedMSE("dense")(pred, sparse, dense).item()
    assert MaskedMSE("dense", l1_weight=2.0)(pred, sparse, dense).item() == pytest.approx(mse + 2.0 * (1 + 0 + 1) / 3)
    assert masked_l1(pred, dense, supervision_mask(sparse, dense, "sparse")).item() == pytest.approx(1.0)
    with pytest.raises(DcslamError, match="L1 weight"):
        MaskedMSE("dense", l1_weight=-1.0)


def test_masked_l1_gradcheck_float64():
    pred, sparse, dense = _pair(dtype=torch.float64)
    pred = (pred + torch.tensor([0.3, -0.4, 0.2], dtype=torch.float64)).detach().requires_grad_()  # off the kinks
    mask = supervision_mask(sparse, dense, "dense")
    assert torch.autograd.gradcheck(lambda p: masked_l1(p, dense, mask), (pred,))
