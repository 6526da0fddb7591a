"""Per-pixel losses and depth error metrics. Depth is in metres and 0 means "no value" everywhere.

The thesis's published code applied its mask after ``nn.MSELoss`` had already reduced to a scalar, so the mask
masked nothing and invalid (zero) targets were trained on. Here the mask selects pixels *before* the mean, and a
pixel without a ground-truth value is never a target.
"""
from __future__ import annotations

import torch

from dcslam.depth.recipes import MASKS
from dcslam.errors import DcslamError


def _check_same(*tensors: torch.Tensor) -> None:
    shape = tensors[0].shape
    if len(shape) != 4 or shape[1] != 1:
        raise DcslamError(f"depth has shape {tuple(shape)}, expected (B, 1, H, W)")
    for t in tensors[1:]:
        if t.shape != shape:
            raise DcslamError(f"shapes differ: {tuple(t.shape)} vs {tuple(shape)}")


def supervision_mask(sparse: torch.Tensor, dense: torch.Tensor, mask: str) -> torch.Tensor:
    """Pixels that supervise training: ``dense`` = every pixel with ground truth; ``sparse`` = pixels with a sparse
    input value that also have ground truth.

    Shape:
        sparse, dense: (B, 1, H, W) metres → (B, 1, H, W) bool
    """
    _check_same(sparse, dense)
    if mask == "dense":
        return dense > 0
    if mask == "sparse":
        return (sparse > 0) & (dense > 0)
    raise DcslamError(f"unknown mask {mask!r}; expected one of {', '.join(MASKS)}")


def _masked_mean(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor, per_pixel) -> torch.Tensor:
    """Mean of ``per_pixel(pred − target)`` over the pixels where ``mask`` is true and the target has a value."""
    _check_same(pred, target, mask)
    mask = mask & (target > 0)
    count = mask.sum()
    if count == 0:
        return (pred * 0).sum()
    return per_pixel(torch.where(mask, pred - target, torch.zeros_like(pred))).sum() / count


def masked_mse(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mean of (pred − target)² over the pixels where ``mask`` is true (0 with zero gradient if none is).

    Shape:
        pred, target: (B, 1, H, W), mask: (B, 1, H, W) bool → scalar
    """
    return _masked_mean(pred, target, mask, torch.square)


def masked_l1(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mean of |pred − target| over the pixels where ``mask`` is true (0 with zero gradient if none is).

    Shape:
        pred, target: (B, 1, H, W), mask: (B, 1, H, W) bool → scalar
    """
    return _masked_mean(pred, target, mask, torch.abs)


class MaskedMSE:
    """The MSE training loss with the thesis's ``sparse`` or ``dense`` mask:
    ``MaskedMSE("dense")(pred, sparse, dense)``; with ``l1_weight`` > 0, plus that weight times the mean absolute
    error (metres) over the same pixels (MSE alone trades absolute error for squared error across depth edges)."""

    def __init__(self, mask: str = "dense", l1_weight: float = 0.0):
        if mask not in MASKS:
            raise DcslamError(f"unknown mask {mask!r}; expected one of {', '.join(MASKS)}")
        if not 0 <= l1_weight < float("inf"):
            raise DcslamError(f"the L1 weight must be a non-negative number, got {l1_weight}")
        self.mask, self.l1_weight = mask, float(l1_weight)

    def __call__(self, pred: torch.Tensor, sparse: torch.Tensor, dense: torch.Tensor) -> torch.Tensor:
        mask = supervision_mask(sparse, dense, self.mask)
        loss = masked_mse(pred, dense, mask)
        return loss + self.l1_weight * masked_l1(pred, dense, mask) if self.l1_weight else loss


def batch_depth_errors(pred: torch.Tensor, dense: torch.Tensor) -> dict[str, float]:
    """MSE (m²), MAE and RMSE (mm) of a batch over the pixels with ground truth, and the pixel count: the quick
    training / validation summary (for the devkit's scores of a drive see :func:`dcslam.eval.depth.depth_errors`).

    Shape:
        pred, dense: (B, 1, H, W) metres
    """
    _check_same(pred, dense)
    with torch.no_grad():
        valid = dense > 0
        n = int(valid.sum())
        if n == 0:
            return {"mse": float("nan"), "mae_mm": float("nan"), "rmse_mm": float("nan"), "pixels": 0}
        err = (pred[valid] - dense[valid]).double()
        mse = float(err.square().mean())
        return {"mse": mse, "mae_mm": float(err.abs().mean()) * 1000.0, "rmse_mm": mse ** 0.5 * 1000.0, "pixels": n}
