"""Table 5.2 over whole drives, from stored per-drive trajectories (no SLAM run here)."""
import csv
import io

import numpy as np
import pytest

from dcslam.report.layers import TrajectoryPair
from dcslam.report.results import LayerResult
from dcslam.report.table_5_2_long import layer_label, long_layers, table_5_2_long
from dcslam.report.tables import RunSummary
from tests.fixtures.slam_outputs import commit_slam

DRIVES = ["d1", "d2", "d3", "d4"]


def straight(n: int, step_m: float = 1.0, bend: float = 0.0) -> np.ndarray:
    """(n, 4, 4) poses driving ahead (camera z) ``step_m`` per frame, drifting sideways by ``bend`` · i² m."""
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, 2, 3] = step_m * np.arange(n)
    T[:, 0, 3] = bend * np.arange(n) ** 2
    return T


def pair(n: int, scale: float, bend: float = 0.0) -> TrajectoryPair:
    """An estimate whose positions are ``scale`` times the truth's (a straight drive: an along-track drift).

    The devkit ends a 100 m segment at the first frame *beyond* 100 m (101 m at 1 m per frame) and divides by 100, so
    its t_rel is (scale − 1) · 101 %."""
    T_gt = straight(n, bend=bend)
    T_est = T_gt.copy()
    T_est[:, :3, 3] *= scale
    return TrajectoryPair(timestamps=0.1 * np.arange(n), T_gt=T_gt, T_est=T_est)


def result(label: str, layer: str, frames: int, scales, bend: float = 0.0, **settings) -> LayerResult:
    shared = {"frames": 0, "odometry": "icp", "voxel_size": 0.1, "suspect": settings.pop("suspect", False)}
    return LayerResult(label=label, layer=layer, pairs={d: pair(frames, s, bend) for d, s in zip(DRIVES, scales)},
                       settings={d: {**shared, **settings} for d in DRIVES})


def test_drift_of_whole_drives_with_its_spread_and_a_verdict_against_sparse():
    sparse = result("sparse depth", "sparse", 151, [1.01, 1.02, 1.03, 1.04])
    dense = result("dense depth", "dense", 151, [1.001, 1.002, 1.001, 1.002])
    table = table_5_2_long([sparse, dense], DRIVES)
    first, second = table.rows
    assert first["drives"] == 4 and first["frames_text"] == "151" and first["path_text"] == "150"
    assert first["kitti_t_rel_percent"] == pytest.approx(2.5 * 1.01, abs=1e-6)  # the mean of 1, 2, 3, 4 % · 1.01
    assert first["kitti_r_rel_deg_per_100m"] == pytest.approx(0.0, abs=1e-9)
    assert first["kitti_t_rel_percent_drives"] == 4
    assert first["kitti_t_rel_percent_std"] == pytest.approx(1.01 * np.std([1, 2, 3, 4], ddof=1), abs=1e-6)
    assert first["vs_sparse"] == "reference" and second["vs_sparse"] == "differs"
    assert second["kitti_t_rel_percent"] == pytest.approx(0.15 * 1.01, abs=1e-6)
    assert first["notes"] == "aligned ATE undefined on some drive (degenerate positions)"  # a straight line
    assert first["failures"] == 0  # metres of mean error over 150 m: no failure unless the run was flagged
    assert {r["slam_settings"] for r in table.rows} == {"as the others"}
    assert "frames=0" in table.notes[-1] and "odometry=icp" in table.notes[-1]
    markdown = table.to_markdown()
    assert "| sparse depth | sparse | 4 | 151 | 150 |" in markdown and "2.53 ±" in markdown
    rows = list(csv.DictReader(io.StringIO(table.to_csv())))
    assert float(rows[0]["kitti_t_rel_percent_median"]) == pytest.approx(2.5 * 1.01, abs=1e-6)


