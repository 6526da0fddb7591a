"""A nearest-neighbour fill of sparse depth as a torch op, and the head that lets a network learn a correction to it.

With ``correct_fill`` (an option of every completer network here; not in any paper) a network no longer outputs
depth itself: it outputs a correction to the nearest-neighbour fill of its input, computed from the fill, the input
mask and the network's own output (depth and, for nconv, confidence; for the guided nconv, the colour image)::

    fill = nearest_fill(sparse)                     every pixel takes its nearest measured pixel's depth
    out  = fill + scale · head(fill / scale, mask, features)        scale = mean depth of the measured pixels

The head's last layer starts at zero, so the untrained network IS the fill, and training can only earn its keep by
improving on it: it corrects the measured pixels as well as the filled ones (a depth-correction model, the thesis's
assignment's wording). The fill keeps depth edges sharp where the networks' averaging blurs them (the reason the
plain networks lost to it on MAE), and the head learns where the network's smoother estimate is the better one.

With ``fill`` other than ``nearest`` the fill starts from a surface-preserving scaffold instead (the scanline or
plane-fit completion of the input, its holes filled from the nearest scaffold pixel), and the head is given the
scaffold's mask too; with ``output="inverse-residual"`` the head's correction is added to the start's inverse depth,
where a plane is affine in the pixel coordinates (:mod:`dcslam.depth.models.scaffold`).
"""
from __future__ import annotations

import numpy as np
import torch
from torch import nn

from dcslam.depth.models.scaffold import FILLS, FILL_OUTPUTS, inverse_residual, scaffold
from dcslam.errors import DcslamError


