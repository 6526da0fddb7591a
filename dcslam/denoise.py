"""Depth denoising learnt through the map (the thesis's appendix C.2): a DnCNN trained only with the chamfer distance
between the map of its output and the map of the clean depth.

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
   over all valid pixels, PSNR (:func:`depth_psnr_db`) and the chamfer distance (m²) of their maps to the clean map.

:func:`run_denoising` writes ``model.pt``, ``results.json``, ``results.csv``, ``results.md`` and ``denoising.png``
(noisy, denoised and clean depth of held-out frames, like the thesis's figure C.6, with both error maps).
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch import nn

from dcslam.depth.chamfer import chamfer_distance
from dcslam.depth.data import check_view, frame_windows
from dcslam.depth.losses import depth_errors
from dcslam.depth.maps import MapChamfer
from dcslam.errors import DcslamError
from dcslam.report.tables import Column, Table
from dcslam.progress import Bar, track
from dcslam.workspace import atomic_output, stage_config, write_json_atomic, write_text_atomic

MIN_NOISY_DEPTH_M = 1e-3
OUTPUT_FILES = ("model.pt", "results.json", "results.csv", "results.md", "denoising.png")


def add_depth_noise(depth_m: torch.Tensor, sigma_m: float, generator: torch.Generator | None = None) -> torch.Tensor:
    """Clean depth plus N(0, sigma_m²) on every pixel that has depth; pixels without depth (0) stay 0 and noisy depth
    is clamped at :data:`MIN_NOISY_DEPTH_M`, so a valid pixel stays valid. The input is not changed.

    Shape:
        depth_m: (B, 1, H, W) metres, 0 = none → (B, 1, H, W)
    """
    _check_images(depth_m)
    if sigma_m < 0:
        raise DcslamError(f"--sigma must be >= 0 m, got {sigma_m}")
    noise = torch.randn(depth_m.shape, generator=generator, dtype=depth_m.dtype).to(depth_m.device)
    noisy = (depth_m + sigma_m * noise).clamp_min(MIN_NOISY_DEPTH_M)
    return torch.where(depth_m > 0, noisy, torch.zeros_like(depth_m))


def depth_psnr_db(pred_m: torch.Tensor, clean_m: torch.Tensor) -> torch.Tensor:
    """PSNR of each image over the pixels with clean depth: 10 log10(peak² / MSE), peak = the image's largest clean
    depth, MSE the mean squared error over its valid pixels (inf if 0; NaN for an image without depth).

    Shape:
        pred_m, clean_m: (B, 1, H, W) metres → (B,) dB
    """
    _check_images(pred_m, clean_m)
    valid = clean_m > 0
    count = valid.flatten(1).sum(1)
    sq = torch.where(valid, pred_m - clean_m, torch.zeros_like(pred_m)).double().square().flatten(1).sum(1)
    peak = clean_m.flatten(1).amax(1).double()
    mse = sq / count.clamp_min(1)
    psnr = 10 * torch.log10(peak.square() / mse)
    return torch.where(count > 0, psnr, torch.full_like(psnr, float("nan")))


def _check_images(*images: torch.Tensor) -> None:
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
        _check_images(noisy_m)
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
class DenoiseConfig:
    """Every option of the denoising experiment (written to ``results.json``); :meth:`check` checks all but the
    drives."""

    sigma_m: float = 0.05
    scale: float = 0.25
    steps: int = 200
    batch_size: int = 4
    patch: int = 64
    lr: float = 1e-3
    warmup_fraction: float = 0.1
    weight_decay: float = 0.01
    features: int = 32
    layers: int = 8
    depth_scale_m: float = 4.0
    map_frames: int = 1
    map_voxel_m: float = 0.0
    max_frames: int = 200
    stride: int = 1
    heldout_fraction: float = 0.25
    examples: int = 3
    seed: int = 0
    device: str = "auto"
    train_drives: list = field(default_factory=list)
    test_drives: list = field(default_factory=list)

    def check(self) -> None:
        check_view(self.scale, 0)
        for name in ("steps", "batch_size", "features", "layers", "map_frames", "max_frames", "stride"):
            if getattr(self, name) < 1:
                raise DcslamError(f"--{name.replace('_', '-')} must be >= 1, got {getattr(self, name)}")
        if self.sigma_m <= 0:
            raise DcslamError(f"--sigma must be > 0 m, got {self.sigma_m}")
        if self.patch < 0 or self.map_voxel_m < 0 or self.depth_scale_m <= 0:
            raise DcslamError("--patch and the map voxel size must be >= 0, the depth scale > 0")
        if not 0 <= self.warmup_fraction < 1:
            raise DcslamError(f"the warm-up fraction must be in [0, 1), got {self.warmup_fraction}")
        if not 0 < self.heldout_fraction < 1:
            raise DcslamError(f"the held-out fraction must be in (0, 1), got {self.heldout_fraction}")


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
    optimizer = torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
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


def evaluate(model: DepthDenoiser, frames: list[Frames], config: DenoiseConfig, device, map_builder) -> dict:
    """Scores of the noisy input and of the denoised output against the clean depth on ``frames``.

    Returns ``{"noisy": scores, "denoised": scores, "frames": n, "examples": [(frame id, noisy, denoised, clean)]}``,
    scores ``{"mae_mm", "rmse_mm", "psnr_db", "chamfer_m2"}`` (MAE, RMSE pooled over every valid pixel; PSNR and
    chamfer averaged over frames and map windows). The noise of each frame is seeded by (seed, drive, frame).
    """
    sums = {kind: {"sq": 0.0, "abs": 0.0, "psnr": [], "chamfer": []} for kind in ("noisy", "denoised")}
    pixels, examples = 0, []
    windows = [(d, w) for d, f in enumerate(frames) for w in frame_windows(len(f.frame_ids), config.map_frames)]
    shown = set(np.linspace(0, len(windows) - 1, min(config.examples, len(windows))).round().astype(int).tolist())
    model.eval()
    with torch.no_grad():
        for number, (d, window) in enumerate(track(windows, "score held-out frames")):
            part = frames[d].select(window)
            generator = torch.Generator().manual_seed(config.seed * 1_000_003 + d * 10_007 + window.start + 1)
            clean = part.clean.to(device)
            noisy = add_depth_noise(part.clean, config.sigma_m, generator).to(device)
            outputs = {"noisy": noisy, "denoised": model(noisy)}
            K, T = part.K.to(device), part.T_world_cam.to(device)
            clean_map = map_builder(clean, K, T).points
            for kind, depth in outputs.items():
                e = depth_errors(depth, clean)
                sums[kind]["sq"] += e["mse"] * e["pixels"]
                sums[kind]["abs"] += e["mae_mm"] * e["pixels"]
                sums[kind]["psnr"] += depth_psnr_db(depth, clean).tolist()
                depth_map = map_builder(depth, K, T).points
                if len(depth_map) and len(clean_map):
                    sums[kind]["chamfer"].append(float(chamfer_distance(depth_map, clean_map)))
            pixels += int((clean > 0).sum())
            if number in shown:
                examples.append((part.frame_ids[0], *(x[0, 0].cpu().numpy() for x in (noisy, outputs["denoised"],
                                                                                      clean))))
    if pixels == 0:
        raise DcslamError("the held-out frames have no clean depth to score against")
    scores = {kind: {"mae_mm": s["abs"] / pixels, "rmse_mm": math.sqrt(s["sq"] / pixels) * 1000.0,
                     "psnr_db": float(np.nanmean(s["psnr"])),
                     "chamfer_m2": float(np.mean(s["chamfer"])) if s["chamfer"] else float("nan")}
              for kind, s in sums.items()}
    return {**scores, "frames": sum(len(f.frame_ids) for f in frames), "pixels": pixels, "examples": examples}


SCORE_COLUMNS = (("mae_mm", "MAE (mm)", "{:.1f}"), ("rmse_mm", "RMSE (mm)", "{:.1f}"),
                 ("psnr_db", "PSNR (dB)", "{:.2f}"), ("chamfer_m2", "chamfer (m²)", "{:.3g}"))


def results_table(scores: dict, config: DenoiseConfig) -> Table:
    """The before/after table: rows noisy input, denoised output and the change (%, negative = lower)."""
    columns = [Column("depth", "depth")] + [Column(k, h, f) for k, h, f in SCORE_COLUMNS]
    table = Table(f"depth denoising through the map, σ = {config.sigma_m * 1000:g} mm, {scores['frames']} held-out "
                  "frames", columns)
    table.rows.append({"depth": "noisy input", **scores["noisy"]})
    table.rows.append({"depth": "DnCNN (chamfer only)", **scores["denoised"]})
    change = {k: 100.0 * (scores["denoised"][k] / scores["noisy"][k] - 1) for k in ("mae_mm", "rmse_mm",
                                                                                      "chamfer_m2")}
    change["psnr_db"] = scores["denoised"]["psnr_db"] - scores["noisy"]["psnr_db"]
    table.rows.append({"depth": "change", **{k: f"{v:+.1f} %" if k != "psnr_db" else f"{v:+.2f} dB"
                                            for k, v in change.items()}})
    table.notes += ["MAE, RMSE: over every held-out pixel with clean depth (the noisy input has the same pixels)",
                    "PSNR: per frame 10·log10(peak² / MSE) over its valid pixels, peak = its largest clean depth; "
                    "mean over frames",
                    "chamfer: squared distances, mean each way, between the PointFusion map (ground-truth poses) of "
                    f"{config.map_frames} frame(s) and that of the clean depth; mean over maps"]
    return table


def plot_denoising(path: Path, examples: list, sigma_m: float) -> Path:
    """Like the thesis's figure C.6: per held-out frame noisy, denoised and clean depth, and |noisy − clean|,
    |denoised − clean| on one colour scale. ``examples``: (frame id, noisy, denoised, clean), each (H, W) metres."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(examples), 5, figsize=(17, 2.9 * len(examples) + 0.4), squeeze=False)
    for row, (frame_id, noisy, denoised, clean) in zip(axes, examples):
        valid = clean > 0
        vmax = float(clean.max()) or 1.0
        errors = [np.where(valid, np.abs(x - clean), np.nan) for x in (noisy, denoised)]
        top = float(np.nanpercentile(errors[0], 99)) if valid.any() else 1.0
        panels = [(noisy, f"held-out frame {frame_id}: noisy (σ = {sigma_m * 1000:g} mm)", "viridis", vmax),
                  (denoised, "denoised (DnCNN, chamfer only)", "viridis", vmax), (clean, "clean", "viridis", vmax),
                  (errors[0], "|noisy − clean| (m)", "magma", top), (errors[1], "|denoised − clean| (m)", "magma", top)]
        for ax, (image, title, cmap, high) in zip(row, panels):
            shown = np.where(valid, image, np.nan)
            im = ax.imshow(shown, cmap=cmap, vmin=0, vmax=high)
            ax.set_title(title, fontsize=8)
            ax.axis("off")
        fig.colorbar(im, ax=row[4], fraction=0.04)
    fig.tight_layout()
    with atomic_output(path, force=True) as tmp:
        fig.savefig(tmp, dpi=90, format="png")
    plt.close(fig)
    return Path(path)


