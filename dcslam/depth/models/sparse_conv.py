"""Sparsity-Invariant CNN (Uhrig, Schneider, Schneider, Franke, Brox, Geiger, "Sparsity Invariant CNNs", 3DV 2017).

Each layer computes, for input ``x`` and validity mask ``m``::

    y = conv(x * m, W) / (conv(m, 1) + eps) + b          (1 = an all-ones kernel of the layer's size)
    m' = maxpool(m, kernel size of the layer, stride 1)

followed by a ReLU. The network is the paper's: six sparse convolutions 1→16 (11×11), 16→16 (7×7, 5×5, 3×3, 3×3),
16→1 (1×1).

The paper's network has no output beyond its receptive field (about 13 pixels from the nearest input): with 8 of 64
LiDAR beams whole bands between scan lines stay empty. With ``fill_holes`` (not the paper's) those pixels take the
network's own output brought in from coarser scales by :func:`fill_from_coarser`, but only where the data reach:
every pixel above the topmost measured pixel of its column (:func:`below_topmost`: the sky, and the far background
that no LiDAR point saw) is left empty, the network's own output there included. With ``correct_fill`` (not the
paper's either) the network's output and reach feed :class:`dcslam.depth.models.fill.FillCorrection`, and the
network outputs a correction of the nearest-neighbour fill of its input (untrained: the fill itself).
"""
from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from dcslam.depth.models.fill import FillCorrection, correction_options, depth_scale
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


def fill_from_coarser(x: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Fill the pixels where ``mask`` is 0 from a pyramid of valid-pixel averages (no parameters, differentiable).

    Each level halves the resolution: a 2 × 2 block holds the mean of its valid pixels (valid if it has one); levels
    are added until no pixel is empty or the image is one pixel. Going back up, an empty pixel takes the value of its
    block one level coarser (nearest). Valid pixels keep their values.

    Shape:
        x: (B, C, H, W), mask: (B, 1, H, W) in {0, 1} → (B, C, H, W), (B, 1, H, W) (the mask after filling: 1
        wherever the image held a valid pixel)
    """
    _check_pair(x, mask, x.shape[1])
    mask = mask.to(x.dtype)
    levels = [(x, mask)]
    while bool((levels[-1][1] == 0).any()) and max(levels[-1][1].shape[-2:]) > 1:
        x_c, m_c = levels[-1]
        count = F.avg_pool2d(m_c, 2, ceil_mode=True)
        mean = F.avg_pool2d(x_c * m_c, 2, ceil_mode=True) / count.clamp(min=1e-12)
        levels.append((mean, (count > 0).to(x.dtype)))
    x_c, m_c = levels[-1]
    for x_f, m_f in reversed(levels[:-1]):
        size = x_f.shape[-2:]
        x_up = F.interpolate(x_c, size=size, mode="nearest")
        m_up = F.interpolate(m_c, size=size, mode="nearest")
        x_c = torch.where(m_f > 0, x_f, x_up)
        m_c = torch.maximum(m_f, m_up)
    return x_c, m_c


def below_topmost(mask: torch.Tensor, width: int = 1) -> torch.Tensor:
    """Where the data reach down a column: 1 at and below the topmost valid pixel of each column, 0 above it (and
    in a column with no valid pixel). A pixel counts as valid in its column when it is within ``width`` // 2 columns
    of a valid pixel of its row, so that the gaps between one scan line's points do not make ragged edges.

    Shape:
        mask: (B, 1, H, W) in {0, 1} → (B, 1, H, W) in {0, 1}, of ``mask``'s dtype (not differentiable: a mask)
    """
    if mask.ndim != 4 or mask.shape[1] != 1:
        raise DcslamError(f"mask has shape {tuple(mask.shape)}, expected (B, 1, H, W)")
    if width < 1 or width % 2 != 1:
        raise DcslamError(f"width must be an odd number of columns >= 1, got {width}")
    valid = (mask.detach() > 0).to(torch.float32)
    if width > 1:
        valid = F.max_pool2d(valid, (1, width), stride=1, padding=(0, width // 2))
    return torch.cummax(valid, dim=2).values.to(mask.dtype)


class SparseConvNet(nn.Module):
    """The paper's six-layer network: sparse depth and its mask in, dense depth out (same units as the input);
    with ``fill_holes``, what lies beyond its receptive field is filled by :func:`fill_from_coarser` and what lies
    above the topmost measured pixel of each column (:func:`below_topmost`, measurements widened by the first
    kernel's width) is left empty (0); with ``correct_fill``, the nearest-neighbour fill of the input (or, with
    ``fill``, of its scanline or plane-fit scaffold; with ``fill_output="inverse-residual"`` corrected in inverse
    depth) corrected by a head that sees the network's output (:mod:`dcslam.depth.models.fill`).

    Shape:
        sparse: (B, 1, H, W) depth (0 where unknown), mask: (B, 1, H, W) → (B, 1, H, W)
    """

    ARCH = "sparse-conv"

    def __init__(self, channels: int = 16, kernels: tuple[int, ...] = (11, 7, 5, 3, 3, 1), eps: float = 1e-8,
                 fill_holes: bool = False, correct_fill: bool = False, fill: str = "nearest",
                 fill_output: str = "depth", confidence: bool = False):
        super().__init__()
        if confidence and not correct_fill:
            raise DcslamError("a sparse-conv confidence is its fill correction's gate: confidence needs correct_fill")
        kernels = tuple(int(k) for k in kernels)
        sizes = [1] + [channels] * (len(kernels) - 1) + [1]
        self.hparams = {"channels": int(channels), "kernels": list(kernels), "eps": float(eps)}
        if fill_holes:  # recorded only when set, so that model files of the paper's network stay as they were
            self.hparams["fill_holes"] = True
        self.hparams.update(correction_options(correct_fill, fill, fill_output))  # likewise
        if confidence:  # likewise
            self.hparams["confidence"] = True
        #: whether :meth:`forward_with_confidence` says something (trained with a confidence loss); a prediction
        #: leaves empty the pixels of confidence below :attr:`empty_below`
        self.gives_confidence = bool(confidence)
        self.empty_below = 0.5 if confidence else None
        self.fill_holes = bool(fill_holes)
        self.layers = nn.ModuleList(SparseConv(sizes[i], sizes[i + 1], k, eps=eps) for i, k in enumerate(kernels))
        # the network's depth (scale-free) and where it reached
        self.correction = FillCorrection(2, fill=fill, output=fill_output) if correct_fill else None

    def forward(self, sparse: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
        return self.forward_with_confidence(sparse, mask)[0]

    def forward_with_confidence(self, sparse: torch.Tensor, mask: torch.Tensor | None = None
                                ) -> tuple[torch.Tensor, torch.Tensor | None]:
        """Depth and confidence (B, 1, H, W) each: the fill correction's gate through a sigmoid (untrained 0.98
        everywhere; it means something only where :attr:`gives_confidence`); None without ``correct_fill``."""
        if mask is None:
            mask = (sparse > 0).to(sparse.dtype)
        _check_pair(sparse, mask, 1)
        x, m = sparse, mask
        for layer in self.layers:
            x, m = layer(x, m)
        if self.fill_holes:
            x, _ = fill_from_coarser(x, m)
            x = x * below_topmost(mask, self.layers[0].kernel_size)
        if self.correction is None:
            return x, None
        scale = depth_scale(sparse, mask.to(sparse.dtype))
        depth, gate = self.correction(sparse, mask, torch.cat([x / scale, m.to(x.dtype)], 1), scale)
        return depth, torch.sigmoid(gate)
