"""The scaffold a fill-correcting network starts from, and the inverse-depth output that can represent planes.

A fill-correcting network (``correct_fill``, :class:`dcslam.depth.models.fill.FillCorrection`) outputs a correction
of a *start*: a dense depth map computed from its sparse input alone. The start is the nearest-neighbour fill of a
*scaffold* (:data:`FILLS`):

- ``nearest``: the scaffold is the sparse input itself, so the start is its nearest-neighbour fill (a depth step at
  every Voronoi border, the wrong surface between the returns);
- ``scanline``: :func:`dcslam.depth.models.scanline.complete_scanline`, inverse depth interpolated between the
  returns of a column that lie on one surface;
- ``planefit``: :func:`dcslam.depth.models.planefit.complete_planefit`, local planes fitted in inverse depth where
  the returns around a pixel lie on one.

The last two place only what lies on one surface and leave the rest empty; those holes still need a value to start
from, so they take the depth of the nearest scaffold pixel, and the head is told which pixels the scaffold placed.

The output (:data:`FILL_OUTPUTS`): ``depth`` adds the head's correction to the start's depth, ``out = start + scale ·
c``; ``inverse-residual`` adds it to the start's inverse depth, ``1 / out = 1 / start + c / scale``. Seen through a
pinhole a plane has inverse depth affine in the pixel coordinates, so with ``inverse-residual`` an affine correction
of a start that is a plane over a region (a scaffold's, or one value the fill carried) leaves a plane there, and a
zero one keeps the scaffold's planes exactly; with ``depth`` the same correction bends them.

No torch at import: the command line reads :data:`FILLS` and :data:`FILL_OUTPUTS` to list the options.
"""
from __future__ import annotations

import numpy as np

from dcslam.errors import DcslamError

FILLS = ("nearest", "scanline", "planefit")  # the scaffolds a start can be made from
FILL_OUTPUTS = ("depth", "inverse-residual")  # what the head's correction is added to
#: With ``inverse-residual`` a pixel's depth is at most this many times its start's (the inverse depth is clamped
#: there: a correction that would send it through zero to the other side of the camera places it far instead).
MAX_DEPTH_RATIO = 100.0


def check_fill(fill: str, fill_output: str) -> None:
    """Raise a :class:`DcslamError` naming the option unless ``fill`` and ``fill_output`` are known names."""
    if fill not in FILLS:
        raise DcslamError(f"unknown --fill {fill!r}; expected one of {', '.join(FILLS)}")
    if fill_output not in FILL_OUTPUTS:
        raise DcslamError(f"unknown --fill-output {fill_output!r}; expected one of {', '.join(FILL_OUTPUTS)}")


def _completer(fill: str):
    if fill == "scanline":
        from dcslam.depth.models.scanline import complete_scanline

        return complete_scanline
    from dcslam.depth.models.planefit import complete_planefit

    return complete_planefit


def scaffold(sparse, mask, fill: str):
    """The scaffold of each frame and where it has depth: the measured pixels (``mask`` > 0) keep their depth, the
    pixels the ``fill`` completer places take its depth, every other pixel is 0. ``nearest``: the input itself.

    Differentiable with respect to the measured depths; the placed depths are a fixed function of the input (computed
    by the NumPy completers on the CPU, frame by frame) and carry no gradient.

    Shape:
        sparse, mask: (B, 1, H, W) → depth (B, 1, H, W) of ``sparse``'s dtype, mask (B, 1, H, W) in {0, 1}
    """
    import torch

    if fill not in FILLS:
        raise DcslamError(f"unknown fill {fill!r}; expected one of {', '.join(FILLS)}")
    if sparse.ndim != 4 or sparse.shape[1] != 1:
        raise DcslamError(f"sparse depth has shape {tuple(sparse.shape)}, expected (B, 1, H, W)")
    if mask.shape != sparse.shape:
        raise DcslamError(f"mask has shape {tuple(mask.shape)}, expected {tuple(sparse.shape)}")
    if fill == "nearest":
        return sparse, (mask > 0).to(sparse.dtype)
    measured = mask > 0
    sparse = torch.where(measured, sparse, torch.zeros_like(sparse))
    complete = _completer(fill)
    given = sparse.detach().cpu().numpy()[:, 0]
    placed = np.stack([complete(frame) for frame in given])[:, None]
    placed = torch.from_numpy(placed).to(sparse.device, sparse.dtype)
    depth = torch.where(measured, sparse, placed)
    return depth, (depth > 0).to(sparse.dtype)


def inverse_residual(start, correction, scale):
    """``start`` with ``correction`` added to its inverse depth in units of ``1 / scale``: ``1 / out = 1 / start +
    correction / scale``, computed as ``start / (1 + start · correction / scale)`` (exactly ``start`` where the
    correction is 0, and 0 where the start is) with the denominator at least ``1 /`` :data:`MAX_DEPTH_RATIO`.

    Shape:
        start, correction: (B, 1, H, W); scale: (B, 1, 1, 1), > 0 → (B, 1, H, W)
    """
    import torch

    denominator = torch.clamp(1 + start * correction / scale, min=1 / MAX_DEPTH_RATIO)
    return start / denominator
