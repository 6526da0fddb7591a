"""Scores of depth denoising: PSNR of a depth image against clean depth."""
from __future__ import annotations

import torch

from dcslam.errors import DcslamError


def depth_psnr_db(pred_m: torch.Tensor, clean_m: torch.Tensor) -> torch.Tensor:
    """PSNR of each image over the pixels with clean depth: 10 log10(peak² / MSE), peak = the image's largest clean
    depth, MSE the mean squared error over its valid pixels (inf if 0; NaN for an image without depth).

    Shape:
        pred_m, clean_m: (B, 1, H, W) metres → (B,) dB
    """
    if pred_m.ndim != 4 or pred_m.shape[1] != 1 or pred_m.shape != clean_m.shape:
        raise DcslamError(f"depth images have shapes {tuple(pred_m.shape)} and {tuple(clean_m.shape)}, expected both "
                          "(B, 1, H, W)")
    valid = clean_m > 0
    count = valid.flatten(1).sum(1)
    sq = torch.where(valid, pred_m - clean_m, torch.zeros_like(pred_m)).double().square().flatten(1).sum(1)
    peak = clean_m.flatten(1).amax(1).double()
    mse = sq / count.clamp_min(1)
    psnr = 10 * torch.log10(peak.square() / mse)
    return torch.where(count > 0, psnr, torch.full_like(psnr, float("nan")))
