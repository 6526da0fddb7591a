"""The front door (`import dcslam`): its public names pinned, the README's example run as written, and each call
against the library piece it wraps."""
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import dcslam
from dcslam.errors import DcslamError
from tests.fixtures.street import write_analytic_street, write_generated_drive

README = Path(__file__).parents[1] / "README.md"
PUBLIC = ["SlamSettings", "TrainedRun", "TrajectoryScores", "__version__", "complete", "complete_drive",
          "load_completer", "load_run", "run_slam", "score_trajectory", "slam_arrays"]


def test_public_names_are_pinned():
    # a name added or dropped here is a change of the library's surface: the README and the CHANGELOG say so too
    assert sorted(dcslam.__all__) == sorted(PUBLIC)
    for name in PUBLIC:
        assert getattr(dcslam, name) is not None
    assert set(PUBLIC) <= set(dir(dcslam))
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        dcslam.nothing


def test_import_dcslam_loads_no_numpy_or_torch():
    # the command line imports the package first: `dcslam --help` must not pay for NumPy, torch or Open3D
    code = ("import sys, dcslam; "
            "print(sorted(m for m in ('numpy', 'torch', 'open3d', 'dcslam.api') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def readme_example() -> str:
    text = README.read_text(encoding="utf-8")
    match = re.search(r"<!-- example: front door -->\n```python\n(.*?)```", text, re.S)
    assert match, "README.md lost its front-door example"
    return match.group(1)


@pytest.mark.slow
def test_readme_example_runs_as_written(tmp_path, monkeypatch, capsys):
    drives = tmp_path / "workspace" / "drives"
    drives.mkdir(parents=True)
    write_generated_drive(drives / "2011_09_26_drive_0001_sync.h5", seed=3, frames=8, scale=0.4)
    monkeypatch.chdir(tmp_path)
    exec(compile(readme_example(), "README.md", "exec"), {})
    lines = capsys.readouterr().out.splitlines()
    assert [line.split(":")[0] for line in lines] == ["sparse", "workspace/predictions/planefit/"
                                                      "2011_09_26_drive_0001_sync.h5"]
    for line in lines:
        value = float(re.search(r"localisation ([0-9.]+)", line).group(1))
        assert np.isfinite(value) and value < 1.0  # eight frames of a street: SLAM tracks, whatever the depth
    assert (tmp_path / "workspace" / "predictions" / "planefit" / "2011_09_26_drive_0001_sync.h5").exists()


def test_complete_is_the_registered_completer():
    from dcslam.depth.models.scanline import complete_scanline

    rng = np.random.default_rng(0)
    sparse = np.where(rng.random((40, 60)) < 0.1, rng.uniform(5, 20, (40, 60)), 0).astype(np.float32)
    np.testing.assert_array_equal(dcslam.complete(sparse, "scanline"), complete_scanline(sparse))
    assert dcslam.complete(sparse).shape == sparse.shape and (dcslam.complete(sparse) > 0).mean() > 0.9
    with pytest.raises(DcslamError, match="neither a registered completer nor a training run"):
        dcslam.complete(sparse, "no-such-completer")


def test_load_run_reads_a_trained_run(tmp_path):
    import json

    import torch

    from dcslam.depth.models import build_model, save_model

    torch.manual_seed(0)
    run = tmp_path / "runs" / "r"
    save_model(run / "model.pt", build_model("sparse-conv", channels=4), meta={"scale": 1.0, "epoch": 0, "step": 1})
    (run / "config.json").write_text(json.dumps({"settings": {"loss": "mse"}}))
    (run / "metrics.jsonl").write_text('{"kind": "train", "step": 0, "loss": 2.0}\n')
    trained = dcslam.load_run(run)
    assert trained.name == "r" and trained.settings == {"loss": "mse"} and trained.metrics[0]["loss"] == 2.0
    sparse = np.zeros((16, 24), np.float32)
    sparse[::4, ::3] = 7.0
    np.testing.assert_array_equal(trained.complete(sparse), dcslam.complete(sparse, run))
    with pytest.raises(DcslamError, match="no model.pt"):
        dcslam.load_run(tmp_path)


def test_run_slam_and_slam_arrays_agree_on_a_drive(tmp_path):
    import torch

    from dcslam.io.drive import DriveFile

    path = tmp_path / "street.h5"
    write_analytic_street(path, frames=5, H=60, W=200)
    run = dcslam.run_slam(path, depth="dense")
    with DriveFile(path) as drive:
        depth = np.stack([drive.depth("dense", i) for i in range(len(drive.frame_ids))])
        K, T0 = drive.K, drive.poses[0]
    with torch.no_grad():
        poses = dcslam.slam_arrays(depth, K, T0)
    assert poses.shape == run.T_world_cam.shape == (5, 4, 4)
    np.testing.assert_allclose(poses, run.T_world_cam, atol=1e-5)
    assert dcslam.score_trajectory(run.T_gt, run.T_world_cam).localisation < 0.05
    with pytest.raises(DcslamError, match="expected \\(N, H, W\\)"):
        dcslam.slam_arrays(depth[0], K)
    with pytest.raises(DcslamError, match="ground-truth poses"):
        dcslam.slam_arrays(depth, K, settings=dcslam.SlamSettings(odometry="gt"))
