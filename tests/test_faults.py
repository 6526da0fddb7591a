"""Fault test: Ctrl-C (SIGINT to the process group, as a terminal sends it) at seeded random moments of
prepare-kitti, train, predict, slam and reproduce on tiny drives (one moment each, drawn from the seconds the
uninterrupted run spent in that stage), then the rerun docs/usage.md prescribes; the final outputs must equal those of
an uninterrupted run, and no temporary file may be left.

Deselect with ``-m "not faults"``. About a minute on a quiet 2-core machine.
"""
from __future__ import annotations

import json
import os
import random
import shutil
import signal
import subprocess
from pathlib import Path

import h5py
import numpy as np
import pytest

from dcslam.stages.experiments.table_5_2 import PROFILES
from tests.fixtures.smoke import dcslam, start

pytestmark = [pytest.mark.faults, pytest.mark.slow]  # a whole reproduction, then one per stage

SMOKE = PROFILES["smoke"]
SEED = 16  # the moments of interruption follow from it: a failure is reproducible
STAGES = {  # each stage as `reproduce --profile smoke` runs it, so that its outputs are the uninterrupted ones
    "prepare-kitti": ["prepare-kitti", "--kitti", "{kitti}"],
    "train": ["train", "--loss", "mse", "--mask", "dense", "--epochs", "1", "--max-frames", "2", "--scale", "0.25",
              "--name", "mse-dense"],
    "predict": ["predict", "--run", "mse-dense"],
    "slam": ["slam", "--depth", "dense", "--odometry", "icp", "--frames", str(SMOKE.slam_frames),
             *(arg for key, value in SMOKE.slam.items() for arg in (f"--{key.replace('_', '-')}", str(value)))],
}


def interrupt(args, after_s: float) -> bool:
    """Run ``args``, SIGINT its process group ``after_s`` seconds into its work; True if it was interrupted.

    A Ctrl-C that lands once the command has written everything (while Python shuts down) changes nothing: exit 0.
    """
    proc, _ = start([str(a) for a in args])
    try:
        proc.wait(timeout=after_s)
        return False  # it finished first
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    assert "Traceback" not in err and "Exception ignored" not in err, err
    if proc.returncode == 0:
        assert out.strip(), (out, err)  # its work was done and summarised (stderr may hold its progress log)
        return False
    assert proc.returncode == 130, (proc.returncode, err)
    last = err.strip().splitlines()[-1]  # what was kept and how to go on, in one line
    assert last == "interrupted: no partial output was kept; rerun the command to finish" or (
        last.startswith("interrupted: the ") and " kept" in last and ("rerun" in last or "--resume" in last)), last
    return True


def leftovers(root: Path) -> list[Path]:
    return [p for p in root.rglob(".*") if ".tmp-" in p.name or ".set-" in p.name]


def same_h5(a: Path, b: Path) -> None:
    with h5py.File(a, "r") as fa, h5py.File(b, "r") as fb:
        names = []
        fa.visit(names.append)
        for name in names:
            if isinstance(fa[name], h5py.Dataset):
                np.testing.assert_allclose(fa[name][()], fb[name][()], rtol=1e-6, atol=1e-6, err_msg=f"{a}:{name}")


def same_outputs(stage: str, got: Path, want: Path) -> None:
    if stage == "prepare-kitti":
        assert json.loads((got / "drives" / "splits.json").read_text()) == \
            json.loads((want / "drives" / "splits.json").read_text())
        for path in sorted((want / "drives").glob("*.h5")):
            same_h5(got / "drives" / path.name, path)
    elif stage == "train":
        import torch

        a = torch.load(got / "runs" / "mse-dense" / "model.pt", weights_only=True)["state_dict"]
        b = torch.load(want / "runs" / "mse-dense" / "model.pt", weights_only=True)["state_dict"]
        assert a.keys() == b.keys() and all(torch.allclose(a[k], b[k], atol=1e-6) for k in a)
    elif stage == "predict":
        for path in sorted((want / "predictions" / "mse-dense").glob("*.h5")):
            same_h5(got / "predictions" / "mse-dense" / path.name, path)
    elif stage == "slam":
        for path in sorted((want / "slam" / "dense").glob("*.txt")):
            np.testing.assert_allclose(np.loadtxt(got / "slam" / "dense" / path.name), np.loadtxt(path), atol=1e-6)


