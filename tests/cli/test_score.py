import csv
import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dcslam.io.drive import DriveFrame, DriveWriter, Layer, write_layer
from dcslam.io.kitti_poses import write_kitti_poses
from dcslam.io.tum import read_tum, write_tum
from tests.fixtures.slam_outputs import commit_slam

K = np.array([[20.0, 0, 12], [0, 20.0, 8], [0, 0, 1]])
H, W, N = 16, 24, 4


def gt_poses(n=N):
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = Rotation.from_rotvec([[0, 0.05 * i, 0] for i in range(n)]).as_matrix()
    T[:, :3, 3] = [[np.sin(i), 0.1 * i, 2.0 * i] for i in range(n)]
    return T


def write_ply(path, points):
    path.parent.mkdir(parents=True, exist_ok=True)
    header = f"ply\nformat ascii 1.0\nelement vertex {len(points)}\nproperty float x\nproperty float y\n" \
             "property float z\nend_header\n"
    path.write_text(header + "".join(f"{x} {y} {z}\n" for x, y, z in points))


def write_run(root, name, loss, mask, map_frames, vals):
    run = root / "runs" / name
    run.mkdir(parents=True)
    settings = {"loss": loss, "mask": mask, "map_frames": map_frames}
    (run / "config.json").write_text(json.dumps({"stage": "train", "settings": settings}))
    lines = [{"kind": "train", "epoch": 0, "step": 0, "drive": "d0", "loss": 1.0}]
    lines += [{"kind": "val", "epoch": e, "step": e, **v} for e, v in enumerate(vals)]
    (run / "metrics.jsonl").write_text("".join(json.dumps(line) + "\n" for line in lines))


@pytest.fixture
def ws(tmp_path):
    """Two test drives, a trained run with predictions and a filter of them, SLAM outputs for several layers."""
    root = tmp_path / "ws"
    rng = np.random.default_rng(0)
    (root / "drives").mkdir(parents=True)
    drives = ("d0", "d1")
    for name in drives:
        with DriveWriter(root / "drives" / f"{name}.h5", K, H, W, source="synthetic", date="2011_09_26",
                         drive=name) as writer:
            for i, T in enumerate(gt_poses()):
                dense = rng.uniform(2, 30, (H, W)).astype(np.float32)
                sparse = np.where(rng.random((H, W)) < 0.3, dense, 0).astype(np.float32)
                writer.append(DriveFrame(rgb=np.zeros((H, W, 3), np.uint8), sparse=sparse, dense=dense, T_world_cam=T,
                                    timestamp=10 + 0.1 * i, frame_id=i))
    (root / "drives" / "splits.json").write_text(json.dumps({"train": [], "val": [], "test": list(drives)}))
    write_run(root, "mse-dense", "mse", "dense", 1, [{"chamfer": 3.0, "mse": 2.0, "mae_mm": 900.0, "rmse_mm": 1500.0},
                                                     {"chamfer": 2.5, "mse": 1.0, "mae_mm": 800.0, "rmse_mm": 1200.0},
                                                     {"chamfer": 2.0, "mse": 1.5, "mae_mm": 850.0, "rmse_mm": 1300.0}])
    offset = {"mse-dense": 0.5, "mse-dense+range": 0.2, "sparse": 1.0, "dense": 0.0}
    for name in drives:
        write_layer(root / "predictions" / "mse-dense" / f"{name}.h5",
                    Layer(depth=rng.uniform(1, 40, (N, H, W)).astype(np.float32), drive=name, made_by="mse-dense"))
        write_layer(root / "filtered" / "mse-dense+range" / f"{name}.h5",
                    Layer(depth=rng.uniform(5, 20, (N, H, W)).astype(np.float32), drive=name, made_by="x"))
        for layer, shift in offset.items():
            T = gt_poses()[:3].copy()          # SLAM ran over the first 3 frames only
            T[:, 0, 3] += shift * np.arange(3)
            write_tum(root / "slam" / layer / f"{name}.txt", 10 + 0.1 * np.arange(3), T)
            write_ply(root / "slam" / layer / f"{name}.ply", [[0, 0, shift], [1, 0, 0], [0, 1, 0]])
            commit_slam(root / "slam" / layer, name)
    (root / "filtered" / "mse-dense+range" / "config.json").write_text(
        json.dumps({"stage": "filter", "settings": {"source_layer": "mse-dense"}}))
    return root


