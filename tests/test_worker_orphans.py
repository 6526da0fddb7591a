"""Workers end with their parent: SIGKILL of a process whose pool is busy leaves no worker (nor multiprocessing's
resource tracker) behind."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]
PARENT = textwrap.dedent("""
    import os, sys, time
    from pathlib import Path
    from dcslam.workers import process_pool

    def task(folder):
        (Path(folder) / str(os.getpid())).write_text("")
        time.sleep(120)

    if __name__ == "__main__":
        folder = Path(sys.argv[1])
        pool = process_pool(2, 2)
        futures = [pool.submit(task, str(folder)) for _ in range(2)]
        while len(list(folder.iterdir())) < 2:
            time.sleep(0.05)
        print("busy", flush=True)
        time.sleep(120)
""")


def _children(pid: int) -> list[int]:
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rpartition(")")[2].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


def _running(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.faults
@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads the process table from /proc")
def test_busy_workers_end_when_their_parent_is_killed(tmp_path):
    script = tmp_path / "parent.py"
    script.write_text(PARENT)
    folder = tmp_path / "pids"
    folder.mkdir()
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    parent = subprocess.Popen([sys.executable, str(script), str(folder)], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True, env=env)
    try:
        assert parent.stdout.readline().strip() == "busy", parent.stderr.read()
        workers = [int(p.name) for p in folder.iterdir()]
        children = _children(parent.pid)  # the workers and the resource tracker
        assert set(workers) <= set(children) and all(_running(pid) for pid in children)
        parent.send_signal(signal.SIGKILL)
        parent.wait()
        deadline = time.monotonic() + 10
        while any(_running(pid) for pid in children) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert [pid for pid in children if _running(pid)] == []
    finally:
        for pid in _children(parent.pid) if parent.poll() is None else []:
            os.kill(pid, signal.SIGKILL)
        if parent.poll() is None:
            parent.kill()
            parent.wait()
