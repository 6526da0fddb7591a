import csv
import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from dcslam.cli import app
from dcslam.io.drive import DriveFrame, DriveWriter, Layer, write_layer
from dcslam.io.tum import write_tum

K = np.array([[20.0, 0, 12], [0, 20.0, 8], [0, 0, 1]])
H, W, N = 16, 24, 4
runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


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
    (root / "filtered" / "mse-dense+range" / "config.json").write_text(
        json.dumps({"stage": "filter", "settings": {"source_layer": "mse-dense"}}))
    return root


def read_csv(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def test_score_depth(ws):
    result = invoke("score", "depth", "-w", ws, "--layer", "dense")
    assert result.exit_code == 0, result.output
    rows = read_csv(ws / "results" / "depth_dense.csv")
    assert [r["drive"] for r in rows] == ["d0", "d1", "all"]
    assert float(rows[-1]["mae_mm"]) == 0.0 and rows[-1]["frames"] == str(2 * N)
    result = invoke("score", "depth", "-w", ws, "--layer", "mse-dense", "--drive", "d1", "--out", ws / "x.csv")
    assert result.exit_code == 0 and float(read_csv(ws / "x.csv")[0]["mae_mm"]) > 1000
    again = invoke("score", "depth", "-w", ws, "--layer", "dense")
    assert again.exit_code == 1 and "--force" in again.output


def test_score_trajectory_layer_and_files(ws):
    result = invoke("score", "trajectory", "-w", ws, "--layer", "sparse")
    assert result.exit_code == 0, result.output
    rows = read_csv(ws / "results" / "trajectory_sparse.csv")
    assert [r["trajectory"] for r in rows] == ["d0", "d1"] and rows[0]["poses"] == "3"
    # x drifts by 0, 1, 2 m: unaligned ATE errors 0, 1, 2 → rmse sqrt(5/3); RPE translation 1 m every step
    assert float(rows[0]["ate_rmse"]) == pytest.approx(np.sqrt(5 / 3), rel=1e-6)
    assert float(rows[0]["rpe_trans_m_rmse"]) == pytest.approx(1.0, rel=1e-6)
    assert float(rows[0]["localisation"]) == pytest.approx(1.0, rel=1e-6)
    est, ref = ws / "slam" / "dense" / "d0.txt", ws / "slam" / "sparse" / "d0.txt"
    result = invoke("score", "trajectory", "-w", ws, "--est", est, "--gt", ref, "--out", ws / "t.csv")
    assert result.exit_code == 0 and float(read_csv(ws / "t.csv")[0]["ate_rmse"]) == pytest.approx(np.sqrt(5 / 3))


def test_score_trajectory_bad_input(ws, tmp_path):
    short = tmp_path / "short.txt"
    write_tum(short, 10 + 0.1 * np.arange(2), gt_poses(2))
    result = invoke("score", "trajectory", "-w", ws, "--est", short, "--gt", ws / "slam" / "dense" / "d0.txt")
    assert result.exit_code == 1 and "different lengths" in result.output
    unsorted = tmp_path / "unsorted.txt"
    unsorted.write_text("10.2 0 0 0 0 0 0 1\n10.1 0 0 0 0 0 0 1\n")
    result = invoke("score", "trajectory", "-w", ws, "--est", unsorted, "--gt", ws / "drives" / "d0.h5")
    assert result.exit_code == 1 and "not strictly increasing" in result.output
    assert not (ws / "results").exists()
    assert invoke("score", "trajectory", "-w", ws).exit_code == 1


def test_score_map(ws):
    result = invoke("score", "map", "-w", ws, "--layer", "sparse")
    assert result.exit_code == 0, result.output
    rows = read_csv(ws / "results" / "map_sparse.csv")
    # map point (0, 0, 1) vs ground truth (0, 0, 0): nearest 1 m away both ways → (1/3 + 1/3) m²
    assert float(rows[0]["chamfer_m2"]) == pytest.approx(2 / 3, rel=1e-6)


@pytest.mark.parametrize("command, file_option, file_name, usage", [
    ("trajectory", "--est", "slam/dense/d0.txt", "give either --est X.txt --gt REFERENCE, or --layer NAME"),
    ("map", "--map", "slam/dense/d0.ply", "give either --map X.ply --gt Y.ply, or --layer NAME"),
])
def test_score_file_or_layer_preamble(ws, command, file_option, file_name, usage):
    """trajectory and map take either FILE --gt REFERENCE or --layer NAME: anything else is one line, exit 1."""
    path, ref = ws / file_name, ws / file_name.replace("dense", "sparse")
    for args in ([], [file_option, path], [file_option, path, "--gt", ref, "--layer", "dense"], ["--gt", ref]):
        result = invoke("score", command, "-w", ws, *args)
        assert result.exit_code == 1 and usage in result.output, args
    assert not (ws / "results").exists()
    result = invoke("score", command, "-w", ws, file_option, path, "--gt", ref)
    assert result.exit_code == 0, result.output
    assert (ws / "results" / f"{command}_d0.csv").exists()             # named after the file's stem
    again = invoke("score", command, "-w", ws, file_option, path, "--gt", ref)
    assert again.exit_code == 1 and "--force" in again.output


def test_score_tables(ws):
    result = invoke("score", "tables", "-w", ws)
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
    assert "| MSE dense mask | mse-dense |" in (results / "table_5_2.md").read_text()
    again = invoke("score", "tables", "-w", ws)
    assert again.exit_code == 1 and "--force" in again.output
    assert invoke("score", "tables", "-w", ws, "--force").exit_code == 0


def test_tables_refuse_a_run_without_validation(ws):
    write_run(ws, "broken", "chamfer", "dense", 8, [])
    result = invoke("score", "tables", "-w", ws)
    assert result.exit_code == 1 and "no validation metrics" in result.output
    assert not (ws / "results").exists()


def test_tables_refuse_a_layer_with_wrong_frame_count(ws):
    write_layer(ws / "predictions" / "mse-dense" / "d1.h5",
                Layer(depth=np.ones((N - 1, H, W), np.float32), drive="d1", made_by="mse-dense"), force=True)
    result = invoke("score", "tables", "-w", ws)
    assert result.exit_code == 1 and "frames but its drive has" in result.output
    assert not (ws / "results").exists()
