"""One writer at a time in the stages: a second process holding an output's lock makes train, slam, predict and
reproduce refuse in one line naming it, before anything of the output is removed or written."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

from dcslam.errors import DcslamError
from dcslam.locks import lock_path

HOLD = """
import sys, time
from dcslam.locks import output_lock
with output_lock(sys.argv[1], sys.argv[2]):
    print("held", flush=True)
    sys.stdin.readline()
"""


@pytest.fixture
def hold():
    """``hold(path, what)``: another process holds ``path``'s lock until the test ends; returns its PID."""
    holders = []

    def start(path: Path, what: str) -> int:
        env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
        process = subprocess.Popen([sys.executable, "-c", HOLD, str(path), what], stdin=subprocess.PIPE,
                                   stdout=subprocess.PIPE, text=True, env=env)
        holders.append(process)
        assert process.stdout.readline().strip() == "held"
        return process.pid

    yield start
    for process in holders:
        process.stdin.close()
        process.wait(timeout=30)


def test_train_force_never_deletes_a_run_another_process_is_writing(ws, hold, cli):
    run_dir = ws.runs / "mse-dense"
    run_dir.mkdir(parents=True)
    (run_dir / "last.pt").write_bytes(b"the other process's checkpoint")
    pid = hold(run_dir, "run")
    result = cli("train", "-w", ws.root, "--max-frames", 2, "--scale", 0.5, "--device", "cpu", "--force")
    assert result.exit_code == 1 and result.output.count("\n") == 1
    assert f"error: run {run_dir} is being written by PID {pid} (" in result.output
    assert "wait for it or stop it" in result.output
    assert (run_dir / "last.pt").read_bytes() == b"the other process's checkpoint"


def test_slam_refuses_a_drive_another_process_is_writing(ws, hold, cli):
    out = ws.slam / "dense"
    pid = hold(out / "drive_d", "SLAM output")
    result = cli("slam", "-w", ws.root, "--odometry", "gt", "--frames", 2, "--force")
    assert result.exit_code == 1 and f"SLAM output {out / 'drive_d'} is being written by PID {pid}" in result.output
    assert [p.name for p in out.iterdir()] == [".drive_d.lock"]  # the holder's lock file, nothing written


def test_slam_writes_one_drive_of_a_layer_while_another_process_writes_another(ws, hold, cli):
    """The SLAM stages of one layer's drives run side by side (reproduce --jobs 2, a Slurm array): each holds only
    its own drive's outputs."""
    out = ws.slam / "dense"
    hold(out / "drive_c", "SLAM output")
    result = cli("slam", "-w", ws.root, "--odometry", "gt", "--frames", 2, "--drive", "drive_d")
    assert result.exit_code == 0, result.output
    assert (out / "drive_d.done").exists() and not (out / "drive_c.json").exists()
    refused = cli("slam", "-w", ws.root, "--odometry", "gt", "--frames", 2, "--drive", "drive_c", "--force")
    assert refused.exit_code == 1 and f"SLAM output {out / 'drive_c'} is being written by PID" in refused.output


def test_predict_refuses_a_layer_another_process_is_writing(ws, hold):
    from dcslam.stages.predict import PredictConfig, run

    pid = hold(ws.predictions / "ip-basic-fast", "layer")
    with pytest.raises(DcslamError, match=f"layer .*ip-basic-fast is being written by PID {pid}"):
        run(ws, PredictConfig(model="ip-basic", device="cpu"))


def test_a_second_reproduce_of_one_workspace_is_refused_before_it_touches_the_workspace(tmp_path, hold):
    from dcslam.stages.experiments.table_5_2 import PROFILES
    from dcslam.stages.reproduce import reproduce
    from dcslam.workspace import Workspace

    ws = Workspace(tmp_path / "ws")
    pid = hold(ws.root, "workspace")
    with pytest.raises(DcslamError, match=f"workspace {ws.root} is being written by PID {pid}"):
        reproduce(ws, PROFILES["smoke"])
    assert not ws.root.exists() and lock_path(ws.root).parent == tmp_path


def test_the_lock_is_released_when_the_stage_ends(ws):
    from dcslam.stages.slam import SlamStageConfig, run

    run(ws, SlamStageConfig(odometry="gt", frames=2, evidence="none"))
    assert not lock_path(ws.slam / "dense").exists()
    assert {p.name for p in ws.slam.iterdir()} == {"dense"}


def test_the_slam_stages_of_one_layer_run_side_by_side_in_worker_processes(ws):
    """reproduce --jobs 2 hands each (layer, drive) SLAM stage to a worker: two drives of one layer, at once, both
    written (a lock on the whole layer folder refused the second)."""
    from dcslam.stages import slam
    from dcslam.stages.pipeline import Pipeline, Stage

    out = ws.slam / "dense"
    stages = [Stage(f"slam-dense-{drive}", slam.run, slam.SlamStageConfig(drive=[drive], odometry="gt"),
                    outputs=lambda d=drive: [out / f"{d}.done"], kind="slam") for drive in ("drive_c", "drive_d")]
    Pipeline(ws).run_all(stages, jobs=2)
    assert (out / "drive_c.done").exists() and (out / "drive_d.done").exists()
