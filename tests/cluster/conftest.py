"""The tests marked ``cluster`` run on a single-node Slurm cluster that ``slurm.sh start`` brings up on this machine
(installing slurm-wlm and munge when missing, as root). Where it cannot start, the tests fail with the reason under
CI (``CI=true``) and are skipped with the reason elsewhere: never a silent pass."""
from __future__ import annotations

import importlib.util
import subprocess
from pathlib import Path

import pytest

from tests.cluster.unavailable import unavailable

SCRIPT = Path(__file__).with_name("slurm.sh")


@pytest.fixture(scope="session")
def slurm_cluster() -> Path:
    """A running single-node Slurm (started here unless it already ran, stopped at the end if started here);
    yields the path of slurmctld's log, the only record of the jobs (the cluster keeps no accounting)."""
    if importlib.util.find_spec("submitit") is None:
        unavailable("submitit is not installed (pip install -e '.[test]')")
    try:
        done = subprocess.run(["bash", str(SCRIPT), "start"], capture_output=True, text=True, timeout=900)
    except subprocess.TimeoutExpired:
        unavailable(f"{SCRIPT} start did not finish within 15 minutes")
    if done.returncode != 0:
        lines = done.stderr.strip().splitlines()
        unavailable(lines[-1] if lines else f"{SCRIPT} start exited {done.returncode}")
    started_here = "already up" not in done.stderr
    log = subprocess.run(["bash", str(SCRIPT), "log"], capture_output=True, text=True, check=True).stdout.strip()
    yield Path(log)
    if started_here:
        subprocess.run(["bash", str(SCRIPT), "stop"], capture_output=True, timeout=120)
