"""The beams table and its plot, from per-drive figures stored in LayerResults (no SLAM run): known answers for the
spread, the verdict against the sparse input, the share of the gap closed, and the refusal of mixed SLAM settings."""
import csv
import io

import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.eval.depth import DepthErrors
from dcslam.report.layers import TrajectoryPair
from dcslam.report.table_5_2 import LayerResult
from dcslam.report.table_beams import (INPUTS, layer_name, per_drive_table, plot_localisation_vs_beams,
                                       table_beams)

DRIVES = ["d0", "d1", "d2", "d3"]
SETTINGS = {"frames": 5, "odometry": "icp", "mapper": "pointfusion", "voxel_size": 0.2}


def _pair(offset_m: float, n: int = 5) -> TrajectoryPair:
    """A straight drive along z and an estimate ``offset_m`` to its side at every pose: localisation = offset."""
    T_gt = np.repeat(np.eye(4)[None], n, axis=0)
    T_gt[:, 2, 3] = np.arange(n, dtype=float)
    T_est = T_gt.copy()
    T_est[:, 0, 3] += offset_m
    return TrajectoryPair(timestamps=np.arange(n, dtype=float), T_gt=T_gt, T_est=T_est)


def _result(label: str, layer: str, offsets: list[float], mae: float = 100.0, settings=SETTINGS) -> LayerResult:
    errors = DepthErrors(mae_mm=mae, rmse_mm=2 * mae, imae_per_km=1.0, irmse_per_km=2.0, pixels=10, coverage=1.0)
    return LayerResult(label=label, layer=layer, depth={d: errors for d in DRIVES},
                       pairs={d: _pair(o) for d, o in zip(DRIVES, offsets)},
                       settings={d: dict(settings, suspect=False) for d in DRIVES})


def _results(beams=(64, 16), settings_of=lambda key: SETTINGS):
    """Sparse localises at 0.4 (16 beams) / 0.1 (64); exact at 0.02; nconv masked beats sparse at 16 beams; nconv
    fine-tuned through the pose beats nconv at 16 beams and is level with it at 64."""
    offsets = {"sparse": {64: 0.1, 16: 0.4}, "nconv masked": {64: 0.12, 16: 0.21}, "nconv": {64: 0.5, 16: 0.8},
               "nconv pose": {64: 0.5, 16: 0.7}}
    jitter = [0.0, 0.01, -0.01, 0.005]
    out = {}
    for b in sorted(beams, reverse=True):
        for item in INPUTS:
            if item.per_beam:
                base = offsets.get(item.label, {64: 0.3, 16: 0.6})[b]
                out[(b, item.label)] = _result(item.label, layer_name(item, b), [base + j for j in jitter],
                                               settings=settings_of((b, item.label)))
    out[(None, "annotated dense")] = _result("annotated dense", "dense", [0.05 + j / 10 for j in jitter], mae=0.0)
    out[(None, "exact")] = _result("exact", "exact", [0.02 + j / 10 for j in jitter], mae=5.0)
    return out


def test_layer_names_follow_the_pipeline():
    names = {item.label: layer_name(item, 16) for item in INPUTS}
    assert names == {"sparse": "sparse@16", "IP-Basic": "ip-basic-fast-sparse16",
                     "SparseConvNet": "sparse-conv-sparse16", "nconv": "nconv-sparse16",
                     "nconv masked": "nconv-sparse16+masked", "nconv-guided": "nconv-guided-sparse16",
                     "nconv pose": "nconv-pose-sparse16", "annotated dense": "dense", "exact": "exact"}
    assert layer_name(INPUTS[0], 64) == "sparse"


