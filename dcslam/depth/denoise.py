"""Depth denoising learnt through the map (the thesis's appendix C.2): the noise model, the denoiser and its training
loop, a DnCNN trained only with the chamfer distance between the map of its output and the map of the clean depth.
Scoring is :mod:`dcslam.report.denoising` (PSNR: :mod:`dcslam.eval.denoising`); the experiment that writes files is
:mod:`dcslam.stages.demo_icl`.

The experiment, on drive files whose ``depth/dense`` is clean sensor depth (e.g. an indoor sequence from
``dcslam prepare-tum``):

1. Frames are read at an image scale of 1/integer (:class:`~dcslam.depth.data.DriveFrames`: each pixel the nearest
   depth of its block, intrinsics scaled to match) and Gaussian noise of ``sigma_m`` metres is added to every valid
   pixel of the clean depth at that scale (:func:`add_depth_noise`; pixels without depth stay 0, noisy depth is
   kept at or above 1 mm).
2. The network sees depth divided by a fixed ``depth_scale_m`` and works only on pixels that have depth
   (:class:`DepthDenoiser`). Training draws ``batch_size`` training frames per step (or one window of ``map_frames``
   consecutive frames), optionally a random ``patch`` × ``patch`` window of them (the intrinsics shifted to match),
   fresh noise, and minimises :class:`~dcslam.depth.maps.MapChamfer` between the maps of the output and of the clean
   depth, built by dcslam's differentiable PointFusion with ground-truth poses. No per-pixel loss is used. AdamW,
   its learning rate warmed up linearly over the first ``warmup_fraction`` of the steps; DnCNN's last (residual)
   layer starts at zero, so training starts from the identity; after training, the batch-norm statistics are
   recomputed over the training frames (:func:`recalibrate_batchnorm`).
3. Scores on held-out frames (other drives, or the last ``heldout_fraction`` of each drive's frames), for the noisy
   input and for the denoised output against the clean depth, with the same seeded noise for both: MAE and RMSE (mm)
   over all valid pixels, PSNR (:func:`dcslam.eval.denoising.depth_psnr_db`) and the chamfer distance (m²) of their
   maps to the clean map (:func:`dcslam.report.denoising.evaluate`).

:func:`dcslam.stages.demo_icl.run_denoising` writes ``model.pt``, ``results.json``, ``results.csv``, ``results.md`` and
``denoising.png``
(noisy, denoised and clean depth of held-out frames, like the thesis's figure C.6, with both error maps).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from dcslam.depth.config import DenoiseConfig
from dcslam.depth.data import frame_windows
from dcslam.depth.maps import MapChamfer
from dcslam.depth.optimizer import adamw
from dcslam.errors import DcslamError
from dcslam.progress import Bar

MIN_NOISY_DEPTH_M = 1e-3


def add_depth_noise(depth_m: torch.Tensor, sigma_m: float, generator: torch.Generator | None = None) -> torch.Tensor:
    """Clean depth plus N(0, sigma_m²) on every pixel that has depth; pixels without depth (0) stay 0 and noisy depth
    is clamped at :data:`MIN_NOISY_DEPTH_M`, so a valid pixel stays valid. The input is not changed.

    Shape:
        depth_m: (B, 1, H, W) metres, 0 = none → (B, 1, H, W)
    """
    check_images(depth_m)
    if sigma_m < 0:
        raise DcslamError(f"--sigma must be >= 0 m, got {sigma_m}")
    noise = torch.randn(depth_m.shape, generator=generator, dtype=depth_m.dtype).to(depth_m.device)
    noisy = (depth_m + sigma_m * noise).clamp_min(MIN_NOISY_DEPTH_M)
    return torch.where(depth_m > 0, noisy, torch.zeros_like(depth_m))


def check_images(*images: torch.Tensor) -> None:
    shape = images[0].shape
    if images[0].ndim != 4 or shape[1] != 1:
        raise DcslamError(f"depth has shape {tuple(shape)}, expected (B, 1, H, W)")
    if any(image.shape != shape for image in images[1:]):
        raise DcslamError(f"depth images have shapes {[tuple(i.shape) for i in images]}, expected the same")


class DepthDenoiser(nn.Module):
    """A network applied to depth in units of ``depth_scale_m``, on pixels with depth only (elsewhere 0; output
    clamped at :data:`MIN_NOISY_DEPTH_M`, so it is a depth image like its input).

    Shape:
        noisy_m: (B, 1, H, W) metres, 0 = none → (B, 1, H, W) metres
    """

    def __init__(self, net: nn.Module, depth_scale_m: float):
        super().__init__()
        if depth_scale_m <= 0:
            raise DcslamError(f"depth scale must be > 0 m, got {depth_scale_m}")
        self.net, self.depth_scale_m = net, float(depth_scale_m)

    def forward(self, noisy_m: torch.Tensor) -> torch.Tensor:
        check_images(noisy_m)
        out = self.net(noisy_m / self.depth_scale_m) * self.depth_scale_m
        return torch.where(noisy_m > 0, out.clamp_min(MIN_NOISY_DEPTH_M), torch.zeros_like(out))


def pointfusion_builder(voxel_size_m: float):
    """dcslam's differentiable PointFusion map with given poses; ``voxel_size_m`` = 0: no voxel merging (as gradSLAM's
    PointFusion: one map point per valid pixel of a single frame)."""
    from dcslam.slam.fusion import PointFusion
    from dcslam.slam.pipeline import build_map

    def build(depth, K, T_world_cam):
        return build_map(depth, K, T_world_cam, mapper=PointFusion(voxel_size=voxel_size_m, keep_graph=True))

    return build


@dataclass
class Frames:
    """Clean depth of frames of one drive at the working scale. Shape: clean (N, 1, h, w) m, K (3, 3),
    T_world_cam (N, 4, 4)."""

    name: str
    clean: torch.Tensor
    K: torch.Tensor
    T_world_cam: torch.Tensor
    frame_ids: list

    def select(self, positions: range) -> "Frames":
        sl = slice(positions.start, positions.stop)
        return Frames(self.name, self.clean[sl], self.K, self.T_world_cam[sl], self.frame_ids[sl])


def read_frames(path: Path | str, config: DenoiseConfig) -> Frames:
    """The clean depth (``depth/dense``) of a drive file's frames at ``config.scale`` (every ``stride``-th frame, at
    most ``max_frames``)."""
    from dcslam.depth.data import DriveFrames

    frames = DriveFrames(path, config.max_frames, config.stride, config.scale)
    try:
        batch = frames.load(range(len(frames)))
        ids = [int(frames.drive.frame_ids[i]) for i in frames.indices]
        return Frames(frames.name, batch.dense.float(), batch.K.float(), batch.T_world_cam.float(), ids)
    finally:
        frames.close()


def split_frames(config: DenoiseConfig) -> tuple[list[Frames], list[Frames]]:
    """(training frames, held-out frames): the test drives when there are any, else the last ``heldout_fraction``
    of each training drive's frames (a contiguous tail: frames never trained on)."""
    train = [read_frames(p, config) for p in config.train_drives]
    if config.test_drives:
        return train, [read_frames(p, config) for p in config.test_drives]
    kept, heldout = [], []
    for frames in train:
        n = len(frames.frame_ids)
        n_test = max(1, round(n * config.heldout_fraction))
        if n - n_test < 1:
            raise DcslamError(f"drive {frames.name} has {n} frame(s): too few to hold some out; give test drives")
        kept.append(frames.select(range(0, n - n_test)))
        heldout.append(frames.select(range(n - n_test, n)))
    return kept, heldout