@dataclass
class DenoiseResult:
    out_dir: Path
    table: Table
    scores: dict
    losses: list
    seconds: float


def run_denoising(out_dir: Path | str, config: DenoiseConfig, *, force: bool = False,
                  map_builder=None) -> DenoiseResult:
    """The whole experiment into ``out_dir`` (see the module docstring); fails before any work if an output exists
    and ``force`` is false."""
    from dcslam.depth.models import build_model, save_model
    from dcslam.depth.train import resolve_device
    from dcslam.report.scores import check_outputs

    out_dir = Path(out_dir)
    config.check()
    if not config.train_drives:
        raise DcslamError("no training drives; run `dcslam prepare-tum` first, or give --drives")
    check_outputs([out_dir / name for name in OUTPUT_FILES], force)
    start = time.perf_counter()
    device = resolve_device(config.device)
    torch.manual_seed(config.seed)
    map_builder = map_builder or pointfusion_builder(config.map_voxel_m)
    train_frames, test_frames = split_frames(config)
    net = build_model("dncnn", channels=1, features=config.features, depth=config.layers)
    with torch.no_grad():  # the residual layer starts at zero: training starts from the identity (output = input)
        net.body[-1].weight.zero_()
        net.body[-1].bias.zero_()
    model = DepthDenoiser(net, config.depth_scale_m).to(device)
    losses = train_denoiser(model, train_frames, config, device, map_builder)
    scores = evaluate(model, test_frames, config, device, map_builder)
    table = results_table(scores, config)
    seconds = time.perf_counter() - start

    settings = {**asdict(config), "train_drives": [str(p) for p in config.train_drives],
                "test_drives": [str(p) for p in config.test_drives], "resolved_device": str(device)}
    split = {"train": {f.name: f.frame_ids for f in train_frames}, "test": {f.name: f.frame_ids for f in test_frames}}
    save_model(out_dir / "model.pt", net, meta={"experiment": "demo-icl", "depth_scale_m": config.depth_scale_m,
                                               "sigma_m": config.sigma_m, "scale": config.scale,
                                               "steps": config.steps})
    record = stage_config("denoise", settings)
    record.update(scores={k: scores[k] for k in ("noisy", "denoised", "frames", "pixels")}, frames=split,
                  losses=losses, seconds=seconds)
    write_json_atomic(out_dir / "results.json", record)
    write_text_atomic(out_dir / "results.csv", table.to_csv())
    write_text_atomic(out_dir / "results.md", table.to_markdown())
    plot_denoising(out_dir / "denoising.png", scores["examples"], config.sigma_m)
    return DenoiseResult(out_dir, table, scores, losses, seconds)
