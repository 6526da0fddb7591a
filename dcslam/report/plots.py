"""Figures of the results: trajectories seen from above, and depth examples like the thesis's appendix C.

Matplotlib is imported lazily with the Agg backend (no display needed). Files are written atomically.
"""
from __future__ import annotations

import json
import textwrap
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.io.atomic import atomic_output


def pyplot():
    """matplotlib's pyplot on the Agg backend (files only, no display)."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def trajectory_styles(T_gt: np.ndarray, estimates: dict[str, np.ndarray]) -> list[dict]:
    """Matplotlib styles, one per estimate, that never repeat: 10 colours × 4 line styles, and a trajectory that
    barely moves (a failed SLAM: path shorter than 2 % of the truth's) drawn as a large hollow marker at its
    position, labelled "(static)", so that it cannot hide under the start marker. Shapes: T_gt (N, 4, 4)."""
    colours = [f"C{i}" for i in range(10)]
    dashes = ["-", "--", "-.", ":"]
    truth_m = float(np.linalg.norm(np.diff(np.asarray(T_gt)[:, :3, 3], axis=0), axis=1).sum())
    styles = []
    for i, (name, T) in enumerate(estimates.items()):
        T = np.asarray(T)
        path_m = float(np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1).sum()) if len(T) > 1 else 0.0
        style = {"color": colours[i % 10], "linestyle": dashes[(i // 10) % 4], "label": name}
        if path_m < 0.02 * max(truth_m, 1e-9):
            style.update(label=f"{name} (static)", marker="o", ms=11, mfc="none", mew=2)
        styles.append(style)
    return styles


def plot_trajectories(path: Path | str, T_gt: np.ndarray, estimates: dict[str, np.ndarray], title: str = "",
                      force: bool = False) -> Path:
    """Top view (x right, z forward, in the world = first camera frame) of the true trajectory and estimates.

    Shapes: T_gt (N, 4, 4); each estimate (M, 4, 4), M ≤ N.
    """
    T_gt = np.asarray(T_gt)
    if T_gt.ndim != 3 or T_gt.shape[1:] != (4, 4):
        raise DcslamError(f"ground-truth poses have shape {T_gt.shape}, expected (N, 4, 4)")
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8.5, 6))
    ax.plot(T_gt[0, 0, 3], T_gt[0, 2, 3], "ko", ms=4, zorder=1)  # the start, beneath everything
    ax.plot(T_gt[:, 0, 3], T_gt[:, 2, 3], "k--", lw=2, label="ground truth", zorder=2)
    for (name, T), style in zip(estimates.items(), trajectory_styles(T_gt, estimates)):
        T = np.asarray(T)
        ax.plot(T[:, 0, 3], T[:, 2, 3], lw=1.2, zorder=3, **style)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)
    # beside the axes, never over the curves: a table of 15 recipes would cover them
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0,
              ncol=1 if len(estimates) < 20 else 2)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    with atomic_output(path, force=force) as tmp:
        fig.savefig(tmp, dpi=120, format="png", bbox_inches="tight")
    plt.close(fig)
    return Path(path)


def _dilate(depth: np.ndarray, radius: int = 2) -> np.ndarray:
    """Sparse depth (H, W) with each measurement spread over a (2r+1)² square (where squares overlap, one of
    them), so that one-pixel LiDAR points are visible in a figure. For display only."""
    depth = np.asarray(depth, np.float64)
    out = depth.copy()
    h, w = depth.shape
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            shifted = np.zeros_like(depth)
            shifted[max(dy, 0):h + min(dy, 0), max(dx, 0):w + min(dx, 0)] = \
                depth[max(-dy, 0):h + min(-dy, 0), max(-dx, 0):w + min(-dx, 0)]
            out = np.where((out == 0) & (shifted > 0), shifted, out)
    return out


def plot_depth_examples(path: Path | str, rows: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]],
                        rgb: np.ndarray | None = None, max_depth_m: float | None = None, force: bool = False) -> Path:
    """One row per method: input depth (dilated so sparse points show), prediction, ground truth, absolute error
    (where there is ground truth; one colour range, the 99th percentile over all rows, so rows compare). Each panel
    has its colour bar; the columns are named once above the first row and each row by its label on its left
    (wrapped, never clipped).

    ``rows``: (label, input (H, W), prediction (H, W), ground truth (H, W)), metres, 0 = none; ``rgb`` (H, W, 3)
    uint8 shown above them when given.
    """
    if not rows:
        raise DcslamError("no depth examples to plot")
    plt = pyplot()
    extra = rgb is not None
    fig, axes = plt.subplots(len(rows) + extra, 4, figsize=(16, 1.6 * (len(rows) + extra) + 0.6), squeeze=False)
    vmax = max_depth_m or float(max(np.max(r[3]) for r in rows) or 1.0)
    errors = [np.where(gt > 0, np.abs(pred - gt), np.nan) for _, _, pred, gt in rows]
    finite = np.concatenate([e[np.isfinite(e)] for e in errors] + [np.zeros(1)])
    error_max = float(np.percentile(finite, 99)) or 1e-3  # one colour range for every row's error
    if extra:
        axes[0, 0].imshow(rgb)
        axes[0, 0].set_title("image", fontsize=8)
        for ax in axes[0]:
            ax.axis("off")
    for i, ((label, inp, pred, gt), error) in enumerate(zip(rows, errors), start=extra):
        panels = [(_dilate(inp), "input depth (m), dilated to be seen", "viridis", vmax),
                  (pred, "prediction (m)", "viridis", vmax), (gt, "ground truth (m)", "viridis", vmax),
                  (error, "|error| (m)", "magma", error_max)]
        for ax, (image, name, cmap, top) in zip(axes[i], panels):
            shown = np.where(image > 0, image, np.nan) if cmap == "viridis" else image
            # nearest pixels picked before the colour map, not after: the same figure, without colour-mapping all
            # of a full-size image that the panel shows at a quarter of its width (a third of the figure's time)
            im = ax.imshow(shown, cmap=cmap, vmin=0, vmax=top, interpolation="nearest", interpolation_stage="data")
            if i == extra:
                ax.set_title(name, fontsize=9)
            ax.set_xticks([])
            ax.set_yticks([])
            fig.colorbar(im, ax=ax, fraction=0.035, pad=0.01).ax.tick_params(labelsize=7)
        axes[i, 0].set_ylabel(textwrap.fill(label, 18, break_on_hyphens=False), fontsize=9, rotation=0, ha="right",
                              va="center")
    fig.tight_layout()
    with atomic_output(path, force=force) as tmp:
        fig.savefig(tmp, dpi=100, format="png", bbox_inches="tight")
    plt.close(fig)
    return Path(path)


CURVES_MARGINS = {"left": 0.075, "right": 0.99, "bottom": 0.15, "top": 0.86, "wspace": 0.32}  # of the figure


def plot_training_curves(path: Path | str, metrics_path: Path | str) -> Path:
    """A training run's curves from its ``metrics.jsonl``, one quantity family per panel (so no legend covers
    another's curves): the training loss per step; the validation RMSE and MAE (mm); the validation MSE (m², the
    checkpoint criterion of MSE runs) and chamfer (m², that of chamfer runs), each on its own axis."""
    plt = pyplot()
    rows = [json.loads(line) for line in Path(metrics_path).read_text().splitlines() if line.strip()]
    train = [(r["step"], r["loss"]) for r in rows if r["kind"] == "train"]
    val = [r for r in rows if r["kind"] == "val"]
    # fixed margins, not tight_layout: its extra draw of the figure took a quarter of a call's time, paid after every
    # epoch of every training; they fit the longest ticks the formats below give, offsets and titles (a test draws
    # extreme values)
    fig, axes = plt.subplots(1, 4, figsize=(16, 3.6), gridspec_kw=CURVES_MARGINS)
    if train:
        # a lone step (a one-step smoke training) is a line of no length: drawn as a dot
        axes[0].plot(*zip(*train), lw=0.8, label="training loss", marker="o" if len(train) == 1 else None)
    axes[0].set(xlabel="step", ylabel="loss", yscale="log", title="training loss")
    steps = [r["step"] for r in val]
    panels = [(axes[1], (("rmse_mm", "val RMSE", "o-"), ("mae_mm", "val MAE", "s-")), "mm", "validation depth errors"),
              (axes[2], (("mse", "val MSE", "o-"),), "m²", "validation MSE (MSE runs' criterion)"),
              (axes[3], (("chamfer", "val chamfer", "^-"),), "m²", "validation chamfer (chamfer runs' criterion)")]
    for ax, curves, unit, title in panels:
        for key, label, style in curves:
            points = [(s, r[key]) for s, r in zip(steps, val) if r.get(key) is not None]
            if points:
                ax.plot(*zip(*points), style, label=label)
        ax.set(xlabel="step", ylabel=unit, title=title)
        ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 4))  # short ticks: 0.00012 is 1.2 with 1e-4 above
        if ax.lines:
            ax.legend(loc="best", fontsize=8)
    if train:
        axes[0].legend(loc="best", fontsize=8)
    for ax in axes:
        ax.title.set_fontsize(9)
    with atomic_output(path, force=True) as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)
    return Path(path)
