"""Normalized convolutions that carry a confidence (after Eldesokey, Felsberg, Khan, "Confidence Propagation
through CNNs for Guided Sparse Depth Regression", TPAMI 2020: the unguided NConv-CNN).

A normalized convolution of signal ``x`` with confidence ``c`` (both (B, C, H, W), ``c`` in [0, 1]) and a
non-negative kernel ``w = softplus(v)`` computes::

    x' = conv(x · c, w) / (conv(c, w) + eps)          (a weighted average of the confident inputs)
    c' = conv(c, w) / sum(w)                          (how much confident input the window held, in [0, 1])

There is no bias, so the network is equivariant to the scale of depth (twice the input depth, twice the output),
and the untrained network is a smoothing interpolator of the sparse depth. The network is the paper's multi-scale
encoder-decoder in miniature: three normalized convolutions at full resolution, the same three again after each of
``scales`` confidence-driven down-samplings (each 2 × 2 block keeps its most confident pixel), then each coarser
result is brought up (nearest) and fused with the finer one by a 3 × 3 normalized convolution over both, and a
1 × 1 one makes one depth channel. Its output confidence is what lets later stages drop what the network guessed.
With ``correct_fill`` (both networks; not the paper's) the depth and confidence feed
:class:`dcslam.depth.models.fill.FillCorrection`: the network outputs a correction of the nearest-neighbour fill of
its input, or with ``fill`` of its scanline or plane-fit scaffold, in depth or (``fill_output``) in inverse depth
(untrained: the fill itself), and its confidence gated by the head.
"""
from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from dcslam.depth.models.fill import FillCorrection, correction_options, depth_scale
from dcslam.depth.models.sparse_conv import _check_pair
from dcslam.errors import DcslamError


