"""Figures of the results: trajectories seen from above, and depth examples like the thesis's appendix C.

Matplotlib is imported lazily with the Agg backend (no display needed). Files are written atomically.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.io.atomic import atomic_output


def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def plot_trajectories(path: Path | str, T_gt: np.ndarray, estimates: dict[str, np.ndarray], title: str = "",
                      force: bool = False) -> Path:
    """Top view (x right, z forward, in the world = first camera frame) of the true trajectory and estimates.

    Shapes: T_gt (N, 4, 4); each estimate (M, 4, 4), M ≤ N.
    """
    T_gt = np.asarray(T_gt)
    if T_gt.ndim != 3 or T_gt.shape[1:] != (4, 4):
        raise DcslamError(f"ground-truth poses have shape {T_gt.shape}, expected (N, 4, 4)")
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 6))
    ax.plot(T_gt[:, 0, 3], T_gt[:, 2, 3], "k--", lw=2, label="ground truth")
    for name, T in estimates.items():
        T = np.asarray(T)
        ax.plot(T[:, 0, 3], T[:, 2, 3], lw=1.2, label=name)
    ax.plot(T_gt[0, 0, 3], T_gt[0, 2, 3], "ko", ms=4)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    with atomic_output(path, force=force) as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)
    return Path(path)


def plot_depth_examples(path: Path | str, rows: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]],
                        rgb: np.ndarray | None = None, max_depth_m: float | None = None, force: bool = False) -> Path:
    """One row per method: input depth, prediction, ground truth, absolute error (where there is ground truth).

    ``rows``: (label, input (H, W), prediction (H, W), ground truth (H, W)), metres, 0 = none; ``rgb`` (H, W, 3)
    uint8 shown above them when given.
    """
    if not rows:
        raise DcslamError("no depth examples to plot")
    plt = _pyplot()
    extra = rgb is not None
    fig, axes = plt.subplots(len(rows) + extra, 4, figsize=(16, 1.6 * (len(rows) + extra) + 0.6), squeeze=False)
    vmax = max_depth_m or float(max(np.max(r[3]) for r in rows) or 1.0)
    if extra:
        axes[0, 0].imshow(rgb)
        axes[0, 0].set_title("image", fontsize=8)
        for ax in axes[0]:
            ax.axis("off")
    for i, (label, inp, pred, gt) in enumerate(rows, start=extra):
        error = np.where(gt > 0, np.abs(pred - gt), np.nan)
        panels = [(inp, "input", "viridis", vmax), (pred, "prediction", "viridis", vmax),
                  (gt, "ground truth", "viridis", vmax), (error, "|error| (m)", "magma", None)]
        for ax, (image, name, cmap, top) in zip(axes[i], panels):
            shown = np.where(image > 0, image, np.nan) if name != "|error| (m)" else image
            im = ax.imshow(shown, cmap=cmap, vmin=0, vmax=top if top else np.nanmax(np.r_[error.ravel(), 1e-3]))
            ax.set_title(f"{label}: {name}", fontsize=8)
            ax.axis("off")
        fig.colorbar(im, ax=axes[i, 3], fraction=0.03)
    fig.tight_layout()
    with atomic_output(path, force=force) as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)
    return Path(path)


def plot_training_curves(path: Path | str, metrics_path: Path | str) -> Path:
    """A training run's curves from its ``metrics.jsonl``: the training loss per step, and the validation RMSE, MAE
    (mm) and chamfer (m²) per validation."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [json.loads(line) for line in Path(metrics_path).read_text().splitlines() if line.strip()]
    train = [(r["step"], r["loss"]) for r in rows if r["kind"] == "train"]
    val = [r for r in rows if r["kind"] == "val"]
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    if train:
        axes[0].plot(*zip(*train), lw=0.8, label="training loss")
    axes[0].set_xlabel("step")
    axes[0].set_ylabel("loss")
    axes[0].set_yscale("log")
    axes[0].legend()
    if val:
        steps = [r["step"] for r in val]
        axes[1].plot(steps, [r["rmse_mm"] for r in val], "o-", label="val RMSE (mm)")
        axes[1].plot(steps, [r["mae_mm"] for r in val], "s-", label="val MAE (mm)")
        twin = axes[1].twinx()
        twin.plot(steps, [r["chamfer"] for r in val], "^--", color="tab:green", label="val chamfer (m²)")
        twin.set_ylabel("chamfer (m²)")
        twin.legend(loc="upper center")
    axes[1].set_xlabel("step")
    axes[1].set_ylabel("mm")
    axes[1].legend(loc="upper right")
    fig.tight_layout()
    with atomic_output(path, force=True) as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)
    return Path(path)