def test_table_rows_verdicts_and_gap_closed():
    table = table_beams(_results(), [64, 16], DRIVES)
    rows = {(r["beams"], r["input"]): r for r in table.rows}
    assert [k for k in rows][:2] == [(64, "sparse"), (64, "IP-Basic")]  # beam counts from the largest
    assert len(table.rows) == 2 * 7 + 2 and rows[("any", "exact")]["layer"] == "exact"
    masked = rows[(16, "nconv masked")]
    assert masked["drives"] == 4 and masked["failures"] == 0
    assert masked["localisation"] == pytest.approx(0.21 + 0.00125)
    assert masked["vs_sparse"] == "better" and rows[(16, "nconv")]["vs_sparse"] == "worse"
    assert rows[(16, "sparse")]["vs_sparse"] == "reference"
    # (sparse − masked) / (sparse − exact) with the means over the drives: (0.40125 − 0.21125) / (0.40125 − 0.020125)
    assert masked["gap_closed"] == pytest.approx(0.19 / (0.40125 - 0.020125))
    assert masked["gap_closed_text"] == "50 %"
    assert " ± " in masked["localisation_text"] and masked["mae_mm_text"].startswith("100.0 ± 0.0")
    text = table.to_markdown()
    assert "16 beams: better than sparse beyond the spread: nconv masked" in text
    assert "nconv masked vs unmasked: better" in text and "4 test drives × 5 SLAM frames" in text
    assert "64 beams: better than sparse beyond the spread: none" in text
    assert "16 beams:" in text and "nconv pose vs nconv: better" in text
    assert rows[(64, "nconv pose")]["layer"] == "nconv-pose-sparse64"
    sixty_four = next(line for line in table.notes if line.startswith("64 beams:"))
    assert sixty_four.endswith("nconv pose vs nconv: within spread")
    header = next(csv.reader(io.StringIO(table.to_csv())))
    assert {"localisation_ci_low", "localisation_median", "gap_closed", "rmse_mm_std"} <= set(header)


def test_missing_inputs_are_kept_as_empty_rows():
    results = _results()
    results[(16, "SparseConvNet")] = LayerResult("SparseConvNet", "sparse-conv-sparse16",
                                                 missing=["slam/sparse-conv-sparse16/ for 4 test drive(s)"])
    row = next(r for r in table_beams(results, [64, 16], DRIVES).rows
               if r["input"] == "SparseConvNet" and r["beams"] == 16)
    assert row.get("localisation_text") is None and row["vs_sparse"] is None and "slam/" in row["notes"]


def test_rows_made_with_other_slam_settings_are_refused():
    other = dict(SETTINGS, voxel_size=0.05)
    results = _results(settings_of=lambda key: other if key == (16, "nconv") else SETTINGS)
    with pytest.raises(DcslamError, match="voxel_size=0.2 .* but voxel_size=0.05 for nconv at 16 beams"):
        table_beams(results, [64, 16], DRIVES)
    # the beam count of the input is not a difference of settings
    beams = _results(settings_of=lambda key: dict(SETTINGS, beams=key[0]) if key[0] else SETTINGS)
    assert len(table_beams(beams, [64, 16], DRIVES).rows) == 16


def test_confidence_use_is_compared_only_among_layers_that_have_a_confidence():
    def settings_of(key):
        if key[1].startswith("nconv"):
            return dict(SETTINGS, confidence="weights", min_confidence=0.0)
        return dict(SETTINGS, confidence="none", min_confidence=0.0)

    assert len(table_beams(_results(settings_of=settings_of), [64, 16], DRIVES).rows) == 16
    ignored = _results(settings_of=lambda key: dict(settings_of(key), confidence="ignore") if key == (16, "nconv")
                       else settings_of(key))
    with pytest.raises(DcslamError, match="confidence=weights .* but confidence=ignore for nconv at 16 beams"):
        table_beams(ignored, [64, 16], DRIVES)


def test_per_drive_table_has_every_drive_of_every_row():
    table = per_drive_table(_results())
    assert len(table.rows) == 16 * 4
    row = next(r for r in table.rows if r["input"] == "nconv masked" and r["beams"] == 16 and r["drive"] == "d1")
    assert row["localisation"] == pytest.approx(0.22) and row["layer"] == "nconv-sparse16+masked"
    assert row["mae_mm"] == 100.0 and row["voxel_size"] == 0.2


def test_plot_of_localisation_against_beams(tmp_path):
    path = plot_localisation_vs_beams(tmp_path / "beams.png", _results(), [64, 16])
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 10_000
    with pytest.raises(DcslamError, match="exists"):
        plot_localisation_vs_beams(path, _results(), [64, 16])


def test_a_layer_left_empty_on_a_drive_shows_infinite_depth_errors_not_a_crash():
    results = _results()
    masked = results[(16, "nconv masked")]
    empty = DepthErrors(mae_mm=float("inf"), rmse_mm=float("inf"), imae_per_km=float("inf"),
                        irmse_per_km=float("inf"), pixels=0, coverage=0.0)
    masked.depth["d2"] = empty
    row = next(r for r in table_beams(results, [64, 16], DRIVES).rows
               if r["input"] == "nconv masked" and r["beams"] == 16)
    assert row["mae_mm"] == float("inf") and row["mae_mm_text"] == "inf (1 drive(s) without a finite value)"
    assert row["localisation"] == pytest.approx(0.21125)  # the other figures are unaffected
