"""The beams table and its plot, from per-drive figures stored in LayerResults (no SLAM run): known answers for the
spread, the verdict against the sparse input, the share of the gap closed, and the refusal of mixed SLAM settings."""
import csv
import io

import pytest

from dcslam.errors import DcslamError
from dcslam.eval.depth import DepthErrors
from dcslam.report.results import LayerResult
from dcslam.report.table_beams import (INPUTS, MEASURED, layer_name, per_drive_table, plot_localisation_vs_beams,
                                       slam_name, sparse_kind, table_beams)
from tests.fixtures.slam_outputs import commit_slam
from tests.fixtures.trajectories import offset_pair

DRIVES = ["d0", "d1", "d2", "d3"]
PER_BEAM = sum(i.per_beam for i in INPUTS)  # rows per beam count: 9 layers, 8 of them again with measured sources
ROWS = 2 * PER_BEAM + 2
SETTINGS = {"frames": 5, "odometry": "icp", "mapper": "pointfusion", "voxel_size": 0.2}



def _result(label: str, layer: str, offsets: list[float], mae: float = 100.0, settings=SETTINGS) -> LayerResult:
    errors = DepthErrors(mae_mm=mae, rmse_mm=2 * mae, imae_per_km=1.0, irmse_per_km=2.0, pixels=10, coverage=1.0)
    return LayerResult(label=label, layer=layer, depth={d: errors for d in DRIVES},
                       pairs={d: offset_pair(o) for d, o in zip(DRIVES, offsets)},
                       settings={d: dict(settings, suspect=False) for d in DRIVES})


def _results(beams=(64, 16), settings_of=lambda key: SETTINGS):
    """Sparse localises at 0.4 (16 beams) / 0.1 (64); exact at 0.02; nconv masked beats sparse at 16 beams; nconv
    fine-tuned through the pose beats nconv at 16 beams and is level with it at 64; with measured sources exact
    localises at 0.01 and IP-Basic beats sparse at 16 beams. A measured-source row's settings record its mode
    unless ``settings_of`` names one."""
    offsets = {"sparse": {64: 0.1, 16: 0.4}, "nconv masked": {64: 0.12, 16: 0.21}, "nconv": {64: 0.5, 16: 0.8},
               "nconv pose": {64: 0.5, 16: 0.7}, "exact, measured sources": {64: 0.01, 16: 0.01},
               "IP-Basic, measured sources": {64: 0.3, 16: 0.2}}
    jitter = [0.0, 0.01, -0.01, 0.005]
    out = {}
    for b in sorted(beams, reverse=True):
        for item in INPUTS:
            if item.per_beam:
                base = offsets.get(item.label, {64: 0.3, 16: 0.6})[b]
                settings = settings_of((b, item.label))
                if item.sources == MEASURED and "sources" not in settings:
                    settings = dict(settings, sources=MEASURED, measured=sparse_kind(b))
                out[(b, item.label)] = _result(item.label, layer_name(item, b), [base + j for j in jitter],
                                               settings=settings)
    out[(None, "annotated dense")] = _result("annotated dense", "dense", [0.05 + j / 10 for j in jitter], mae=0.0)
    out[(None, "exact")] = _result("exact", "exact", [0.02 + j / 10 for j in jitter], mae=5.0)
    return out


def test_layer_names_follow_the_pipeline():
    names = {item.label: (layer_name(item, 16), slam_name(item, 16)) for item in INPUTS}
    depth = {"sparse": "sparse@16", "IP-Basic": "ip-basic-fast-sparse16", "SparseConvNet": "sparse-conv-sparse16",
             "SparseConvNet → exact": "sparse-conv-exact-sparse16",
             "SparseConvNet geometry": "sparse-conv-geometry-sparse16", "nconv": "nconv-sparse16",
             "nconv masked": "nconv-sparse16+masked", "nconv-guided": "nconv-guided-sparse16",
             "nconv pose": "nconv-pose-sparse16", "annotated dense": "dense", "exact": "exact"}
    measured = {f"{label}, measured sources": (layer, f"{layer}+measured") for label, layer in depth.items()
                if label not in ("sparse", "nconv masked", "annotated dense", "exact")}
    measured["exact, measured sources"] = ("exact", "exact+measured-sparse16")
    assert names == {**{label: (layer, layer) for label, layer in depth.items()}, **measured}
    assert layer_name(INPUTS[0], 64) == "sparse"
    exact = next(i for i in INPUTS if i.label == "exact, measured sources")
    assert exact.per_beam and slam_name(exact, 64) == "exact+measured-sparse64"


