"""Scoring the denoiser of the appendix C.2 experiment: held-out frames before and after, their table and figure."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch

from dcslam.depth.chamfer import chamfer_distance
from dcslam.depth.data import frame_windows
from dcslam.depth.denoise import DenoiseConfig, DepthDenoiser, Frames, add_depth_noise
from dcslam.depth.losses import batch_depth_errors
from dcslam.errors import DcslamError
from dcslam.eval.denoising import depth_psnr_db
from dcslam.progress import track
from dcslam.report.tables import Column, Table
from dcslam.io.atomic import atomic_output


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
                e = batch_depth_errors(depth, clean)
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
