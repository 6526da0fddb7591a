"""Sparsity-Invariant CNN (Uhrig, Schneider, Schneider, Franke, Brox, Geiger, "Sparsity Invariant CNNs", 3DV 2017).

Each layer computes, for input ``x`` and validity mask ``m``::

    y = conv(x * m, W) / (conv(m, 1) + eps) + b          (1 = an all-ones kernel of the layer's size)
    m' = maxpool(m, kernel size of the layer, stride 1)

followed by a ReLU. The network is the paper's: six sparse convolutions 1→16 (11×11), 16→16 (7×7, 5×5, 3×3, 3×3),
16→1 (1×1).
"""
from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from dcslam.errors import DcslamError


def _check_pair(x: torch.Tensor, mask: torch.Tensor, channels: int) -> None:
    if x.ndim != 4 or x.shape[1] != channels:
        raise DcslamError(f"input has shape {tuple(x.shape)}, expected (B, {channels}, H, W)")
    if mask.ndim != 4 or mask.shape[1] != 1 or mask.shape[0] != x.shape[0] or mask.shape[2:] != x.shape[2:]:
        raise DcslamError(f"mask has shape {tuple(mask.shape)}, expected ({x.shape[0]}, 1, {x.shape[2]}, {x.shape[3]})")


class SparseConv(nn.Module):
    """One sparsity-invariant convolution with its mask propagation and ReLU.

    Shape:
        x: (B, C_in, H, W), mask: (B, 1, H, W) in {0, 1} → (B, C_out, H, W), (B, 1, H, W)
    """

    def __init__(self, in_channels: int, out_channels: int, kernel_size: int, eps: float = 1e-8, relu: bool = True,
                 init_noise: float = 0.3):
        super().__init__()
        if kernel_size % 2 != 1:
            raise DcslamError(f"kernel size must be odd, got {kernel_size}")
        self.in_channels, self.out_channels, self.kernel_size = in_channels, out_channels, kernel_size
        self.eps, self.relu = eps, relu
        self.weight = nn.Parameter(torch.empty(out_channels, in_channels, kernel_size, kernel_size))
        self.bias = nn.Parameter(torch.zeros(out_channels))
        # Initialisation: every output channel starts as a normalised average of its valid inputs, channel mean
        # included (weight 1 / in_channels), plus 30 % noise to break symmetry. The untrained network is then a
        # smoothing interpolator of the sparse depth. The usual fan-in initialisation (in_channels · k²) ignores
        # that the window sum is already divided by the valid-pixel count: six such layers shrink the output by
        # ~1e-7 and the ReLUs start dead; a zero-mean one at the right scale blows up where few pixels are valid.
        with torch.no_grad():
            self.weight.normal_(1.0, init_noise).div_(in_channels)
        self.register_buffer("ones", torch.ones(1, 1, kernel_size, kernel_size), persistent=False)

    def forward(self, x: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        pad = self.kernel_size // 2
        mask = mask.to(x.dtype)
        numerator = F.conv2d(x * mask, self.weight, padding=pad)
        count = F.conv2d(mask, self.ones.to(x.dtype), padding=pad)
        y = numerator / (count + self.eps) + self.bias.view(1, -1, 1, 1)
        if self.relu:
            y = torch.relu(y)
        new_mask = F.max_pool2d(mask, self.kernel_size, stride=1, padding=pad)
        return y, new_mask


class SparseConvNet(nn.Module):
    """The paper's six-layer network: sparse depth and its mask in, dense depth out (same units as the input).

    Shape:
        sparse: (B, 1, H, W) depth (0 where unknown), mask: (B, 1, H, W) → (B, 1, H, W)
    """

    ARCH = "sparse-conv"

    def __init__(self, channels: int = 16, kernels: tuple[int, ...] = (11, 7, 5, 3, 3, 1), eps: float = 1e-8):
        super().__init__()
        kernels = tuple(int(k) for k in kernels)
        sizes = [1] + [channels] * (len(kernels) - 1) + [1]
        self.hparams = {"channels": int(channels), "kernels": list(kernels), "eps": float(eps)}
        self.layers = nn.ModuleList(SparseConv(sizes[i], sizes[i + 1], k, eps=eps) for i, k in enumerate(kernels))

    def forward(self, sparse: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
        if mask is None:
            mask = (sparse > 0).to(sparse.dtype)
        _check_pair(sparse, mask, 1)
        x, m = sparse, mask
        for layer in self.layers:
            x, m = layer(x, m)
        return x
