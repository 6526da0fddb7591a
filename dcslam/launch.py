"""The ``dcslam`` command's entry point (``dcslam`` and ``python -m dcslam``): glibc's allocator tunables, then the
command line (:func:`dcslam.cli.main`).

Contract: when the environment names no ``GLIBC_TUNABLES`` and the process runs on glibc, the same interpreter is
started again in this process (``execve``: the same process id, arguments and standard streams) with
:data:`dcslam.allocator.SLAM_TUNABLES` added to its environment, before anything is read or written; the processes
it starts (workers, Slurm jobs) inherit them. Set ``GLIBC_TUNABLES`` (even empty) and nothing is started again. Why:
glibc reads its tunables only when a process starts, and the per-thread cache they turn off fragments a long SLAM
run's heap (:mod:`dcslam.allocator`). A library caller's own process is never started again.
"""
from __future__ import annotations

import os
import sys


def restart_tuned() -> None:
    """Start this interpreter again with glibc's tunables for dcslam (see the module docstring); returns only when
    there is nothing to do or starting it fails, in which case the command runs with glibc's defaults."""
    from dcslam.allocator import tuned_environment

    environ = tuned_environment()
    argv = getattr(sys, "orig_argv", None)  # Python >= 3.10: the interpreter's options included
    if environ is None or not argv:
        return
    for stream in (sys.stdout, sys.stderr):   # nothing is written before this; a closed stream is no matter
        try:
            stream.flush()
        except (AttributeError, OSError, ValueError):
            pass
    try:
        os.execve(sys.executable, [sys.executable, *argv[1:]], environ)
    except OSError:
        return


def main() -> None:
    """The ``dcslam`` command (:func:`dcslam.cli.main`), in a process with dcslam's allocator tunables."""
    restart_tuned()
    from dcslam.cli import main as command

    command()