def test_drives_too_short_for_100_m_segments_are_said_so_and_keep_ate_rpe():
    short = result("sparse depth", "sparse", 32, [1.01, 1.02, 1.03, 1.04], bend=0.01)
    (row,) = table_5_2_long([short], DRIVES).rows
    assert row.get("kitti_t_rel_percent") is None and row.get("kitti_t_rel_percent_text") is None
    assert "drives too short (longest 33 m < 100 m)" in row["notes"]
    assert row["ate_rmse_m"] > 0 and row["rpe_rmse_m"] > 0 and row["path_text"] == "33"


def test_rows_of_other_settings_or_lengths_say_how():
    sparse = result("sparse depth", "sparse", 151, [1.01] * 4)
    coarse = result("IP-Basic", "ip-basic-fast", 101, [1.01] * 4, voxel_size=0.2)
    rows = table_5_2_long([sparse, coarse], DRIVES).rows
    assert rows[1]["slam_settings"] == "differs: voxel_size=0.2" and rows[1]["frames_text"] == "101"
    flagged = result("dense depth", "dense", 151, [1.0] * 4, suspect=True)
    assert table_5_2_long([flagged], DRIVES).rows[0]["failures"] == 4


def test_layers_found_in_slam_long_sparse_dense_ip_basic_first(tmp_path):
    for name in ("mse-dense", "dense", "ip-basic-fast", "sparse", "empty"):
        (tmp_path / name).mkdir()
        if name != "empty":
            (tmp_path / name / "d1.txt").write_text("")
    assert long_layers(tmp_path) == ["sparse", "dense", "ip-basic-fast", "mse-dense"]
    assert long_layers(tmp_path / "absent") == []
    runs = [RunSummary(name="mse-dense", recipe="MSE dense mask", selected_by="mse", best={}, validations=1)]
    assert [layer_label(n, runs) for n in ("sparse", "ip-basic-fast", "mse-dense", "other")] == [
        "sparse depth", "IP-Basic", "MSE dense mask", "other"]


def test_results_read_from_slam_long_and_build_report_prints_the_table(tmp_path):
    """Trajectories written under slam-long/ (the ground truth itself for sparse, shifted for dense) are scored
    against the drive files; build_report then writes the table after Table 5.2 and its CSVs."""
    from dcslam.io.drive import DriveFile
    from dcslam.io.tum import write_tum
    from dcslam.report.scores import build_report
    from dcslam.report.table_5_2_long import table_5_2_long_results
    from dcslam.workspace import Workspace
    from tests.fixtures.depth import write_workspace

    ws = Workspace(write_workspace(tmp_path))
    with DriveFile(ws.drives / "drive_d.h5") as drive:
        stamps, T_gt = drive.timestamps, drive.poses
    shifted = T_gt.copy()
    shifted[:, 0, 3] += 0.5
    for layer, T in (("dense", shifted), ("sparse", T_gt)):
        write_tum(ws.slam_long / layer / "drive_d.txt", stamps, T)
        commit_slam(ws.slam_long / layer, "drive_d")
    (ws.slam_long / "ip-basic-fast").mkdir()  # no trajectory: not a row

    results = table_5_2_long_results(ws, [], ["drive_d"])
    assert [(r.label, r.layer) for r in results] == [("sparse depth", "sparse"), ("dense depth", "dense")]
    assert results[0].localisation == pytest.approx(0.0, abs=1e-6)
    assert results[1].localisation == pytest.approx(0.5, abs=1e-6)

    report = build_report(ws, ["drive_d"])
    assert report.table_5_2_long is not None and len(report.table_5_2_long.rows) == 2
    markdown = (ws.results / "table_5_2.md").read_text()
    assert markdown.index("### Table 5.2 —") < markdown.index("### Table 5.2, whole drives")
    per_drive = list(csv.DictReader(io.StringIO((ws.results / "table_5_2_long_per_drive.csv").read_text())))
    assert [(r["layer"], r["drive"]) for r in per_drive] == [("sparse", "drive_d"), ("dense", "drive_d")]