def nearest_indices(mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """For every pixel, the flat index (row · W + column) of its nearest pixel where ``mask`` > 0, in Euclidean
    pixel distance (scipy's exact distance transform; ties as scipy breaks them), and that distance in pixels; a
    frame with no such pixel maps every pixel to itself at distance 0. Not differentiable (an index and a distance
    in pixels); computed on the CPU.

    Shape:
        mask: (B, 1, H, W) → index (B, H · W) int64, distance (B, 1, H, W) float32, both on ``mask``'s device
    """
    from scipy.ndimage import distance_transform_edt

    if mask.ndim != 4 or mask.shape[1] != 1:
        raise DcslamError(f"mask has shape {tuple(mask.shape)}, expected (B, 1, H, W)")
    b, _, h, w = mask.shape
    valid = (mask.detach() > 0).cpu().numpy()[:, 0]
    index = np.empty((b, h * w), np.int64)
    distance = np.zeros((b, 1, h, w), np.float32)
    for i in range(b):
        if valid[i].any():
            distance[i, 0], (rows, cols) = distance_transform_edt(~valid[i], return_indices=True)
            index[i] = (rows.astype(np.int64) * w + cols).ravel()
        else:
            index[i] = np.arange(h * w)
    return torch.from_numpy(index).to(mask.device), torch.from_numpy(distance).to(mask.device)


def nearest_fill(sparse: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
    """Every pixel takes the depth of its nearest valid pixel (:func:`nearest_indices`); differentiable with respect
    to ``sparse`` (each output is one input value).

    Shape:
        sparse: (B, 1, H, W), mask: (B, 1, H, W) (default: ``sparse`` > 0) → (B, 1, H, W)
    """
    return nearest_fill_with_distance(sparse, mask)[0]


def nearest_fill_with_distance(sparse: torch.Tensor, mask: torch.Tensor | None = None
                               ) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`nearest_fill` and how far each pixel's value was carried, in pixels ((B, 1, H, W) each)."""
    if sparse.ndim != 4 or sparse.shape[1] != 1:
        raise DcslamError(f"sparse depth has shape {tuple(sparse.shape)}, expected (B, 1, H, W)")
    if mask is None:
        mask = (sparse > 0).to(sparse.dtype)
    if mask.shape != sparse.shape:
        raise DcslamError(f"mask has shape {tuple(mask.shape)}, expected {tuple(sparse.shape)}")
    index, distance = nearest_indices(mask)
    return sparse.flatten(1).gather(1, index).view_as(sparse), distance.to(sparse.dtype)


def depth_scale(sparse: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """The mean depth of each frame's valid pixels (B, 1, 1, 1), at least 1 mm: what makes the heads' inputs and
    outputs scale-free (twice the depth in, twice the depth out)."""
    valid = mask.sum(dim=(1, 2, 3), keepdim=True)
    return ((sparse * mask).sum(dim=(1, 2, 3), keepdim=True) / valid.clamp(min=1)).clamp(min=1e-3)


class FillCorrection(nn.Module):
    """The correction head: ``features`` channels of the network's own (scale-free) output, plus the start (the
    nearest fill of the ``fill`` scaffold: its depth divided by the scale, or for ``output="inverse-residual"`` the
    scale divided by its depth), the input mask, the scaffold's mask (``fill`` other than ``nearest`` only) and log(1 +
    how many pixels the fill carried each value), through four 3 × 3 convolutions (dilations 1, 2, 4, 1: a 17-pixel
    window) to a correction of the start (of its depth, or of its inverse depth:
    :func:`dcslam.depth.models.scaffold.inverse_residual`) and a gate logit (for a confidence). Untrained:
    correction 0 (the output is the start, exactly), gate logit 4 (sigmoid 0.98).

    Shape:
        sparse, mask: (B, 1, H, W); features: (B, ``features``, H, W) → depth (B, 1, H, W), gate logit (B, 1, H, W)
    """

    def __init__(self, features: int, width: int = 16, fill: str = "nearest", output: str = "depth"):
        super().__init__()
        if fill not in FILLS or output not in FILL_OUTPUTS:
            raise DcslamError(f"fill {fill!r}, output {output!r}: expected a fill of {', '.join(FILLS)} and an "
                              f"output of {', '.join(FILL_OUTPUTS)}")
        self.features, self.width, self.fill, self.output = int(features), int(width), fill, output
        layers: list[nn.Module] = []
        channels = 3 + self.features + (fill != "nearest")
        for dilation in (1, 2, 4):
            layers += [nn.Conv2d(channels, self.width, 3, padding=dilation, dilation=dilation), nn.ReLU()]
            channels = self.width
        layers.append(nn.Conv2d(channels, 2, 3, padding=1))
        self.net = nn.Sequential(*layers)
        with torch.no_grad():
            self.net[-1].weight.zero_()
            self.net[-1].bias.copy_(torch.tensor([0.0, 4.0]))

    def start(self, sparse: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The start (the nearest fill of the scaffold), the scaffold's mask and how far the fill carried each value
        in pixels, (B, 1, H, W) each."""
        placed, placed_mask = scaffold(sparse, mask, self.fill)
        start, distance = nearest_fill_with_distance(placed, placed_mask)
        return start, placed_mask, distance

    def forward(self, sparse: torch.Tensor, mask: torch.Tensor, features: torch.Tensor,
                scale: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """``scale``: :func:`depth_scale` of the input, when the caller has it already (it divided its features by
        it)."""
        if features.ndim != 4 or features.shape[1] != self.features or features.shape[2:] != sparse.shape[2:]:
            raise DcslamError(f"features have shape {tuple(features.shape)}, expected ({sparse.shape[0]}, "
                              f"{self.features}, {sparse.shape[2]}, {sparse.shape[3]})")
        mask = mask.to(sparse.dtype)
        if scale is None:
            scale = depth_scale(sparse, mask)
        start, placed_mask, distance = self.start(sparse, mask)
        if self.output == "depth":
            level = start / scale
        else:  # scale-free inverse depth, the quantity the correction is added to (affine on a plane)
            has = start > 0
            level = torch.where(has, scale / torch.where(has, start, torch.ones_like(start)), torch.zeros_like(start))
        inputs = [level, mask, *([placed_mask] if self.fill != "nearest" else []), torch.log1p(distance),
                  features.to(sparse.dtype)]
        correction, gate = self.net(torch.cat(inputs, 1)).unbind(1)
        if self.output == "depth":
            return start + scale * correction[:, None], gate[:, None]
        return inverse_residual(start, correction[:, None], scale), gate[:, None]


def correction_options(correct_fill: bool, fill: str = "nearest", fill_output: str = "depth") -> dict:
    """The hyperparameters a network records for its fill correction: each only when it is not the default, so that
    model files written before an option existed stay as they were. ``fill`` and ``fill_output`` other than the
    defaults need ``correct_fill``."""
    if fill not in FILLS or fill_output not in FILL_OUTPUTS:
        raise DcslamError(f"fill {fill!r}, fill_output {fill_output!r}: expected a fill of {', '.join(FILLS)} and an "
                          f"output of {', '.join(FILL_OUTPUTS)}")
    if not correct_fill:
        if (fill, fill_output) != ("nearest", "depth"):
            raise DcslamError(f"fill {fill!r} and fill_output {fill_output!r} are options of correct_fill, which is "
                              "off")
        return {}
    return {"correct_fill": True, **({"fill": fill} if fill != "nearest" else {}),
            **({"fill_output": fill_output} if fill_output != "depth" else {})}
