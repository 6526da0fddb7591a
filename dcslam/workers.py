"""Worker processes for independent work (drives to generate, stages to run, table rows to score): a pool of
spawned processes (no fork of a process that has run torch), each with one BLAS / OpenMP / torch thread, since the
workers already use every core. A worker ends when the process that started it dies, even by SIGKILL, so a killed
command leaves no orphaned workers (nor, once they are gone, multiprocessing's resource tracker).
"""
from __future__ import annotations

import os
import sys

#: Environment variables that set the thread count of the numeric libraries a worker may load.
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


#: Set in the workers of a pool of more than one process: they share every core with their siblings.
SHARED_CORES = "DCSLAM_SHARED_CORES"


def exit_with_parent() -> None:
    """End this process as soon as the process that spawned it dies (SIGKILL included): a thread waits on
    multiprocessing's parent sentinel, the end of a pipe that closes only when the parent is gone. Does nothing in a
    process that multiprocessing did not start."""
    import multiprocessing
    import threading

    parent = multiprocessing.parent_process()
    if parent is None or parent.sentinel is None:
        return

    def watch() -> None:
        from multiprocessing.connection import wait

        wait([parent.sentinel])
        os._exit(1)  # no cleanup to run: the parent that would collect this worker's results is gone

    threading.Thread(target=watch, name="dcslam-parent-watch", daemon=True).start()


def one_thread(shared: bool = False) -> None:
    """Worker initializer: one thread per library in this process (torch, loaded later, reads OMP_NUM_THREADS);
    ``shared``: sibling workers keep the other cores busy (:func:`cores_shared`). The worker ends with its parent
    (:func:`exit_with_parent`)."""
    exit_with_parent()
    for name in THREAD_VARIABLES:
        os.environ[name] = "1"
    if shared:
        os.environ[SHARED_CORES] = "1"
    torch = sys.modules.get("torch")
    if torch is not None:
        torch.set_num_threads(1)


def process_pool(jobs: int, tasks: int):
    """A :class:`~concurrent.futures.ProcessPoolExecutor` of ``min(jobs, tasks)`` spawned, one-thread workers."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    workers = max(1, min(jobs, tasks))
    return ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=one_thread, initargs=(workers > 1,))


def cores_shared() -> bool:
    """Whether this process is one of several pool workers, which between them keep every core busy: work that
    would run on a second thread to save wall time (e.g. ``dcslam slam``'s prefetch) only slows its siblings."""
    return os.environ.get(SHARED_CORES) == "1"


def cpu_clock() -> float:
    """CPU seconds (user + system) of this process and of its children that have ended, so far."""
    import resource
    import time

    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime


class OwnLoad:
    """This process's share of the kernel's 1-minute load average, from the moment it is made: the CPU seconds per
    second of its threads and its ended children (``cpu``), averaged as the kernel averages the load, exponentially
    over a minute (``clock``: seconds; both given in tests). The load average alone counts the command's own earlier
    work as another process's: after one drive's main run, prefetch thread and companion worker, a second core looks
    busy that is not."""

    def __init__(self, clock=None, cpu=None):
        import time

        self.clock, self.cpu = clock or time.monotonic, cpu or cpu_clock
        self.at, self.used, self.average = self.clock(), self.cpu(), 0.0

    def read(self) -> float:
        """The share now (busy threads, averaged)."""
        import math

        now, used = self.clock(), self.cpu()
        if now > self.at:
            keep = math.exp(-(now - self.at) / 60.0)
            self.average = self.average * keep + (used - self.used) / (now - self.at) * (1.0 - keep)
            self.at, self.used = now, used
        return self.average