def _draw(frames: list[Frames], config: DenoiseConfig, rng: np.random.Generator):
    """One training chunk: (clean (B, 1, h, w), K (3, 3), T_world_cam (B, 4, 4)), a random patch when asked."""
    d = int(rng.integers(len(frames)))
    n = len(frames[d].frame_ids)
    if config.map_frames > 1:
        start = int(rng.integers(max(1, n - config.map_frames + 1)))
        idx = np.arange(start, min(start + config.map_frames, n))
    else:
        idx = rng.choice(n, size=min(config.batch_size, n), replace=False)
    clean, K, T = frames[d].clean[idx], frames[d].K.clone(), frames[d].T_world_cam[idx]
    h, w = clean.shape[-2:]
    if config.patch and (config.patch < h or config.patch < w):
        ph, pw = min(config.patch, h), min(config.patch, w)
        y0, x0 = int(rng.integers(h - ph + 1)), int(rng.integers(w - pw + 1))
        clean = clean[..., y0:y0 + ph, x0:x0 + pw]
        K[0, 2] -= x0
        K[1, 2] -= y0
    return clean, K, T


def train_denoiser(model: DepthDenoiser, frames: list[Frames], config: DenoiseConfig, device, map_builder) -> list:
    """Train ``model`` in place for ``config.steps`` AdamW steps of the chamfer loss alone; returns the losses."""
    rng = np.random.default_rng(config.seed)
    noise = torch.Generator().manual_seed(config.seed)
    optimizer = adamw(model.parameters(), config.lr, config.weight_decay)
    warmup = max(1, round(config.steps * config.warmup_fraction))
    schedule = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda k: min(1.0, (k + 1) / warmup))
    objective = MapChamfer(config.map_frames, map_builder)
    losses = []
    model.train()
    with Bar("train denoiser (chamfer)", total=config.steps) as bar:
        for step in range(config.steps):
            clean, K, T = _draw(frames, config, rng)
            noisy = add_depth_noise(clean, config.sigma_m, noise)
            out = model(noisy.to(device))
            loss = objective(out, clean.to(device), K.to(device), T.to(device))
            if not torch.isfinite(loss):
                raise DcslamError(f"training loss became {float(loss)} at step {step}")
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            schedule.step()
            losses.append(float(loss.detach()))
            bar.advance(status=f"chamfer {losses[-1]:.3g} m²")
    recalibrate_batchnorm(model, frames, config, device)
    return losses


def recalibrate_batchnorm(model: DepthDenoiser, frames: list[Frames], config: DenoiseConfig, device) -> None:
    """Batch-norm statistics of the trained weights: reset, then the plain average over one pass of the training
    frames (whole images, fresh noise, no gradient). Training updates them as a running average while the weights
    move, and on patches; this makes evaluation see the statistics of the final network on whole images. Leaves
    the model in eval mode."""
    norms = [m for m in model.modules() if isinstance(m, nn.modules.batchnorm._BatchNorm)]
    momenta = [m.momentum for m in norms]
    for m in norms:
        m.reset_running_stats()
        m.momentum = None  # cumulative average
    generator = torch.Generator().manual_seed(config.seed + 1)
    model.train()
    with torch.no_grad():
        for f in frames:
            for window in frame_windows(len(f.frame_ids), config.batch_size):
                model(add_depth_noise(f.select(window).clean, config.sigma_m, generator).to(device))
    for m, momentum in zip(norms, momenta):
        m.momentum = momentum
    model.eval()
