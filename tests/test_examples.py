"""The scripts in examples/, each run as a user runs it (a child process with this Python) on tiny data.

Sizes: 2 generated drives of 12 frames (1 train, 1 test; 2 frames with depth each), 1 epoch on 2 frames at quarter
scale, SLAM on 2 frames with 1 ICP iteration per gate stage, each kind of filter once in two chains (the default
list of the filters example, presets included, is only parsed). The numbers mean nothing; exit codes and files do.
"""
import csv
import importlib.util
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).parents[1] / "examples"
SAMPLE = Path(__file__).parent / "data" / "kitti-sample"
TINY_SLAM = ["--slam-frames", "2", "--icp-iterations", "1"]
TEST_DRIVE = "2011_09_26_drive_1001_sync"  # of 2 generated drives, the proportional split tests the second


def run_example(script: str, *args) -> subprocess.CompletedProcess:
    env = {**os.environ, "DCSLAM_PROGRESS": "0"}
    return subprocess.run([sys.executable, str(EXAMPLES / script), *map(str, args)], capture_output=True, text=True,
                          env=env, timeout=600)


def read_csv(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def generated(tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess]:
    """A workspace made by generated_end_to_end.py (shared: the filters example reuses its drive files)."""
    ws = tmp_path_factory.mktemp("generated") / "ws"
    result = run_example("generated_end_to_end.py", "--workspace", ws, "--drives", 2, "--frames", 12, "--epochs", 1,
                         "--max-frames", 2, "--scale", 0.25, *TINY_SLAM)
    return ws, result


@pytest.mark.slow  # synth, prepare, train, predict, SLAM and scores in a child process
def test_generated_end_to_end(generated):
    ws, result = generated
    assert result.returncode == 0, result.stderr[-3000:]
    assert (ws / "runs" / "mse-dense" / "model.pt").is_file()
    assert (ws / "predictions" / "mse-dense" / f"{TEST_DRIVE}.h5").is_file()
    for layer in ("sparse", "dense", "mse-dense"):
        for ext in ("txt", "ply", "json"):
            assert (ws / "slam" / layer / f"{TEST_DRIVE}.{ext}").stat().st_size > 0
        assert read_csv(ws / "results" / f"trajectory_{layer}.csv")[0]["poses"] == "2"
        assert read_csv(ws / "results" / f"depth_{layer}.csv")[-1]["frames"] == "2"
    table = result.stdout[result.stdout.index("depth source"):].splitlines()
    assert [line.split()[0] for line in table[1:4]] == ["sparse", "dense", "mse-dense"]
    assert all(len(line.split()) == 6 for line in table[1:4])  # MAE, RMSE, iRMSE, localisation, ATE

    again = run_example("generated_end_to_end.py", "--workspace", ws, "--drives", 2, "--frames", 12)
    assert again.returncode == 1 and "pass --force" in again.stderr  # nothing is overwritten without --force
    assert again.stderr.strip().splitlines()[-1].startswith("stopped: `dcslam synth")


def test_real_kitti_one_frame_sample_gives_depth_scores_only(tmp_path):
    result = run_example("real_kitti.py", "--kitti", SAMPLE, "--workspace", tmp_path / "ws")
    assert result.returncode == 0, result.stderr[-3000:]
    assert "no SLAM" in result.stdout
    rows = read_csv(tmp_path / "ws" / "results" / "kitti_frames_ip-basic-fast.csv")
    assert [r["frame"] for r in rows] == ["2011_09_26_drive_0001_sync/0000000005", "mean"]
    assert 200 < float(rows[0]["mae_mm"]) < 400  # IP-Basic (fast) on this frame: 281.9 mm
    assert not (tmp_path / "ws" / "drives").exists()
    again = run_example("real_kitti.py", "--kitti", SAMPLE, "--workspace", tmp_path / "ws")
    assert again.returncode == 1 and "pass --force" in again.stderr


def test_default_filters_of_the_filters_example_parse():
    spec = importlib.util.spec_from_file_location("filters_through_slam", EXAMPLES / "filters_through_slam.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    names = [module.chain_of(s).name for s in module.FILTERS]
    assert names == ["range", "bilateral", "outlier", "hidden", "edges", "range", "bilateral"]  # presets last
    assert module.chain_of("thesis-range+edges").name == "range+edges"


@pytest.mark.slow  # each filter, then SLAM on each, in a child process
def test_filters_through_slam(generated, tmp_path):
    ws = tmp_path / "ws"
    shutil.copytree(generated[0] / "drives", ws / "drives")
    filters = ["range:min=1,max=60+bilateral:sigma_color=2+outlier+hidden", "edges"]  # each kind of filter once
    result = run_example("filters_through_slam.py", "--workspace", ws, "--frames", 2, "--icp-iterations", 1,
                         *(arg for spec in filters for arg in ("--filter", spec)))
    assert result.returncode == 0, result.stderr[-3000:]
    rows = read_csv(ws / "results" / "filters_ip-basic-fast.csv")
    assert [r["filter"] for r in rows] == ["(none)", *filters]
    assert all(float(r["localisation"]) >= 0 and float(r["mae_mm"]) >= 0 for r in rows)
    assert (ws / "results" / "filters_ip-basic-fast.md").read_text() in result.stdout
    for layer in ("ip-basic-fast", "ip-basic-fast+range-min1-max60+bilateral-sigma_color2+outlier+hidden",
                  "ip-basic-fast+edges"):
        assert (ws / "slam" / layer / f"{TEST_DRIVE}.txt").is_file()
    assert (ws / "filtered" / "ip-basic-fast+edges" / f"{TEST_DRIVE}.h5").is_file()

    bad = run_example("filters_through_slam.py", "--workspace", ws, "--filter", "edges+median")
    assert bad.returncode == 1 and bad.stderr.strip().startswith("error: unknown filter 'median'")
    again = run_example("filters_through_slam.py", "--workspace", ws, "--filter", "edges")
    assert again.returncode == 1 and "pass --force" in again.stderr
