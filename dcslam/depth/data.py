"""Frames of drive files as training tensors: frame selection (stride, at most N per drive), bottom crop, integer
down-scaling, with the intrinsics changed to match, and windows of consecutive frames.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from dcslam.errors import DcslamError

if TYPE_CHECKING:
    import torch


def check_view(scale: float, crop: int) -> int:
    """Return the integer down-scaling factor for ``scale`` (1, 0.5, 0.25, ... = 1/integer)."""
    if scale <= 0 or scale > 1:
        raise DcslamError(f"--scale must be in (0, 1], got {scale}")
    factor = round(1 / scale)
    if abs(1 / factor - scale) > 1e-9:
        raise DcslamError(f"--scale must be 1/integer (1, 0.5, 0.25, ...), got {scale}")
    if crop < 0:
        raise DcslamError(f"--crop must be >= 0 rows (0 = no crop), got {crop}")
    return factor


def downscale_depth(depth: np.ndarray, factor: int) -> np.ndarray:
    """Block-wise down-scaling that keeps sparse depth sparse: each output pixel is the nearest (smallest) valid
    depth of its factor × factor block, 0 if the block has none. Trailing rows/columns that do not fill a block
    are dropped.

    Shape:
        depth: (..., H, W) → (..., H // factor, W // factor)
    """
    if factor == 1:
        return depth
    h, w = depth.shape[-2] // factor, depth.shape[-1] // factor
    blocks = depth[..., :h * factor, :w * factor].reshape(*depth.shape[:-2], h, factor, w, factor)
    blocks = np.where(blocks > 0, blocks, np.inf).min(axis=(-3, -1))
    return np.where(np.isfinite(blocks), blocks, 0).astype(np.float32)


def view_intrinsics(K: np.ndarray, height: int, crop: int, factor: int) -> np.ndarray:
    """Intrinsics (3, 3) after keeping the bottom ``crop`` rows (0 = all) and down-scaling by ``factor``."""
    K = np.array(K, dtype=np.float64)
    if crop:
        K[1, 2] -= height - crop
    if factor != 1:
        K[0, 0] /= factor
        K[1, 1] /= factor
        K[0, 2] = (K[0, 2] + 0.5) / factor - 0.5
        K[1, 2] = (K[1, 2] + 0.5) / factor - 0.5
    return K


def frame_windows(n: int, size: int) -> list[range]:
    """Consecutive windows of at most ``size`` frames: 0..size-1, size..2·size-1, … (the last may be shorter)."""
    if size < 1:
        raise DcslamError(f"window size must be >= 1, got {size}")
    return [range(start, min(start + size, n)) for start in range(0, n, size)]


@dataclass
class Batch:
    """Frames of one drive as tensors. Shapes: sparse, dense (B, 1, h, w) metres; K (3, 3); T_world_cam (B, 4, 4);
    rgb None or (B, 3, h, w) in [0, 1] (for guided networks)."""

    sparse: torch.Tensor
    dense: torch.Tensor
    K: torch.Tensor
    T_world_cam: torch.Tensor
    rgb: torch.Tensor | None = None

    def to(self, device) -> "Batch":
        return Batch(self.sparse.to(device), self.dense.to(device), self.K.to(device), self.T_world_cam.to(device),
                     None if self.rgb is None else self.rgb.to(device))


def downscale_rgb(rgb: np.ndarray, factor: int) -> np.ndarray:
    """Block means of an image. Shape: (..., H, W, 3) uint8 → (..., H // factor, W // factor, 3) float32 in [0, 1]."""
    rgb = np.asarray(rgb, np.float32) / 255.0
    if factor == 1:
        return rgb
    h, w = rgb.shape[-3] // factor, rgb.shape[-2] // factor
    blocks = rgb[..., :h * factor, :w * factor, :].reshape(*rgb.shape[:-3], h, factor, w, factor, 3)
    return blocks.mean(axis=(-4, -2))


class DriveFrames:
    """The frames of one drive file used for training or validation, read lazily.

    ``indices`` are the drive frames used: every ``stride``-th frame, at most ``max_frames`` of them.
    ``load(positions)`` reads frames ``indices[positions]`` as a :class:`Batch` after crop and scaling; the batch's
    ``sparse`` is the drive's depth kind ``input`` (``sparse``, ``sparse@16``, ...) and its ``dense`` the kind
    ``target`` (``dense``, or ``exact`` on generated drives).

    With ``mix`` (depth kinds, e.g. ``sparse``, ``sparse@32``, ``sparse@16``, ``sparse@8``: density augmentation),
    the input of each frame is drawn from them instead: ``load(positions, epoch)`` gives the frame at position ``p``
    the kind ``mix[(p + epoch) % len(mix)]``, so consecutive frames differ, each frame meets every kind over
    ``len(mix)`` epochs, and a resumed run reads exactly what an uninterrupted one would.
    """

    def __init__(self, path: Path | str, max_frames: int = 200, stride: int = 1, scale: float = 1.0, crop: int = 0,
                 input: str = "sparse", target: str = "dense", rgb: bool = False, mix: list[str] | tuple = ()):
        from dcslam.io.drive import DriveFile, check_input_kind

        if stride < 1 or max_frames < 1:
            raise DcslamError(f"stride and max frames must be >= 1, got {stride} and {max_frames}")
        self.factor = check_view(scale, crop)
        self.crop = crop
        self.input, self.target = check_input_kind(input), check_input_kind(target)
        self.mix = tuple(check_input_kind(kind) for kind in mix)
        self.with_rgb = rgb
        self.drive = DriveFile(path)
        for kind in (*(self.mix or (input,)), target):
            if kind not in self.drive.kinds:
                self.drive.depth(kind, 0)  # fails with one line naming how to make it
        n, height, _ = self.drive.shape
        if crop > height:
            raise DcslamError(f"--crop {crop} is more rows than the frames of {self.drive.path} have ({height})")
        self.height = height
        self.indices = list(range(0, n, stride))[:max_frames]
        self.K = view_intrinsics(self.drive.K, height, crop, self.factor)

    @property
    def name(self) -> str:
        return self.drive.name

    def __len__(self) -> int:
        return len(self.indices)

    def _view(self, depth: np.ndarray) -> np.ndarray:
        if self.crop:
            depth = depth[..., self.height - self.crop:, :]
        return downscale_depth(depth, self.factor)

    def input_of(self, position: int, epoch: int = 0) -> str:
        """The depth kind fed to the network for the frame at ``position`` in ``epoch`` (see the class)."""
        return self.mix[(position + epoch) % len(self.mix)] if self.mix else self.input

    def load(self, positions, epoch: int = 0) -> Batch:
        import torch  # here, not at the top: the module's numpy helpers serve torch-free classical predictions

        frames = [self.indices[p] for p in positions]
        sparse = np.stack([self._view(self.drive.depth(self.input_of(p, epoch), self.indices[p])) for p in positions])
        dense = np.stack([self._view(self.drive.depth(self.target, i)) for i in frames])
        rgb = None
        if self.with_rgb:
            images = np.stack([self.drive.rgb(i) for i in frames])
            if self.crop:
                images = images[:, self.height - self.crop:]
            rgb = torch.from_numpy(np.ascontiguousarray(downscale_rgb(images, self.factor).transpose(0, 3, 1, 2)))
        return Batch(sparse=torch.from_numpy(sparse)[:, None], dense=torch.from_numpy(dense)[:, None],
                     K=torch.from_numpy(self.K), T_world_cam=torch.from_numpy(self.drive.poses[frames]), rgb=rgb)

    def close(self) -> None:
        self.drive.close()