class NConv2d(nn.Module):
    """One normalized convolution with its confidence propagation.

    Shape:
        x: (B, C_in, H, W), c: (B, C_in, H, W) in [0, 1] → (B, C_out, H, W), (B, C_out, H, W)
    """

    def __init__(self, in_channels: int, out_channels: int, kernel_size: int, eps: float = 1e-8):
        super().__init__()
        if kernel_size % 2 != 1:
            raise DcslamError(f"kernel size must be odd, got {kernel_size}")
        self.in_channels, self.out_channels, self.kernel_size, self.eps = in_channels, out_channels, kernel_size, eps
        # softplus(v) ≈ 1 ± 0.3: near-uniform averaging kernels at the start, different enough to break symmetry
        self.weight = nn.Parameter(torch.empty(out_channels, in_channels, kernel_size, kernel_size).normal_(0.5, 0.3))

    def forward(self, x: torch.Tensor, c: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        w = F.softplus(self.weight)
        pad = self.kernel_size // 2
        numerator = F.conv2d(x * c, w, padding=pad)
        denominator = F.conv2d(c, w, padding=pad)
        x_out = numerator / (denominator + self.eps)
        c_out = denominator / w.sum(dim=(1, 2, 3)).view(1, -1, 1, 1)
        return x_out, c_out


def pool_by_confidence(x: torch.Tensor, c: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Halve the resolution keeping, in each 2 × 2 block, the signal of the most confident pixel.

    Shape:
        x, c: (B, C, H, W) → (B, C, ceil(H / 2), ceil(W / 2)) each
    """
    c_small, index = F.max_pool2d(c, 2, stride=2, return_indices=True, ceil_mode=True)
    x_small = x.flatten(2).gather(2, index.flatten(2)).view_as(c_small)
    return x_small, c_small


class NConvCNN(nn.Module):
    """Unguided NConv-CNN: sparse depth and its mask in, dense depth (and a confidence) out.

    Shape:
        sparse: (B, 1, H, W) depth (0 where unknown), mask: (B, 1, H, W) → (B, 1, H, W)
    """

    ARCH = "nconv"

    def __init__(self, channels: int = 2, kernel_size: int = 5, scales: int = 3, eps: float = 1e-8,
                 correct_fill: bool = False, fill: str = "nearest", fill_output: str = "depth"):
        super().__init__()
        if channels < 1 or scales < 0:
            raise DcslamError(f"nconv needs channels >= 1 and scales >= 0, got {channels} and {scales}")
        self.hparams = {"channels": int(channels), "kernel_size": int(kernel_size), "scales": int(scales),
                        "eps": float(eps)}
        # recorded only when set, so that earlier model files stay as they were
        self.hparams.update(correction_options(correct_fill, fill, fill_output))
        # the network's depth (scale-free) and confidence
        self.correction = FillCorrection(2, fill=fill, output=fill_output) if correct_fill else None
        self.scales = int(scales)
        self.encode = nn.ModuleList([NConv2d(1, channels, kernel_size, eps), NConv2d(channels, channels, kernel_size,
                                                                                     eps),
                                     NConv2d(channels, channels, kernel_size, eps)])
        self.down = nn.ModuleList([NConv2d(channels, channels, kernel_size, eps),
                                   NConv2d(channels, channels, kernel_size, eps)])
        self.fuse = nn.ModuleList(NConv2d(2 * channels, channels, 3, eps) for _ in range(self.scales))
        self.out = NConv2d(channels, 1, 1, eps)

    def forward_with_confidence(self, sparse: torch.Tensor, mask: torch.Tensor | None = None
                                ) -> tuple[torch.Tensor, torch.Tensor]:
        """Depth and confidence, (B, 1, H, W) each; confidence in [0, 1]."""
        if mask is None:
            mask = (sparse > 0).to(sparse.dtype)
        _check_pair(sparse, mask, 1)
        x, c = sparse, mask.to(sparse.dtype)
        for layer in self.encode:
            x, c = layer(x, c)
        levels = [(x, c)]
        for _ in range(self.scales):
            x, c = pool_by_confidence(x, c)
            for layer in self.down:
                x, c = layer(x, c)
            levels.append((x, c))
        x, c = levels[-1]
        for (x_fine, c_fine), fuse in zip(reversed(levels[:-1]), reversed(self.fuse)):
            size = x_fine.shape[-2:]
            x_up = F.interpolate(x, size=size, mode="nearest")
            c_up = F.interpolate(c, size=size, mode="nearest")
            x, c = fuse(torch.cat([x_fine, x_up], 1), torch.cat([c_fine, c_up], 1))
        x, c = self.out(x, c)
        if self.correction is None:
            return x, c
        scale = depth_scale(sparse, mask)
        depth, gate = self.correction(sparse, mask, torch.cat([x / scale, c], 1), scale)
        return depth, c * torch.sigmoid(gate)

    def forward(self, sparse: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
        return self.forward_with_confidence(sparse, mask)[0]


class GuidedNConvCNN(nn.Module):
    """RGB-guided NConv-CNN: the unguided network's depth and confidence, refined by a small CNN that also sees the
    colour image (depth edges fall on colour edges), in the spirit of the paper's guided variant.

    The refinement works on depth divided by the mean of the valid sparse input (so the network stays equivariant to
    the scale of depth): it adds a correction to the normalised depth and gates the confidence.

    Shape:
        sparse: (B, 1, H, W) depth (0 where unknown), mask: (B, 1, H, W), rgb: (B, 3, H, W) in [0, 1]
        → (B, 1, H, W)
    """

    ARCH = "nconv-guided"
    GUIDED = True

    def __init__(self, channels: int = 2, kernel_size: int = 5, scales: int = 3, features: int = 8,
                 eps: float = 1e-8, correct_fill: bool = False, fill: str = "nearest", fill_output: str = "depth"):
        super().__init__()
        self.hparams = {"channels": int(channels), "kernel_size": int(kernel_size), "scales": int(scales),
                        "features": int(features), "eps": float(eps)}
        self.nconv = NConvCNN(channels, kernel_size, scales, eps)
        self.hparams.update(correction_options(correct_fill, fill, fill_output))
        if correct_fill:  # the colour image, the unguided depth (scale-free) and confidence correct the fill
            self.correction = FillCorrection(5, fill=fill, output=fill_output)
            return
        self.correction = None
        self.refine = nn.Sequential(nn.Conv2d(5, features, 3, padding=1), nn.ReLU(),
                                    nn.Conv2d(features, features, 3, padding=1), nn.ReLU(),
                                    nn.Conv2d(features, 2, 3, padding=1))
        with torch.no_grad():  # untrained: the unguided output, unchanged
            self.refine[-1].weight.zero_()
            self.refine[-1].bias.copy_(torch.tensor([0.0, 4.0]))

    def forward_with_confidence(self, sparse: torch.Tensor, mask: torch.Tensor | None = None,
                                rgb: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """Depth and confidence, (B, 1, H, W) each; confidence in [0, 1]."""
        if rgb is None:
            raise DcslamError("nconv-guided needs the colour image (rgb (B, 3, H, W))")
        if rgb.ndim != 4 or rgb.shape[1] != 3 or rgb.shape[0] != sparse.shape[0] or rgb.shape[2:] != sparse.shape[2:]:
            raise DcslamError(f"rgb has shape {tuple(rgb.shape)}, expected ({sparse.shape[0]}, 3, "
                              f"{sparse.shape[2]}, {sparse.shape[3]})")
        if mask is None:
            mask = (sparse > 0).to(sparse.dtype)
        depth, confidence = self.nconv.forward_with_confidence(sparse, mask)
        scale = depth_scale(sparse, mask.to(sparse.dtype))
        if self.correction is not None:
            out, gate = self.correction(sparse, mask, torch.cat([rgb.to(depth.dtype), depth / scale, confidence], 1),
                                        scale)
            return out, confidence * torch.sigmoid(gate)
        correction, gate = self.refine(torch.cat([rgb.to(depth.dtype), depth / scale, confidence], 1)).unbind(1)
        return depth + scale * correction[:, None], confidence * torch.sigmoid(gate[:, None])

    def forward(self, sparse: torch.Tensor, mask: torch.Tensor | None = None,
                rgb: torch.Tensor | None = None) -> torch.Tensor:
        return self.forward_with_confidence(sparse, mask, rgb)[0]
