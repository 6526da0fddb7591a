"""DnCNN (Zhang, Zuo, Chen, Meng, Zhang, "Beyond a Gaussian Denoiser", IEEE TIP 2017): 17 layers, 64 channels,
residual learning (the network predicts the noise, the output is the input minus it).

Used for the depth-denoising experiment: input a noisy dense depth map, output the denoised one.
"""
from __future__ import annotations

import torch
from torch import nn

from dcslam.errors import DcslamError


class DnCNN(nn.Module):
    """Conv+ReLU, (depth − 2) × Conv+BN+ReLU, Conv; output = input − predicted residual.

    Shape:
        depth: (B, C, H, W) → (B, C, H, W). ``mask`` is accepted and ignored, so all models share one call.
    """

    ARCH = "dncnn"

    def __init__(self, channels: int = 1, features: int = 64, depth: int = 17):
        super().__init__()
        if depth < 3:
            raise DcslamError(f"DnCNN needs at least 3 layers, got {depth}")
        self.hparams = {"channels": int(channels), "features": int(features), "depth": int(depth)}
        layers: list[nn.Module] = [nn.Conv2d(channels, features, 3, padding=1), nn.ReLU(inplace=True)]
        for _ in range(depth - 2):
            layers += [nn.Conv2d(features, features, 3, padding=1, bias=False), nn.BatchNorm2d(features),
                       nn.ReLU(inplace=True)]
        layers.append(nn.Conv2d(features, channels, 3, padding=1))
        self.body = nn.Sequential(*layers)
        self.channels = channels

    def forward(self, depth: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
        if depth.ndim != 4 or depth.shape[1] != self.channels:
            raise DcslamError(f"input has shape {tuple(depth.shape)}, expected (B, {self.channels}, H, W)")
        return depth - self.body(depth)
