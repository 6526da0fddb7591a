"""SIGTERM (what ``kill``, a batch system or a container runtime sends to the process alone) stops a command as
Ctrl-C does: the one-line interrupted message saying what was kept and how to go on, nothing partial published,
exit 143; the rerun finishes."""
from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.fixtures.depth import write_workspace
from tests.fixtures.smoke import env

pytestmark = pytest.mark.slow  # each test runs a command into its work, then to its end: 19-26 s on a loaded machine

# Heavy modules are imported before "ready" is printed, so the signal falls in the command's own work.
LAUNCH = ("import sys, dcslam.cli, torch, h5py, numpy, scipy; sys.argv[0] = 'dcslam'; print('ready', flush=True); "
          "dcslam.cli.main()")


def _sigterm_when(args: list[str], ready: callable) -> subprocess.CompletedProcess:
    """Run ``dcslam args``; once ``ready()`` is true, SIGTERM the process (not its group); wait for its end."""
    proc = subprocess.Popen([sys.executable, "-c", LAUNCH, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env())
    assert proc.stdout.readline().strip() == "ready", proc.stderr.read()
    while not ready() and proc.poll() is None:
        time.sleep(0.02)
    assert proc.poll() is None, f"dcslam {' '.join(args)} ended before the signal: {proc.stderr.read()}"
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=120)
    return subprocess.CompletedProcess(args, proc.returncode, out, err)


def _leftovers(root: Path) -> list[Path]:
    return [p for p in root.rglob(".*") if ".tmp-" in p.name or ".set-" in p.name]


def test_sigterm_stops_slam_between_drives_and_keeps_no_partial_output(tmp_path):
    ws = write_workspace(tmp_path / "ws", n=40)
    drives = ["drive_a", "drive_b", "drive_c", "drive_d"]
    out = ws / "slam" / "dense"
    args = ["slam", "--depth", "dense", "--odometry", "icp", "--iterations", "3", "-w", str(ws),
            *(arg for d in drives for arg in ("--drive", d))]
    done = _sigterm_when(args, ready=lambda: (out / "drive_a.done").exists())
    assert done.returncode == 143, done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("interrupted: the SLAM outputs of drive_a") and f"are kept, complete, in {out}" in last
    assert last.endswith("rerun with --drive naming the others, or the same command with --force")
    assert "Traceback" not in done.stderr and "Exception ignored" not in done.stderr, done.stderr
    assert not (out / "drive_d.json").exists() and _leftovers(ws) == []  # the last drive was never published
    kept = {d: (out / f"{d}.json").read_bytes() for d in drives if (out / f"{d}.json").exists()}
    assert "drive_a" in kept and all(d in last for d in kept)
    others = [*args[:args.index("--drive")], *(arg for d in drives if d not in kept for arg in ("--drive", d))]
    again = subprocess.run([sys.executable, "-m", "dcslam", *others], capture_output=True, text=True, env=env(),
                           timeout=600)  # the message's first advice: the drives not done
    assert again.returncode == 0, again.stderr
    assert all((out / f"{d}.json").exists() for d in drives)
    assert all((out / f"{d}.json").read_bytes() == made for d, made in kept.items())  # the kept ones untouched


def test_sigterm_stops_training_which_then_resumes(tmp_path):
    ws = write_workspace(tmp_path / "ws", n=6)
    run = ws / "runs" / "long"
    args = ["train", "--loss", "mse", "--epochs", "500", "--name", "long", "-w", str(ws)]
    done = _sigterm_when(args, ready=lambda: (run / "last.pt").exists())
    assert done.returncode == 143, done.stderr
    assert done.stderr.strip().splitlines()[-1] == (
        f"interrupted: the run folder {run} is kept with last.pt (the last saved point of the training); continue "
        "it with the same command and --resume, or start again with --force")
    assert "Traceback" not in done.stderr, done.stderr
    assert _leftovers(ws) == []
    again = subprocess.run([sys.executable, "-m", "dcslam", "train", "--resume", "--epochs", "2", "--name", "long",
                            "--loss", "mse", "-w", str(ws)], capture_output=True, text=True, env=env(), timeout=600)
    assert again.returncode == 0, again.stderr
    assert (run / "model.pt").exists()
