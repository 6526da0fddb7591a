"""One writer at a time (dcslam/locks.py): a second process is refused naming the holder's PID and command, the lock
is released on every exit path, and a lock left by a dead process is taken over with a note."""
from __future__ import annotations

import errno
import json
import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from dcslam.errors import DcslamError
from dcslam.locks import holder, lock_path, output_lock

ROOT = Path(__file__).parents[1]
HOLD = ("import sys; from dcslam.locks import output_lock; sys.argv = ['dcslam', 'train', '--name', 'same']\n"
        "with output_lock(sys.argv_path, 'run'):\n"
        "    print('held', flush=True); sys.stdin.read()")


def _hold(path: Path) -> subprocess.Popen:
    """A second process holding ``path``'s lock until its stdin closes."""
    code = HOLD.replace("sys.argv_path", repr(str(path)))
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    assert proc.stdout.readline().strip() == "held", proc.stderr.read()
    return proc


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_a_second_process_is_refused_naming_the_holder_then_takes_the_lock_once_it_ends(tmp_path):
    run = tmp_path / "runs" / "same"
    proc = _hold(run)
    try:
        with pytest.raises(DcslamError) as caught:
            with output_lock(run, "run"):
                pytest.fail("the lock was taken twice")
        assert str(caught.value) == (f"run {run} is being written by PID {proc.pid} (dcslam train --name same); "
                                     "wait for it or stop it")
        assert holder(run)["pid"] == proc.pid
    finally:
        proc.communicate("")
    assert proc.returncode == 0
    assert not lock_path(run).exists()  # released and removed when the holder ended
    assert holder(run) is None
    notes = []
    with output_lock(run, "run", note=notes.append):
        assert holder(run)["pid"] == os.getpid()
    assert notes == []


def test_the_lock_of_a_killed_process_is_taken_over_with_a_note(tmp_path):
    layer = tmp_path / "predictions" / "mse" / "d.h5"
    proc = _hold(layer)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert lock_path(layer).exists()  # SIGKILL leaves the file; the kernel dropped the flock
    notes = []
    with output_lock(layer, "layer", note=notes.append):
        assert json.loads(lock_path(layer).read_text())["pid"] == os.getpid()
    assert notes == [f"note: layer {layer}: took over the lock of PID {proc.pid} (dcslam train --name same), "
                     "which is no longer running"]


def test_a_stale_lock_file_of_a_dead_pid_is_taken_over(tmp_path):
    out = tmp_path / "slam" / "dense"
    pid = _dead_pid()
    lock_path(out).parent.mkdir(parents=True)
    lock_path(out).write_text(json.dumps({"pid": pid, "command": "dcslam slam --force", "host": socket.gethostname()}))
    notes = []
    with output_lock(out, "SLAM output", note=notes.append):
        pass
    assert notes == [f"note: SLAM output {out}: took over the lock of PID {pid} (dcslam slam --force), which is no "
                     "longer running"]
    assert not lock_path(out).exists()


@pytest.mark.parametrize("raised", [RuntimeError, KeyboardInterrupt])
def test_the_lock_is_released_when_the_block_fails_or_is_interrupted(tmp_path, raised):
    out = tmp_path / "ws"
    with pytest.raises(raised):
        with output_lock(out, "workspace"):
            assert holder(out)["pid"] == os.getpid()
            raise raised()
    assert holder(out) is None and not lock_path(out).exists()
    proc = _hold(out)  # another process takes it at once
    proc.communicate("")
    assert proc.returncode == 0


def test_the_same_process_may_take_its_own_lock_again_inside_its_block(tmp_path):
    out = tmp_path / "runs" / "a"
    with output_lock(out, "run"):
        with output_lock(out, "run"):
            pass
        assert holder(out)["pid"] == os.getpid()  # the inner block did not release it
    assert holder(out) is None


def test_the_lock_sits_beside_the_output_so_removing_the_output_keeps_it(tmp_path):
    run = tmp_path / "runs" / "a"
    run.mkdir(parents=True)
    with output_lock(run, "run") as lock:
        assert lock == tmp_path / "runs" / ".a.lock"
        import shutil

        shutil.rmtree(run)
        assert lock.exists()


def test_without_flock_the_recorded_pid_decides(tmp_path, monkeypatch):
    import fcntl

    def no_flock(fd, op):
        raise OSError(errno.ENOLCK, os.strerror(errno.ENOLCK))

    monkeypatch.setattr(fcntl, "flock", no_flock)
    out = tmp_path / "layer.h5"
    lock = lock_path(out)
    here = socket.gethostname()
    lock.write_text(json.dumps({"pid": os.getppid(), "command": "dcslam predict", "host": here}))
    with pytest.raises(DcslamError, match=rf"^layer {out} is being written by PID {os.getppid()} \(dcslam predict\)"):
        with output_lock(out, "layer"):
            pass
    lock.write_text(json.dumps({"pid": 1234, "command": "dcslam predict", "host": "elsewhere"}))
    with pytest.raises(DcslamError, match=r"by PID 1234 on elsewhere \(dcslam predict\)"):
        with output_lock(out, "layer"):
            pass
    lock.write_text(json.dumps({"pid": _dead_pid(), "command": "dcslam predict", "host": here}))
    notes = []
    with output_lock(out, "layer", note=notes.append):
        assert json.loads(lock.read_text())["pid"] == os.getpid()
        assert holder(out)["pid"] == os.getpid()
    assert len(notes) == 1 and "no longer running" in notes[0]
    assert not lock.exists()