def test_table_rows_verdicts_and_gap_closed():
    table = table_beams(_results(), [64, 16], DRIVES)
    rows = {(r["beams"], r["input"]): r for r in table.rows}
    assert [k for k in rows][:2] == [(64, "sparse"), (64, "IP-Basic")]  # beam counts from the largest
    assert len(table.rows) == ROWS and rows[("any", "exact")]["layer"] == "exact"
    # beam counts' rows: the depth-mode ones, then the measured-source ones, compared with the same sparse input
    assert [k for k in rows][PER_BEAM - 8:PER_BEAM] == [(64, f"{label}, measured sources") for label in (
        "IP-Basic", "SparseConvNet", "SparseConvNet → exact", "SparseConvNet geometry", "nconv", "nconv-guided",
        "nconv pose", "exact")]
    ip_measured = rows[(16, "IP-Basic, measured sources")]
    assert ip_measured["vs_sparse"] == "better" and ip_measured["sources"] == MEASURED
    assert ip_measured["layer"] == "ip-basic-fast-sparse16" and rows[(16, "IP-Basic")]["vs_sparse"] == "worse"
    assert ip_measured["gap_closed"] == pytest.approx((0.40125 - 0.20125) / (0.40125 - 0.020125))
    assert rows[(16, "exact, measured sources")]["gap_closed"] > 1  # the ceiling: beyond exact depth's own SLAM
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
    assert sixty_four.endswith("nconv pose vs nconv: within spread; nconv pose, measured sources vs nconv, measured "
                               "sources: within spread")
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
    assert len(table_beams(beams, [64, 16], DRIVES).rows) == ROWS


def test_confidence_use_is_compared_only_among_layers_that_have_a_confidence():
    def settings_of(key):
        if key[1].startswith("nconv"):
            return dict(SETTINGS, confidence="weights", min_confidence=0.0)
        return dict(SETTINGS, confidence="none", min_confidence=0.0)

    assert len(table_beams(_results(settings_of=settings_of), [64, 16], DRIVES).rows) == ROWS
    ignored = _results(settings_of=lambda key: dict(settings_of(key), confidence="ignore") if key == (16, "nconv")
                       else settings_of(key))
    with pytest.raises(DcslamError, match="confidence=weights .* but confidence=ignore for nconv at 16 beams"):
        table_beams(ignored, [64, 16], DRIVES)


def test_per_drive_table_has_every_drive_of_every_row():
    table = per_drive_table(_results())
    assert len(table.rows) == ROWS * 4
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


def test_rows_are_compared_within_their_mode_of_icp_sources():
    def depth(key):  # each row in its own mode (_results records a measured-source row's)
        return SETTINGS if key[1].endswith("measured sources") else dict(SETTINGS, sources="depth", measured=None)

    table = table_beams(_results(settings_of=depth), [64, 16], DRIVES)
    text = table.to_markdown()
    assert "sources=depth / measured" in text and "measured sources: SLAM whose ICP" in text
    # a depth-mode row made with measured sources, a measured-source row made with the depth's own: refused
    wrong = _results(settings_of=lambda key: dict(SETTINGS, sources=MEASURED, measured="sparse@16")
                     if key == (16, "nconv") else depth(key))
    with pytest.raises(DcslamError, match=r"row nconv at 16 beams \(nconv-sparse16\) was made with sources=measured, "
                                          "its rows with sources=depth"):
        table_beams(wrong, [64, 16], DRIVES)
    wrong = _results(settings_of=depth)
    wrong[(16, "IP-Basic, measured sources")] = _result("IP-Basic, measured sources", "ip-basic-fast-sparse16",
                                                        [0.2] * 4, settings=depth((16, "IP-Basic")))
    with pytest.raises(DcslamError, match="IP-Basic, measured sources at 16 beams .* sources=depth, its rows with "
                                          "sources=measured"):
        table_beams(wrong, [64, 16], DRIVES)
    # measured rows differ by their beam count's sparse kind by design, but not from it
    wrong = _results(settings_of=lambda key: dict(SETTINGS, sources=MEASURED, measured="sparse")
                     if key == (16, "exact, measured sources") else depth(key))
    with pytest.raises(DcslamError, match="aligned measured=sparse, not the 16-beam sparse depth"):
        table_beams(wrong, [64, 16], DRIVES)
    # other settings are compared across both modes
    wrong = _results(settings_of=lambda key: dict(SETTINGS, voxel_size=0.05, sources=MEASURED, measured="sparse@16")
                     if key == (16, "nconv, measured sources") else depth(key))
    with pytest.raises(DcslamError, match="voxel_size=0.05 for nconv, measured sources at 16 beams"):
        table_beams(wrong, [64, 16], DRIVES)


