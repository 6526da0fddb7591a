"""The figures a researcher looks at: training curves with validation MSE, depth examples that show the sparse
input and share one error colour range."""
import json

import numpy as np
import pytest

from dcslam.report import plots


def test_training_curves_plot_validation_mse_in_its_own_panel(tmp_path, monkeypatch):
    rows = [{"kind": "train", "epoch": 0, "step": s, "loss": 1.0 / (s + 1)} for s in range(4)]
    rows += [{"kind": "val", "epoch": e, "step": 2 * e + 2, "mse": 0.5 - 0.1 * e, "chamfer": 2.0 - e,
              "mae_mm": 900.0, "rmse_mm": 1200.0} for e in range(2)]
    metrics = tmp_path / "metrics.jsonl"
    metrics.write_text("".join(json.dumps(r) + "\n" for r in rows))
    figures = []
    plt = plots.pyplot()
    monkeypatch.setattr(plt, "close", figures.append)
    out = plots.plot_training_curves(tmp_path / "curves.png", metrics)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    axes = figures[0].axes
    labels = [[line.get_label() for line in ax.lines] for ax in axes]
    assert labels == [["training loss"], ["val RMSE", "val MAE"], ["val MSE"], ["val chamfer"]]
    assert list(axes[2].lines[0].get_ydata()) == [0.5, 0.4]
    assert axes[0].lines[0].get_marker() in (None, "None", "")  # a curve of several steps: a line
    metrics.write_text(json.dumps(rows[0]) + "\n")  # one training step: a dot, not a line of no length
    plots.plot_training_curves(tmp_path / "one.png", metrics)
    assert figures[1].axes[0].lines[0].get_marker() == "o"
    monkeypatch.undo()
    plt.close(figures[0])
    plt.close(figures[1])


@pytest.mark.parametrize("loss, val", [
    ((0.0196, 0.0208), {"rmse_mm": 123456.7, "mae_mm": 0.5, "mse": 1.23456e-5, "chamfer": 99999.9}),  # offset, 1e-5
    ((19.6, 20.8), {"rmse_mm": 6125.5, "mae_mm": 2331.2, "mse": 37.5, "chamfer": 3.5}),  # 2.08 x 10^1 ticks
    ((1e3, 1e-7), {"rmse_mm": 0.01, "mae_mm": 0.001, "mse": 1e9, "chamfer": 0.0001234}),
])
def test_training_curves_keep_every_label_inside_the_figure_and_off_the_other_panels(tmp_path, monkeypatch, loss,
                                                                                    val):
    """The panels sit at fixed margins (no tight_layout pass): long tick labels, offsets and titles still fit."""
    rows = [{"kind": "train", "step": s, "loss": loss[0] + (loss[1] - loss[0]) * s / 12} for s in range(13)]
    rows += [{"kind": "val", "step": 12, **val}]
    metrics = tmp_path / "metrics.jsonl"
    metrics.write_text("".join(json.dumps(r) + "\n" for r in rows))
    figures = []
    plt = plots.pyplot()
    monkeypatch.setattr(plt, "close", figures.append)
    plots.plot_training_curves(tmp_path / "curves.png", metrics)
    fig = figures[0]
    renderer = fig.canvas.get_renderer()
    boxes = [ax.get_tightbbox(renderer) for ax in fig.axes]  # ticks, labels, offset text, title, legend
    assert all(0 <= b.x0 and b.x1 <= fig.bbox.width and 0 <= b.y0 and b.y1 <= fig.bbox.height for b in boxes)
    assert all(left.x1 < right.x0 for left, right in zip(boxes, boxes[1:]))
    monkeypatch.undo()
    plt.close(fig)


def test_depth_examples_dilate_the_input_and_share_the_error_range(tmp_path, monkeypatch):
    gt = np.full((20, 30), 10.0)
    sparse = np.zeros_like(gt)
    sparse[10, 15] = 10.0
    rows = [("small", sparse, gt + 0.1, gt), ("large", sparse, gt + 3.0, gt)]
    figures = []
    plt = plots.pyplot()
    monkeypatch.setattr(plt, "close", figures.append)
    plots.plot_depth_examples(tmp_path / "ex.png", rows)
    panels = [ax for ax in figures[0].axes if ax.images]  # row by row: input, prediction, ground truth, error
    images = [ax.images[0] for ax in panels]
    inputs, errors = images[0::4], images[3::4]
    assert "input" in panels[0].get_title() and "error" in panels[3].get_title()
    assert np.count_nonzero(np.isfinite(np.asarray(inputs[0].get_array(), float))) == 25  # one point, 5 × 5
    assert len(errors) == 2 and errors[0].get_clim() == errors[1].get_clim() == (0, 3.0)
    monkeypatch.undo()
    plt.close(figures[0])


