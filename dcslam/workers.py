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