def test_a_measured_row_reads_its_own_slam_folder_and_the_layer_s_depth(tmp_path):
    """score_layer with ``slam_name``: the localisation of ``slam/<layer>+measured/``, the depth errors of the
    layer itself, and the mode recorded in the SLAM summary as its settings."""
    import json

    from dcslam.io.drive import DriveFile
    from dcslam.io.tum import write_tum
    from dcslam.report.results import score_layer
    from dcslam.workspace import Workspace
    from tests.fixtures import depth as depth_fixtures

    depth_fixtures.write_workspace(tmp_path, n=4, extra=True)
    ws = Workspace(tmp_path)
    with DriveFile(ws.drives / "drive_d.h5") as drive:
        t, T = drive.timestamps, drive.poses
    for name, offset, sources in (("sparse@16", 0.3, {"mode": "depth"}),
                                  ("exact", 0.2, {"mode": "depth"}),
                                  ("exact+measured-sparse16", 0.05, {"mode": MEASURED, "kind": "sparse@16"})):
        (ws.slam / name).mkdir(parents=True)
        moved = T.copy()
        moved[:, 0, 3] += offset
        write_tum(ws.slam / name / "drive_d.txt", t, moved)
        (ws.slam / name / "drive_d.json").write_text(json.dumps(
            {"settings": dict(SETTINGS), "sources": sources, "rejected_steps": [], "health": {"suspect": False}}))
        commit_slam(ws.slam / name, "drive_d")
    own = score_layer(ws, "exact", "exact", ["drive_d"], surface_frames=0)
    measured = score_layer(ws, "exact, measured sources", "exact", ["drive_d"], surface_frames=0,
                           slam_name="exact+measured-sparse16")
    assert measured.layer == "exact" and measured.depth == own.depth and measured.depth
    assert measured.localisation == pytest.approx(0.05) and own.localisation == pytest.approx(0.2)
    assert measured.run_settings()["sources"] == MEASURED and measured.run_settings()["measured"] == "sparse@16"
    assert own.run_settings()["sources"] == "depth" and own.run_settings()["measured"] is None
    absent = score_layer(ws, "exact", "exact", ["drive_d"], depth=False, slam_name="exact+measured-sparse8")
    assert absent.missing == ["slam/exact+measured-sparse8/ for 1 test drive(s) (dcslam slam)"]
    sparse = score_layer(ws, "sparse", "sparse@16", ["drive_d"], surface_frames=0)
    table = table_beams({(16, "sparse"): sparse, (16, "exact, measured sources"): measured, (None, "exact"): own},
                        [16], ["drive_d"])
    row = next(r for r in table.rows if r["input"] == "exact, measured sources")
    assert row["vs_sparse"] == "one drive" and row["gap_closed"] == pytest.approx(0.25 / 0.1)


def test_a_measured_row_over_training_seeds_reads_each_seed_s_slam_folder(tmp_path):
    import json

    from dcslam.io.drive import DriveFile
    from dcslam.io.tum import write_tum
    from dcslam.report.results import SeedResults
    from dcslam.report.table_beams import beams_results
    from dcslam.workspace import Workspace
    from tests.fixtures import depth as depth_fixtures

    depth_fixtures.write_workspace(tmp_path, n=4, extra=True)
    ws = Workspace(tmp_path)
    with DriveFile(ws.drives / "drive_d.h5") as drive:
        t, T = drive.timestamps, drive.poses
    for k, run in enumerate(("nconv", "nconv-s1")):
        (ws.runs / run).mkdir(parents=True)
        (ws.runs / run / "config.json").write_text(json.dumps({"settings": {"seed": k}}))
        for name, offset in ((f"{run}-sparse16", 0.4), (f"{run}-sparse16+measured", 0.1 + k / 10)):
            (ws.slam / name).mkdir(parents=True)
            moved = T.copy()
            moved[:, 0, 3] += offset
            write_tum(ws.slam / name / "drive_d.txt", t, moved)
            commit_slam(ws.slam / name, "drive_d")
    results = beams_results(ws, [16], ["drive_d"])
    row = results[(16, "nconv, measured sources")]
    assert isinstance(row, SeedResults) and [m.seed for m in row.members] == [0, 1]
    assert [m.layer for m in row.members] == ["nconv-sparse16", "nconv-s1-sparse16"]
    assert [m.localisation for m in row.members] == [pytest.approx(0.1), pytest.approx(0.2)]
    assert results[(16, "nconv")].members[1].localisation == pytest.approx(0.4)


def test_inputs_select_the_rows_scored_and_an_unknown_label_is_refused(tmp_path):
    """``inputs``: only those rows are scored (a study of a few inputs); a label the table does not have is one
    line naming the labels, before any work."""
    from dcslam.errors import DcslamError
    from dcslam.report.table_beams import beams_results
    from dcslam.stages import slam
    from dcslam.workspace import Workspace
    from tests.fixtures.depth import write_workspace

    ws = Workspace(write_workspace(tmp_path / "ws", n=6, extra=True))
    for depth in ("sparse", "sparse@16"):
        slam.run(ws, slam.SlamStageConfig(odometry="gt", frames=2, depth=depth, drive=["drive_d"]))
    results = beams_results(ws, [64, 16], ["drive_d"], inputs=["sparse", "IP-Basic"])
    assert sorted(results) == [(16, "IP-Basic"), (16, "sparse"), (64, "IP-Basic"), (64, "sparse")]
    assert results[(16, "sparse")].pairs and not results[(16, "IP-Basic")].pairs
    with pytest.raises(DcslamError, match="no input 'IP Basic'; choose from: sparse; IP-Basic"):
        beams_results(ws, [64], ["drive_d"], inputs=["IP Basic"])