def test_depth_examples_name_each_row_once_and_give_every_panel_a_colour_bar(tmp_path, monkeypatch):
    gt = np.full((20, 30), 10.0)
    label = "chamfer multi-frame + best filter (range 0.5-60 m)"
    rows = [(label, gt, gt + 0.1, gt), ("sparse", gt, gt, gt)]
    figures = []
    plt = plots.pyplot()
    monkeypatch.setattr(plt, "close", figures.append)
    plots.plot_depth_examples(tmp_path / "ex.png", rows)
    fig = figures[0]
    panels = [ax for ax in fig.axes if ax.images]
    bars = [ax for ax in fig.axes if not ax.images]
    assert len(panels) == 8 and len(bars) == 8  # depth columns too, not only the error
    assert [ax.get_title() for ax in panels[4:]] == ["", "", "", ""]  # column names once, above the first row
    assert panels[0].get_ylabel().replace("\n", " ") == label and panels[4].get_ylabel() == "sparse"
    assert max(len(line) for line in panels[0].get_ylabel().splitlines()) <= 18
    assert all(label not in ax.get_title() for ax in panels)
    monkeypatch.undo()
    plt.close(fig)


def test_depth_examples_pick_nearest_pixels_before_the_colour_map_and_draw_the_same_figure(tmp_path, monkeypatch):
    """Panels larger than they are shown are resampled in data (picked, then colour-mapped): the saved figure is
    pixel for pixel the one resampling the colour-mapped image would save, holes (NaN) included."""
    from PIL import Image

    rng = np.random.default_rng(3)
    gt = np.where(rng.random((150, 500)) < 0.3, rng.uniform(2, 60, (150, 500)), 0.0)
    sparse = np.where(rng.random(gt.shape) < 0.05, gt, 0.0)
    rows = [("a", sparse, gt + rng.normal(0, 1, gt.shape), gt), ("b", sparse, np.abs(gt - 1), gt)]
    figures = []
    plt = plots.pyplot()
    monkeypatch.setattr(plt, "close", figures.append)
    plots.plot_depth_examples(tmp_path / "data.png", rows)
    images = [image for ax in figures[0].axes for image in ax.images]
    assert len(images) == 8 and {image.get_interpolation_stage() for image in images} == {"data"}
    for image in images:
        image.set_interpolation_stage("rgba")
    figures[0].savefig(tmp_path / "rgba.png", dpi=100, format="png", bbox_inches="tight")
    data, rgba = (np.asarray(Image.open(tmp_path / f"{name}.png")) for name in ("data", "rgba"))
    assert data.shape == rgba.shape and np.array_equal(data, rgba)
    monkeypatch.undo()
    plt.close(figures[0])


def test_trajectory_styles_never_repeat_and_a_static_trajectory_is_marked(tmp_path):
    T_gt = np.tile(np.eye(4), (20, 1, 1))
    T_gt[:, 2, 3] = np.arange(20.0)  # 19 m straight ahead
    moving = {f"method {i}": T_gt + 0.01 * i for i in range(23)}
    failed = np.tile(np.eye(4), (20, 1, 1))  # never left the start
    estimates = {**moving, "failed": failed}
    styles = plots.trajectory_styles(T_gt, estimates)
    pairs = [(s["color"], s["linestyle"]) for s in styles]
    assert len(set(pairs)) == len(pairs) == 24
    assert styles[-1]["label"] == "failed (static)" and styles[-1]["marker"] == "o"
    assert all("marker" not in s and "(static)" not in s["label"] for s in styles[:-1])
    out = plots.plot_trajectories(tmp_path / "t.png", T_gt, estimates)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_trajectory_legend_lies_beside_the_curves(tmp_path, monkeypatch):
    T_gt = np.tile(np.eye(4), (20, 1, 1))
    T_gt[:, 2, 3] = np.arange(20.0)
    estimates = {f"method {i}": T_gt + 0.05 * i for i in range(15)}
    figures = []
    plt = plots.pyplot()
    monkeypatch.setattr(plt, "close", figures.append)
    plots.plot_trajectories(tmp_path / "t.png", T_gt, estimates)
    (ax,) = figures[0].axes
    figures[0].canvas.draw()
    legend, axes = ax.get_legend().get_window_extent(), ax.get_window_extent()
    assert legend.x0 >= axes.x1 and len(ax.get_legend().get_texts()) == 16
    monkeypatch.undo()
    plt.close(figures[0])
