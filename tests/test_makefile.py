"""The Makefile's reproduce targets pass their variables on to `dcslam reproduce` (checked with `make -n`, which
prints the commands and runs none)."""
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]


def _reproduce_line(*variables: str) -> str:
    done = subprocess.run(["make", "-n", "-C", str(ROOT), "reproduce-beams", *variables], capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    lines = [line for line in done.stdout.splitlines() if "dcslam reproduce" in line]
    assert len(lines) == 1, done.stdout
    return lines[0]


@pytest.mark.skipif(shutil.which("make") is None, reason="no make on this machine")
def test_seeds_jobs_profile_and_workspace_reach_dcslam_reproduce(tmp_path):
    line = _reproduce_line("SEEDS=2", "JOBS=3", "PROFILE=smoke", f"WORKSPACE={tmp_path}")
    assert "--table beams" in line and "--seeds 2" in line and "--jobs 3" in line and "--profile smoke" in line
    assert f"--workspace {tmp_path}" in line
    assert "--seeds" not in _reproduce_line(f"WORKSPACE={tmp_path}")  # the profile's own seeds by default
