"""dcslam.launch: the ``dcslam`` command starts itself again with glibc's tunables for dcslam, which glibc applies
(each check in a fresh interpreter: this test process's allocator keeps glibc's defaults)."""
import os
import subprocess
import sys


from dcslam.allocator import SLAM_TUNABLES, TUNABLES_ENV, tuned_environment
from tests.fixtures.glibc import is_glibc, needs_glibc, needs_mallinfo2


# Restarts as the command does, then frees 64 blocks of 904 bytes: glibc's per-thread cache keeps 7 of them (the
# allocations emptied its bin for that size), which mallinfo2 counts as in use; without it every block is freed.
PROBE = """
import ctypes, os
from dcslam.launch import restart_tuned
from dcslam.allocator import _MallInfo2
restart_tuned()
libc = ctypes.CDLL("libc.so.6")
malloc, free, mallinfo2 = libc.malloc, libc.free, libc.mallinfo2
malloc.restype, malloc.argtypes = ctypes.c_void_p, [ctypes.c_size_t]
free.argtypes = [ctypes.c_void_p]
mallinfo2.restype = _MallInfo2
blocks = [malloc(904) for _ in range(64)]
used = mallinfo2().uordblks
for block in blocks:
    free(block)
freed = (used - mallinfo2().uordblks) // 912   # 904 bytes asked: chunks of 912
print(repr(os.environ.get("GLIBC_TUNABLES")), "cached" if freed <= 57 else "freed")
"""


def _run(code: str, *args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    environ = {k: v for k, v in os.environ.items() if k != TUNABLES_ENV} | (env or {})
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, env=environ)


@needs_mallinfo2
def test_the_process_starts_again_once_with_the_cache_off():
    done = _run(PROBE)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == [f"{SLAM_TUNABLES!r} freed"]   # printed by the restarted process alone


@needs_mallinfo2
def test_tunables_in_the_environment_are_the_users_choice():
    assert _run(PROBE, env={TUNABLES_ENV: ""}).stdout.splitlines() == ["'' cached"]
    mine = "glibc.malloc.mxfast=0"
    assert _run(PROBE, env={TUNABLES_ENV: mine}).stdout.splitlines() == [f"{mine!r} cached"]


def test_the_environment_is_built_not_changed(monkeypatch):
    environ = {"PATH": "/bin"}
    tuned = tuned_environment(environ)
    assert environ == {"PATH": "/bin"}
    if is_glibc():
        assert tuned == {"PATH": "/bin", TUNABLES_ENV: SLAM_TUNABLES}
    assert tuned_environment({TUNABLES_ENV: ""}) is None
    monkeypatch.setattr(sys, "platform", "darwin")
    assert tuned_environment(environ) is None


@needs_glibc
def test_the_command_keeps_its_arguments_and_exit_status():
    environ = {k: v for k, v in os.environ.items() if k != TUNABLES_ENV}
    done = subprocess.run([sys.executable, "-m", "dcslam", "slam", "--no-such-option"], capture_output=True,
                          text=True, env=environ)
    assert done.returncode == 2
    assert "No such option: --no-such-option" in done.stderr and done.stderr.count("Usage:") == 1
    shown = subprocess.run([sys.executable, "-m", "dcslam", "--help"], capture_output=True, text=True, env=environ)
    assert shown.returncode == 0 and shown.stdout.count("Usage: ") == 1 and "slam" in shown.stdout