def rerun_args(stage: str, ws: Path) -> list[str]:
    """The rerun docs/usage.md gives for an interrupted stage."""
    if stage == "train":
        run = ws / "runs" / "mse-dense"
        return ["--resume"] if (run / "last.pt").exists() else ["--force"] if run.exists() else []
    if stage == "slam":
        return ["--force"]  # each drive's outputs are written atomically; a finished drive is redone
    return []  # prepare-kitti and predict write their files together: an interrupted run left none


@pytest.fixture(scope="module")
def baseline(tiny_smoke, tmp_path_factory):
    """The session's uninterrupted ``reproduce --profile smoke`` on tiny drives (``tiny_smoke``, shared with the Slurm
    test): its workspace holds the uninterrupted output of every stage, and its stamps the seconds each stage worked.
    Each test works in a folder of its own."""
    root = tmp_path_factory.mktemp("faults")
    straight = tiny_smoke.workspace
    stamps = {stage: f"{stage}-mse-dense" if stage in ("train", "predict") else stage for stage in STAGES}
    stamps["slam"] = "slam-dense-*"  # reproduce runs SLAM as one stage per (layer, test drive)
    work = {stage: sum(json.loads(path.read_text())["seconds"]
                       for path in (straight / ".reproduce").glob(f"{stamp}.json"))
            for stage, stamp in stamps.items()}
    assert all(work.values()), work
    return root, tiny_smoke.kitti, straight, {**work, "reproduce": tiny_smoke.seconds}, tiny_smoke.table


@pytest.mark.parametrize("stage", list(STAGES))
def test_interrupted_stage_then_rerun_equals_the_uninterrupted_run(baseline, stage):
    root, kitti, straight, seconds, _ = baseline
    rng = random.Random(f"{SEED}-{stage}")
    ws = root / stage
    for earlier in ("drives", "runs", "predictions")[:list(STAGES).index(stage)]:  # inputs: the uninterrupted ones
        shutil.copytree(straight / earlier, ws / earlier)
    args = [a.format(kitti=kitti) for a in STAGES[stage]] + ["-w", str(ws)]
    if interrupt(args, after_s=rng.uniform(0.0, 1.0) * seconds[stage]):
        assert leftovers(ws) == []
        dcslam(*args, *rerun_args(stage, ws))
    same_outputs(stage, ws, straight)
    assert leftovers(ws) == []


def test_interrupted_reproduce_then_rerun_gives_the_same_table(baseline):
    root, kitti, straight, seconds, table = baseline
    ws = root / "reproduce"
    rng = random.Random(f"{SEED}-reproduce")
    args = ["reproduce", "--profile", "smoke", "--kitti", str(kitti), "-w", str(ws)]
    fraction = rng.uniform(0.1, 0.8)
    # On a loaded machine the rerun can be faster than the baseline and finish before the Ctrl-C: interrupt earlier.
    while not interrupt(args, after_s=fraction * seconds["reproduce"]):
        assert fraction > 0.01, "reproduce always finished before the interrupt"
        shutil.rmtree(ws)
        fraction /= 4
    assert leftovers(ws) == []
    again, _ = dcslam(*args)
    # the same table; the paths it names are each run's own workspace
    assert again.replace(str(ws), "<workspace>") == table.replace(str(straight), "<workspace>")
    assert (ws / "results" / "table_5_2.csv").read_text() == (straight / "results" / "table_5_2.csv").read_text()