def read_csv(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def test_score_depth(cli, ws):
    result = cli("score", "depth", "-w", ws, "--layer", "dense")
    assert result.exit_code == 0, result.output
    rows = read_csv(ws / "results" / "depth_dense.csv")
    assert [r["drive"] for r in rows] == ["d0", "d1", "all"]
    assert float(rows[-1]["mae_mm"]) == 0.0 and rows[-1]["frames"] == str(2 * N)
    result = cli("score", "depth", "-w", ws, "--layer", "mse-dense", "--drive", "d1", "--out", ws / "x.csv")
    assert result.exit_code == 0 and float(read_csv(ws / "x.csv")[0]["mae_mm"]) > 1000
    again = cli("score", "depth", "-w", ws, "--layer", "dense")
    assert again.exit_code == 1 and "--force" in again.output


def test_score_depth_devkit_exact(cli, ws):
    """--devkit-exact scores predictions below 0.1 m as the devkit does (dcslam's default counts them as holes)."""
    depth = np.full((N, H, W), 10.0, np.float32)
    depth[:, :, ::2] = 0.05
    for name in ("d0", "d1"):
        write_layer(ws / "predictions" / "tiny" / f"{name}.h5", Layer(depth=depth, drive=name, made_by="test"))
    ours = cli("score", "depth", "-w", ws, "--layer", "tiny", "--out", ws / "ours.csv")
    exact = cli("score", "depth", "-w", ws, "--layer", "tiny", "--out", ws / "exact.csv", "--devkit-exact")
    assert ours.exit_code == 0 and exact.exit_code == 0, ours.output + exact.output
    ours, exact = read_csv(ws / "ours.csv")[-1], read_csv(ws / "exact.csv")[-1]
    # 0.05 m against 2-30 m: inverse errors of about 20 /m = 20000 /km on half the pixels
    assert float(exact["imae_per_km"]) > 5000 > float(ours["imae_per_km"])
    assert json.loads((ws / "exact.json").read_text())["settings"]["devkit_exact"] is True
    both = cli("score", "depth", "-w", ws, "--layer", "tiny", "--raw", "--devkit-exact", "--out", ws / "no.csv")
    assert both.exit_code == 1 and "cannot be combined" in both.output and not (ws / "no.csv").exists()
    assert "--devkit-exact" in cli("score", "depth", "--help").output


SURFACE_COLUMNS = ("normal_mean_deg", "normal_median_deg", "p2p_mean_m", "p2p_rmse_m", "flying_share")


@pytest.fixture
def step_ws(tmp_path):
    """A generated drive whose exact depth is a step (5 m left of column 10, 10 m right of it) seen head-on; a layer
    ``mixed`` that blends the two sides linearly over columns 8-11 and a layer ``far`` 5 cm behind the step."""
    root = tmp_path / "step"
    (root / "drives").mkdir(parents=True)
    rows, columns, frames = 8, 20, 3
    K_step = np.array([[40.0, 0, columns / 2], [0, 40.0, rows / 2], [0, 0, 1]])
    exact = np.full((rows, columns), 10.0, np.float32)
    exact[:, :10] = 5.0
    sparse = np.where(np.arange(rows)[:, None] % 2 == 0, exact, 0).astype(np.float32)
    with DriveWriter(root / "drives" / "s0.h5", K_step, rows, columns, source="synthetic", date="2011_09_26",
                     drive="s0", extra=("exact",)) as writer:
        for i, T in enumerate(gt_poses(frames)):
            writer.append(DriveFrame(rgb=np.zeros((rows, columns, 3), np.uint8), sparse=sparse, dense=exact,
                                     T_world_cam=T, timestamp=10 + 0.1 * i, frame_id=i, extra={"exact": exact}))
    (root / "drives" / "splits.json").write_text(json.dumps({"train": [], "val": [], "test": ["s0"]}))
    mixed = exact.copy()
    mixed[:, 8:12] = [6.0, 7.0, 8.0, 9.0]
    write_layer(root / "predictions" / "mixed" / "s0.h5",
                Layer(depth=np.stack([mixed] * frames), drive="s0", made_by="test"))
    write_layer(root / "predictions" / "far" / "s0.h5",
                Layer(depth=np.stack([exact + 0.05] * frames), drive="s0", made_by="test"))
    return root


def test_score_depth_reports_the_surface_against_exact_depth(cli, step_ws):
    results = step_ws / "results"
    for layer in ("exact", "mixed", "far"):
        result = cli("score", "depth", "-w", step_ws, "--layer", layer, "--target", "exact")
        assert result.exit_code == 0, result.output
        assert all((results / f"depth_{layer}_vs_exact.{ext}").exists() for ext in ("csv", "json"))
        assert "flying share" in result.output and "normal median" in result.output and "p2p mean" in result.output
    rows = {layer: read_csv(results / f"depth_{layer}_vs_exact.csv") for layer in ("exact", "mixed", "far")}
    assert all(c in rows["exact"][0] for c in SURFACE_COLUMNS)
    assert [r["drive"] for r in rows["mixed"]] == ["s0", "all"] and rows["mixed"][-1]["frames"] == "3"
    exact, mixed, far = (rows[k][-1] for k in ("exact", "mixed", "far"))
    assert float(exact["p2p_mean_m"]) == 0 and float(exact["flying_share"]) == 0
    assert float(exact["normal_mean_deg"]) == pytest.approx(0, abs=1e-6)
    # the blend: 4 of the 6 columns within 2 px of the edge lie 1-2 m off both sides
    assert float(mixed["flying_share"]) == pytest.approx(4 / 6)
    # an offset within the tolerance (0.1 m) moves every point off the surface but none off both sides
    assert float(far["p2p_mean_m"]) == pytest.approx(0.05, abs=1e-5) and float(far["flying_share"]) == 0
    config = json.loads((results / "depth_mixed_vs_exact.json").read_text())
    assert config["settings"]["target"] == "exact"
    dense = cli("score", "depth", "-w", step_ws, "--layer", "mixed")          # the annotated (here equal) depth
    assert dense.exit_code == 0, dense.output
    assert float(read_csv(results / "depth_mixed.csv")[-1]["flying_share"]) == pytest.approx(4 / 6)

def test_score_trajectory_layer_and_files(cli, ws):
    result = cli("score", "trajectory", "-w", ws, "--layer", "sparse")
    assert result.exit_code == 0, result.output
    assert "ATE aligned" in result.stdout and "ate_aligned_rmse" not in result.stdout  # headers read by people
    rows = read_csv(ws / "results" / "trajectory_sparse.csv")  # keys, read by programs
    assert [r["trajectory"] for r in rows] == ["d0", "d1"] and rows[0]["poses"] == "3"
    # x drifts by 0, 1, 2 m: unaligned ATE errors 0, 1, 2 → rmse sqrt(5/3); RPE translation 1 m every step
    assert float(rows[0]["ate_rmse"]) == pytest.approx(np.sqrt(5 / 3), rel=1e-6)
    assert float(rows[0]["rpe_trans_m_rmse"]) == pytest.approx(1.0, rel=1e-6)
    assert float(rows[0]["localisation"]) == pytest.approx(1.0, rel=1e-6)
    est, ref = ws / "slam" / "dense" / "d0.txt", ws / "slam" / "sparse" / "d0.txt"
    result = cli("score", "trajectory", "-w", ws, "--est", est, "--gt", ref, "--out", ws / "t.csv")
    assert result.exit_code == 0 and float(read_csv(ws / "t.csv")[0]["ate_rmse"]) == pytest.approx(np.sqrt(5 / 3))


def test_score_trajectory_runs_without_torch(ws):
    """Scoring trajectories is NumPy's work: the command (a fresh process, as users start it) writes its CSV without
    importing torch, whose import alone costs 2-3 s of CPU."""
    import subprocess
    import sys

    code = ("import sys\nfrom dcslam.cli import main\nsys.argv = ['dcslam', *sys.argv[1:]]\ntry:\n    main()\n"
            "except SystemExit as e:\n    assert not e.code, e.code\nprint('torch' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code, "score", "trajectory", "-w", str(ws), "--layer", "dense"],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "False"
    assert read_csv(ws / "results" / "trajectory_dense.csv")[0]["trajectory"] == "d0"


def test_score_trajectory_associates_within_the_time_tolerance(cli, ws, tmp_path):
    """Poses are paired as evo pairs them: nearest timestamp within --max-time-diff (default 10 ms); only the
    paired poses are scored and the pairing is reported."""
    ref = ws / "slam" / "dense" / "d0.txt"
    t_ref, _ = read_tum(ref)
    short = tmp_path / "short.txt"
    write_tum(short, t_ref[:2] + 0.004, gt_poses(2))  # two poses, 4 ms late: both paired
    result = cli("score", "trajectory", "-w", ws, "--est", short, "--gt", ref, "--out", ws / "a.csv")
    assert result.exit_code == 0, result.output
    assert read_csv(ws / "a.csv")[0]["poses"] == "2"
    assert "2 of 2 estimated poses paired with 3 reference poses (max. time difference 10 ms)" in result.output
    late = tmp_path / "late.txt"
    write_tum(late, t_ref + 0.02, gt_poses(3))  # 20 ms late: nothing pairs at 10 ms …
    result = cli("score", "trajectory", "-w", ws, "--est", late, "--gt", ref, "--out", ws / "b.csv")
    assert result.exit_code == 1 and "within 10 ms" in result.output and not (ws / "b.csv").exists()
    result = cli("score", "trajectory", "-w", ws, "--est", late, "--gt", ref, "--out", ws / "b.csv",
                 "--max-time-diff", "0.03")  # … everything at 30 ms
    assert result.exit_code == 0, result.output
    assert read_csv(ws / "b.csv")[0]["poses"] == "3"


def test_score_trajectory_reads_kitti_pose_files(cli, ws, tmp_path):
    """A KITTI pose file (no timestamps) is paired by index with a reference of as many poses; any other length is
    refused."""
    est = tmp_path / "est.kitti.txt"
    _, T_sparse = read_tum(ws / "slam" / "sparse" / "d0.txt")
    write_kitti_poses(est, T_sparse)
    result = cli("score", "trajectory", "-w", ws, "--est", est, "--gt", ws / "slam" / "dense" / "d0.txt",
                 "--out", ws / "k.csv")
    assert result.exit_code == 0, result.output
    assert float(read_csv(ws / "k.csv")[0]["ate_rmse"]) == pytest.approx(np.sqrt(5 / 3))
    too_long = tmp_path / "long.kitti.txt"
    write_kitti_poses(too_long, np.concatenate([T_sparse, T_sparse]))
    result = cli("score", "trajectory", "-w", ws, "--est", too_long, "--gt", ws / "slam" / "dense" / "d0.txt")
    assert result.exit_code == 1 and "paired by index" in result.output


def test_score_trajectory_bad_input(cli, ws, tmp_path):
    unsorted = tmp_path / "unsorted.txt"
    unsorted.write_text("10.2 0 0 0 0 0 0 1\n10.1 0 0 0 0 0 0 1\n")
    result = cli("score", "trajectory", "-w", ws, "--est", unsorted, "--gt", ws / "drives" / "d0.h5")
    assert result.exit_code == 1 and "not strictly increasing" in result.output
    assert not (ws / "results").exists()
    assert cli("score", "trajectory", "-w", ws).exit_code == 1


def test_score_map(cli, ws):
    result = cli("score", "map", "-w", ws, "--layer", "sparse")
    assert result.exit_code == 0, result.output
    rows = read_csv(ws / "results" / "map_sparse.csv")
    # map point (0, 0, 1) vs ground truth (0, 0, 0): nearest 1 m away both ways → (1/3 + 1/3) m²
    assert float(rows[0]["chamfer_m2"]) == pytest.approx(2 / 3, rel=1e-6)


@pytest.mark.parametrize("command, file_option, file_name, usage", [
    ("trajectory", "--est", "slam/dense/d0.txt", "give either --est X.txt --gt REFERENCE, or --layer NAME"),
    ("map", "--map", "slam/dense/d0.ply", "give either --map X.ply --gt Y.ply, or --layer NAME"),
])
def test_score_file_or_layer_preamble(cli, ws, command, file_option, file_name, usage):
    """trajectory and map take either FILE --gt REFERENCE or --layer NAME: anything else is one line, exit 1."""
    path, ref = ws / file_name, ws / file_name.replace("dense", "sparse")
    for args in ([], [file_option, path], [file_option, path, "--gt", ref, "--layer", "dense"], ["--gt", ref]):
        result = cli("score", command, "-w", ws, *args)
        assert result.exit_code == 1 and usage in result.output, args
    assert not (ws / "results").exists()
    result = cli("score", command, "-w", ws, file_option, path, "--gt", ref)
    assert result.exit_code == 0, result.output
    assert (ws / "results" / f"{command}_d0.csv").exists()             # named after the file's stem
    again = cli("score", command, "-w", ws, file_option, path, "--gt", ref)
    assert again.exit_code == 1 and "--force" in again.output


def test_score_tables(cli, ws):
    result = cli("score", "tables", "-w", ws)
    assert result.exit_code == 0, result.output
    results = ws / "results"
    for name in ("table_5_1.md", "table_5_1.csv", "table_5_2.md", "table_5_2.csv", "trajectories_d0.png",
                 "trajectories_d1.png", "depth_examples.png"):
        assert (results / name).stat().st_size > 0, name
    t51 = {r["recipe"]: r for r in read_csv(results / "table_5_1.csv")}
    assert t51["MSE dense mask"]["run"] == "mse-dense" and t51["MSE dense mask"]["epoch"] == "1"
    assert float(t51["MSE dense mask"]["mse"]) == 1.0 and float(t51["MSE dense mask"]["chamfer"]) == 2.5
    assert t51["chamfer single-frame"]["run"].startswith("missing")
    t52 = {r["method"]: r for r in read_csv(results / "table_5_2.csv")}
    assert t52["MSE dense mask"]["layer"] == "mse-dense" and float(t52["MSE dense mask"]["localisation"]) > 0
    assert float(t52["dense depth"]["mae_mm"]) == 0.0
    assert float(t52["dense depth"]["localisation"]) == pytest.approx(0.0, abs=1e-6)
    assert t52["MSE dense mask + best filter"]["layer"] == "mse-dense+range"
    assert float(t52["MSE dense mask + best filter"]["localisation"]) < float(t52["MSE dense mask"]["localisation"])
    assert "dcslam predict" in t52["IP-Basic"]["missing"]
    assert float(t52["MSE dense mask"]["thesis_localisation"]) == 10.29    # the thesis's figure, thesis_tables.json
    assert "| MSE dense mask | mse-dense | 2 | 0 |" in (results / "table_5_2.md").read_text()
    # spread over the two drives: both drift the same, so std 0; failures counted beyond 1 m + rad
    assert t52["sparse depth"]["localisation_std"] == "0.0" and t52["MSE dense mask"]["failures"] == "0"
    assert float(t52["sparse depth"]["localisation_median"]) == pytest.approx(1.0)
    assert t52["MSE dense mask"]["vs_sparse"] == "differs"
    assert t52["dense depth"]["drives"] == "2" and "too short" in t52["dense depth"]["notes"]
    per_drive = read_csv(results / "table_5_2_per_drive.csv")
    assert {(r["layer"], r["drive"]) for r in per_drive} >= {("sparse", "d0"), ("sparse", "d1"), ("dense", "d1")}
    sparse_d0 = next(r for r in per_drive if r["layer"] == "sparse" and r["drive"] == "d0")
    assert float(sparse_d0["localisation"]) == pytest.approx(1.0)
    mse_d0 = next(r for r in per_drive if r["layer"] == "mse-dense" and r["drive"] == "d0")
    assert mse_d0["failed"] == "False" and float(mse_d0["localisation"]) == pytest.approx(0.5)
    assert "3 of 3 estimated poses paired" in sparse_d0["pairing"]
    assert "| testing | 540 | 1810 |" in (results / "table_5_3.md").read_text()   # the authors' figures
    assert "Table 5.3" in result.output
    # which depth metric predicts localisation: every row with SLAM runs on both drives is a pair per drive
    ranks = {r["key"]: r for r in read_csv(results / "table_5_2_correlation.csv")}
    assert ranks["mae_mm"]["pairs"] == str(2 * sum(1 for r in t52.values() if r["drives"] == "2"))
    assert -1 <= float(ranks["mae_mm"]["rho"]) <= 1 and ranks["mae_mm"]["ci_low"] <= ranks["mae_mm"]["ci_high"]
    assert "Table 5.2: depth metrics against localisation" in result.output
    again = cli("score", "tables", "-w", ws)
    assert again.exit_code == 1 and "--force" in again.output
    assert cli("score", "tables", "-w", ws, "--force").exit_code == 0


def _write_summary(ws, layer, drive, frames, rejected=()):
    record = {"stage": "slam", "settings": {"odometry": "icp", "mapper": "pointfusion", "frames": frames},
              "frames": frames, "rejected_steps": [{"frame": i, "reason": "test"} for i in rejected]}
    (ws / "slam" / layer / f"{drive}.json").write_text(json.dumps(record))
    commit_slam(ws / "slam" / layer, drive)


def test_tables_show_rows_made_with_other_settings_and_refuse_mixed_rows(cli, ws):
    for layer in ("sparse", "dense", "mse-dense", "mse-dense+range"):
        for drive in ("d0", "d1"):
            _write_summary(ws, layer, drive, 3, rejected=[2] if (layer, drive) == ("dense", "d1") else [])
    _write_summary(ws, "mse-dense", "d0", 5)
    _write_summary(ws, "mse-dense", "d1", 5)
    result = cli("score", "tables", "-w", ws)
    assert result.exit_code == 0, result.output
    t52 = {r["method"]: r for r in read_csv(ws / "results" / "table_5_2.csv")}
    assert t52["MSE dense mask"]["slam_settings"] == "differs: frames=5"
    assert t52["sparse depth"]["slam_settings"] == "as the others"
    assert t52["dense depth"]["failures"] == "1"             # a run that rejected a step is a failure
    _write_summary(ws, "mse-dense", "d1", 3)                 # one row, two settings: refused
    result = cli("score", "tables", "-w", ws, "--force")
    assert result.exit_code == 1 and "mixes SLAM runs made with frames=5 (d0) and frames=3 (d1)" in result.output


def test_tables_refuse_a_run_without_validation(cli, ws):
    write_run(ws, "broken", "chamfer", "dense", 8, [])
    result = cli("score", "tables", "-w", ws)
    assert result.exit_code == 1 and "no validation metrics" in result.output
    assert not (ws / "results").exists()


def test_tables_refuse_a_layer_with_wrong_frame_count(cli, ws):
    write_layer(ws / "predictions" / "mse-dense" / "d1.h5",
                Layer(depth=np.ones((N - 1, H, W), np.float32), drive="d1", made_by="mse-dense"), force=True)
    result = cli("score", "tables", "-w", ws)
    assert result.exit_code == 1 and "frames but its drive has" in result.output
    assert not (ws / "results").exists()


def test_tables_print_compactly_and_name_every_file_written(cli, ws):
    """The printed Table 5.2 holds its key columns within 100 characters a line; the Markdown file holds them all,
    and every file written is named."""
    result = cli("score", "tables", "-w", ws)
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    shown = [line for line in lines if not line.startswith("wrote ")]  # the one line naming the folder may be long
    assert max(len(line) for line in shown) <= 100, max(shown, key=len)
    start = next(i for i, line in enumerate(lines) if "Table 5.2" in line)
    header = " ".join(lines[start:start + 6])
    for name in ("method", "drives", "failed", "localisation", "vs sparse", "MAE", "ATE"):
        assert name in header, name
    assert "iRMSE" not in header and "SLAM settings" not in header
    assert "every column:" in result.stdout
    markdown = (ws / "results" / "table_5_2.md").read_text()
    assert "iRMSE (1/km)" in markdown and "SLAM settings" in markdown
    written = sorted(p for p in (ws / "results").iterdir())
    assert written and all(f"  {p.name}" in lines for p in written)
    assert f"wrote {len(written)} file(s) in {ws / 'results'}:" in result.stdout.replace("\n", "")


@pytest.fixture
def beams_ws(tmp_path):
    """A workspace whose drive files hold 64- and 16-beam sparse depth, with SLAM runs of both sparse inputs over
    the test drive (the other rows of the beams table left unmade)."""
    from dcslam.stages import slam
    from dcslam.workspace import Workspace
    from tests.fixtures.depth import write_workspace

    ws = Workspace(write_workspace(tmp_path / "ws", n=6, extra=True))
    for depth in ("sparse", "sparse@16"):
        slam.run(ws, slam.SlamStageConfig(odometry="gt", frames=2, depth=depth, drive=["drive_d"]))
    return ws.root


def test_score_tables_of_the_beams_experiment_rebuild_its_table(cli, beams_ws):
    """``score tables --table beams`` writes the beams tables from the SLAM runs there are, at the beam counts the
    drive files hold, or those the experiment's scoring stage last ran with; it overwrites them only with --force."""
    results = beams_ws / "results"
    result = cli("score", "tables", "--table", "beams", "-w", beams_ws)
    assert result.exit_code == 0, result.output
    for name in ("table_beams.md", "table_beams.csv", "table_beams_per_drive.csv", "table_beams.json"):
        assert (results / name).stat().st_size > 0, name
    assert "The beams experiment" in result.stdout and "table_beams.md" in result.stdout
    with open(results / "table_beams.csv") as f:
        rows = {(r["beams"], r["input"]): r for r in csv.DictReader(f)}
    assert {b for b, _ in rows} == {"64", "16", "any"}
    assert rows[("64", "sparse")]["localisation"] and rows[("16", "sparse")]["localisation"]
    assert not (results / "table_5_2.md").exists()
    assert json.loads((results / "table_beams.json").read_text())["settings"]["beams"] == [64, 16]

    again = cli("score", "tables", "--table", "beams", "-w", beams_ws)
    assert again.exit_code == 1 and "table_beams" in again.stderr
    stamp = beams_ws / ".reproduce" / "score-beams.json"
    stamp.parent.mkdir()
    stamp.write_text(json.dumps({"config": {"beams": [64], "drive": ["drive_d"]}, "complete": True}))
    again = cli("score", "tables", "--table", "beams", "-w", beams_ws, "--force")
    assert again.exit_code == 0, again.output
    with open(results / "table_beams.csv") as f:
        assert {r["beams"] for r in csv.DictReader(f)} == {"64", "any"}


def test_score_tables_refuses_an_unknown_experiment(cli, beams_ws):
    result = cli("score", "tables", "--table", "9.9", "-w", beams_ws)
    assert result.exit_code == 2 and "9.9" in result.stderr
