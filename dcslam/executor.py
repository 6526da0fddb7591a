"""Where independent stages run: in local worker processes (:class:`LocalExecutor`, the default) or as Slurm jobs
(:class:`SlurmExecutor`, through submitit), behind one interface.

An executor is handed :class:`Task` s that do not read one another's outputs and yields one :class:`Outcome` per task
as each finishes (in any order); the caller (:meth:`dcslam.stages.pipeline.Pipeline.run_all`) stamps each one.
Closing the iterator before it is exhausted (a failure, Ctrl-C, SIGTERM) stops the work still running: local
workers are terminated, Slurm jobs cancelled with ``scancel``, so nothing keeps writing after the caller gave up.

On Slurm, every task is one job, or ``stages_per_job`` tasks of a kind share one job that runs them one after the
other (:func:`slurm_job`: a job of short stages spends most of its time starting Python and importing torch, 2-3
CPU-s, and the cluster schedules each job); tasks of one kind (``train``, ``predict``, ``filter``, ``slam``,
``score``, ``other``: declared by whoever makes the task, :attr:`Task.kind`) asking the same resources are submitted
together as one job array. The workspace must be on a filesystem
the nodes share (the jobs read and write it), and so must the Python environment (the jobs run this interpreter).
Each job's submitit folder, with its stdout / stderr logs, is ``<workspace>/logs/slurm/<job id>/``. The ``[slurm]``
table of ``dcslam reproduce --config FILE`` sets the partition, account, QoS, extra sbatch options, commands run
before each job and each kind's resources (:class:`SlurmSettings`); submitit itself is imported only here, only
when a Slurm executor is made (``pip install 'dcslam[slurm]'``).
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
import traceback
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Protocol

from dcslam.errors import DcslamError
from dcslam.workers import cpu_clock

KINDS = ("train", "predict", "filter", "slam", "score", "other")


@dataclass(frozen=True)
class Task:
    """One stage to run: ``run(workspace, config, force=True)`` of a dcslam.stages module; ``kind`` (one of
    :data:`KINDS`) chooses its resources."""

    name: str
    run: Callable
    config: object
    workspace: object  # dcslam.workspace.Workspace
    kind: str = "other"

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise DcslamError(f"task {self.name}: unknown kind {self.kind!r}; expected one of {', '.join(KINDS)}")

    def labels(self) -> list[str]:
        """``drive …`` and ``seed …`` when the task's configuration has them (what a failure message names)."""
        labels = []
        drives = getattr(self.config, "drive", None)
        if drives:
            labels.append(f"drive {', '.join(map(str, drives)) if isinstance(drives, list) else drives}")
        seed = getattr(self.config, "seed", None)
        if seed is not None:
            labels.append(f"seed {seed}")
        return labels


@dataclass(frozen=True)
class Outcome:
    """How one task ended: ``seconds`` it ran (wall) and ``cpu_seconds`` its process used, or ``error`` (one line);
    ``job`` and ``log`` on Slurm."""

    task: Task
    seconds: float | None = None
    cpu_seconds: float | None = None
    error: str | None = None
    job: str | None = None
    log: Path | None = None

    @property
    def ok(self) -> bool:
        return self.error is None


class Executor(Protocol):
    """Runs independent tasks; see the module docstring."""

    def in_process(self, tasks: int) -> bool:
        """Whether ``tasks`` tasks are better run one after the other in this process (the caller then does)."""

    def run(self, tasks: list[Task]) -> Iterator[Outcome]:
        """Start every task; yield each one's outcome as it finishes. Closing the iterator early stops the rest."""


def timed(run: Callable, workspace, config, started: Path | None = None) -> tuple[float, float]:
    """Run one stage with ``force=True``; return ``(wall seconds, CPU seconds)`` it took, measured in the process
    that ran it (what a worker or a job runs). ``started``: a file the process writes its pid to first (so that a
    worker that dies can be matched to its stage)."""
    if started is not None:
        started.write_text(str(os.getpid()))
    start, cpu = time.perf_counter(), cpu_clock()
    run(workspace, config, force=True)
    return time.perf_counter() - start, cpu_clock() - cpu


class LocalExecutor:
    """``jobs`` spawned worker processes of one thread each (:func:`dcslam.workers.process_pool`). ``keep``: the
    workers of a :meth:`run` that finished stay up for the next one until :meth:`close` (a new worker imports torch
    again: 2-3 CPU-s), unless one of them died meanwhile; a run that gave up ends them all the same."""

    def __init__(self, jobs: int = 1, keep: bool = False):
        self.jobs, self.keep = jobs, keep
        self._pool = None  # the kept pool, between runs

    def in_process(self, tasks: int) -> bool:
        return self.jobs <= 1 or tasks <= 1

    def close(self) -> None:
        """End the kept workers (they are idle: no run is under way)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

    def _take_kept(self):
        """The kept pool, taken (a run that gives up must not leave it kept); None when there is none or one of its
        workers died while idle (the pool is then broken: ended here, the run starts afresh)."""
        pool, self._pool = self._pool, None
        if pool is not None and (getattr(pool, "_broken", False) or
                                 any(p.exitcode is not None for p in getattr(pool, "_processes", {}).values())):
            pool.shutdown(wait=False, cancel_futures=True)
            return None
        return pool

    def run(self, tasks: list[Task]) -> Iterator[Outcome]:
        import tempfile

        from dcslam.workers import process_pool

        pool = self._take_kept() or process_pool(self.jobs, self.jobs if self.keep else len(tasks))
        futures, workers, finished = {}, [], False
        marks = Path(tempfile.mkdtemp(prefix="dcslam-workers-"))
        try:
            futures = {pool.submit(timed, task.run, task.workspace, task.config, marks / f"{i}.pid"): task
                       for i, task in enumerate(tasks)}
            workers = list(getattr(pool, "_processes", {}).values())  # ProcessPoolExecutor's own table
            broken = False
            for outcome, broken in _as_finished(futures, workers, marks):
                yield outcome
            finished = not broken
        finally:
            if finished and self.keep:
                self._pool = pool
            elif finished:
                pool.shutdown(wait=True)
            else:  # given up: no worker keeps writing outputs nobody will stamp
                for future in futures:
                    future.cancel()
                pool.shutdown(wait=False, cancel_futures=True)
                for process in workers:
                    if process.is_alive():
                        process.terminate()
                for process in workers:
                    process.join(timeout=10)
            shutil.rmtree(marks, ignore_errors=True)


def _as_finished(futures: dict, workers: list, marks: Path) -> Iterator[tuple[Outcome, bool]]:
    """``(outcome, False)`` for each of ``futures`` (future -> task) as it finishes; when a worker dies, one last
    ``(outcome of the stage it ran, True)`` (:func:`died`). The workers are polled as well as the pool's manager
    asked: a worker the pool spawned after its manager last listed them can die unseen by it (CPython 3.11) until
    another worker returns a result, and the command would wait until then (forever, when no other is left)."""
    from concurrent.futures import FIRST_COMPLETED, wait
    from concurrent.futures.process import BrokenProcessPool

    pending = set(futures)
    while pending:
        done, pending = wait(pending, timeout=0.5, return_when=FIRST_COMPLETED)
        for future in done:
            task = futures[future]
            try:
                seconds, cpu = future.result()
            except DcslamError as error:
                yield Outcome(task, error=str(error)), False
            except BrokenProcessPool:
                unfinished = [f for f in futures if f in pending or f.done() and f.exception() is not None]
                yield died([futures[f] for f in unfinished], list(futures.values()), workers, marks), True
                return
            else:
                yield Outcome(task, seconds=seconds, cpu_seconds=cpu), False
        if pending and any(process.exitcode is not None for process in workers):
            yield died([futures[f] for f in futures if f in pending], list(futures.values()), workers, marks), True
            return


def _exit_code(process, patience: float = 2.0) -> int | None:
    """``process.exitcode``, waiting up to ``patience`` seconds for it once the process has ended: while the pool's
    manager thread reaps it, this thread's poll finds no child and reads None."""
    from multiprocessing.connection import wait

    deadline = time.monotonic() + patience
    while process.exitcode is None and wait([process.sentinel], 0) and time.monotonic() < deadline:
        time.sleep(0.01)
    return process.exitcode


def died(stopped: list[Task], tasks: list[Task], workers: list, marks: Path) -> Outcome:
    """The outcome of a pool whose worker died (killed, out of memory, a crash in native code): the failed task is
    the one whose worker (by the pid it wrote to ``marks``, ``<index in tasks>.pid``) ended other than by the
    pool's own SIGTERM, else the first of ``stopped`` (the tasks left unfinished); its error says how the worker
    ended and names the others stopped with it."""
    import signal

    codes = {process.pid: _exit_code(process) for process in workers}
    by_pid = {}
    for i, task in enumerate(tasks):
        mark = marks / f"{i}.pid"
        text = mark.read_text().strip() if mark.is_file() else ""
        if text.isdigit():
            by_pid[int(text)] = task
    dead = [(pid, code) for pid, code in codes.items() if code not in (None, -signal.SIGTERM) and pid in by_pid]
    task = by_pid[dead[0][0]] if dead else stopped[0]
    code = dead[0][1] if dead else None
    how = ("ended without a result" if code is None else
           f"was killed by {signal.Signals(-code).name}" if code < 0 and -code in signal.valid_signals() else
           f"exited with status {code}")
    if code == -signal.SIGKILL:
        how += " (what the out-of-memory killer sends: give it more memory or run fewer --jobs)"
    others = [t.name for t in stopped if t is not task]
    beside = f"; stopped with it: {', '.join(others)}" if others else ""
    where = "its worker process" if dead else "a worker process running it or a stage beside it"
    return Outcome(task, error=f"{where} {how}{beside}")


@dataclass(frozen=True)
class Resources:
    """What one job of a kind asks Slurm for; ``gpus`` None: one per training process (``nproc``) for trainings
    and predictions whose ``device`` is ``cuda``, none otherwise; ``stages_per_job``: at most that many stages of
    the kind run one after the other in each job (``time_min`` is the whole job's)."""

    cpus: int = 1
    mem_gb: float = 4
    time_min: int = 60
    gpus: int | None = None
    stages_per_job: int = 1

    def gpus_for(self, task: Task) -> int:
        if self.gpus is not None:
            return self.gpus
        if task.kind in ("train", "predict") and getattr(task.config, "device", "") == "cuda":
            return max(1, int(getattr(task.config, "nproc", 1)))
        return 0


#: Each kind's resources unless the ``[slurm.<kind>]`` table says otherwise.
DEFAULT_RESOURCES = {
    "train": Resources(cpus=4, mem_gb=16, time_min=720),
    "predict": Resources(cpus=2, mem_gb=8, time_min=120),
    "filter": Resources(cpus=1, mem_gb=4, time_min=60),
    "slam": Resources(cpus=1, mem_gb=4, time_min=120),
    "score": Resources(cpus=1, mem_gb=4, time_min=60),
    "other": Resources(cpus=1, mem_gb=4, time_min=60),
}


@dataclass(frozen=True)
class SlurmSettings:
    """The ``[slurm]`` table of a ``dcslam reproduce`` configuration file::

        [slurm]
        partition = "gpu"                 # sbatch --partition (default: the cluster's default partition)
        account = "my-project"            # --account
        qos = "normal"                    # --qos
        sbatch = {constraint = "a100"}    # any other sbatch option: name = value (true: a bare flag)
        setup = ["module load cuda"]      # shell lines run in each job before dcslam
        poll_seconds = 2                  # how often the queue and the jobs' results are looked at
        [slurm.train]                     # resources of one kind: train, predict, filter, slam, score, other
        cpus = 8
        mem_gb = 32
        time_min = 600                    # the whole job's: all its stages
        gpus = 1                          # default: one per process for --device cuda trainings and predictions
        stages_per_job = 1                # stages run one after the other in one job (default 1)
    """

    partition: str | None = None
    account: str | None = None
    qos: str | None = None
    sbatch: dict = field(default_factory=dict)
    setup: tuple[str, ...] = ()
    poll_seconds: float = 2.0
    resources: dict = field(default_factory=lambda: dict(DEFAULT_RESOURCES))

    @classmethod
    def from_table(cls, table: dict, source: str = "[slurm]") -> "SlurmSettings":
        """Settings from the ``[slurm]`` table (unknown keys, wrong types: :class:`DcslamError` naming the key)."""
        if not isinstance(table, dict):
            raise DcslamError(f"{source}: expected a table ([slurm]), got {table!r}")
        scalars = {"partition": str, "account": str, "qos": str, "poll_seconds": (int, float)}
        known = (*scalars, "sbatch", "setup", *KINDS)
        values: dict = {}
        resources = dict(DEFAULT_RESOURCES)
        for key, value in table.items():
            where = f"{source} {key}"
            if key not in known:
                raise DcslamError(f"{source}: unknown key {key!r}; expected one of {', '.join(known)}")
            if key in scalars:
                if not isinstance(value, scalars[key]) or isinstance(value, bool):
                    raise DcslamError(f"{where}: expected {'a number' if key == 'poll_seconds' else 'a string'}, "
                                      f"got {value!r}")
                values[key] = value
            elif key == "sbatch":
                if not isinstance(value, dict) or any(isinstance(v, (dict, list)) for v in value.values()):
                    raise DcslamError(f"{where}: expected a table of sbatch options (constraint = \"a100\"), got "
                                      f"{value!r}")
                values[key] = dict(value)
            elif key == "setup":
                if not isinstance(value, list) or not all(isinstance(line, str) for line in value):
                    raise DcslamError(f"{where}: expected a list of shell lines, got {value!r}")
                values[key] = tuple(value)
            else:
                resources[key] = _resources(resources[key], value, where)
        if values.get("poll_seconds", 1) <= 0:
            raise DcslamError(f"{source} poll_seconds: must be > 0, got {values['poll_seconds']}")
        return cls(**values, resources=resources)


def _resources(default: Resources, table, where: str) -> Resources:
    if not isinstance(table, dict):
        raise DcslamError(f"{where}: expected a table (cpus, mem_gb, time_min, gpus, stages_per_job), got {table!r}")
    names = [f.name for f in fields(Resources)]
    for key, value in table.items():
        if key not in names:
            raise DcslamError(f"{where}: unknown key {key!r}; expected one of {', '.join(names)}")
        number = (int, float) if key == "mem_gb" else int
        if not isinstance(value, number) or isinstance(value, bool) or value < (0 if key == "gpus" else 1):
            raise DcslamError(f"{where} {key}: expected a {'number' if key == 'mem_gb' else 'whole number'} >= "
                              f"{0 if key == 'gpus' else 1}, got {value!r}")
    return replace(default, **table)


def slurm_job(stages: list[tuple[Callable, object, object]]) -> list[tuple[str, object]]:
    """What one Slurm job runs: its stages (``(run, workspace, config)``) one after the other, with as many threads
    as the job has CPUs. Per stage ``("ok", (seconds, CPU seconds))``, ``("error", message)`` for a known error or
    ``("bug", "Type: message")`` for any other exception (its traceback printed to the job's stderr log); the first
    stage that fails ends the job (the stages after it are not run: they would be stopped with it anyway)."""
    cpus = os.environ.get("SLURM_CPUS_PER_TASK")
    if cpus:
        from dcslam.workers import THREAD_VARIABLES

        for name in THREAD_VARIABLES:
            os.environ[name] = cpus
        torch = sys.modules.get("torch")
        if torch is not None:
            torch.set_num_threads(int(cpus))
    results: list[tuple[str, object]] = []
    for run, workspace, config in stages:
        try:
            results.append(("ok", timed(run, workspace, config)))
        except DcslamError as error:
            results.append(("error", str(error)))
        except Exception as error:  # a bug: named with its stage, its traceback in the job's log
            traceback.print_exc()
            results.append(("bug", f"{type(error).__name__}: {error}"))
        if results[-1][0] != "ok":
            break
    return results


def packs(tasks: list[Task], size: int) -> list[list[Task]]:
    """``tasks`` in order, cut into as few jobs of at most ``size`` as possible, of sizes that differ by one at
    most (17 stages of 8 a job: 6, 6, 5 rather than 8, 8, 1)."""
    if not tasks:
        return []
    count = -(-len(tasks) // max(size, 1))
    base, longer = divmod(len(tasks), count)
    cuts = [i * base + min(i, longer) for i in range(count + 1)]
    return [tasks[a:b] for a, b in zip(cuts, cuts[1:])]


#: Seconds a job may be gone from the queue before its result file must be there (a shared filesystem's delay).
VANISHED_GRACE_S = 20.0
#: Seconds to wait for jobs that are cancelled, or have written their result, to leave the queue.
CANCEL_WAIT_S = 60.0


class SlurmExecutor:
    """Each task a Slurm job, submitted through submitit; see the module docstring."""

    def __init__(self, folder: Path, settings: SlurmSettings | None = None, log: Callable[[str], None] = print):
        try:
            import submitit  # noqa: F401
        except ImportError:
            raise DcslamError("--executor slurm needs submitit: pip install 'dcslam[slurm]' (or pip install "
                              "submitit)") from None
        if shutil.which("sbatch") is None:
            raise DcslamError("--executor slurm: sbatch is not on PATH; run dcslam reproduce where Slurm jobs can be "
                              "submitted (a login node), or use --executor local")
        self.folder = Path(folder)
        self.settings = settings or SlurmSettings()
        self.log = log
        self.submitted: list[str] = []  # every job id this executor submitted

    def in_process(self, tasks: int) -> bool:
        return False

    def _parameters(self, kind: str, gpus: int) -> dict:
        """submitit parameters of one kind's jobs."""
        s, res = self.settings, self.settings.resources[kind]
        params = {"name": f"dcslam-{kind}", "timeout_min": res.time_min, "cpus_per_task": res.cpus,
                  "mem_gb": res.mem_gb, "nodes": 1, "tasks_per_node": 1, "slurm_additional_parameters": dict(s.sbatch)}
        if gpus:
            params["gpus_per_node"] = gpus
        for name in ("partition", "account", "qos"):
            if getattr(s, name):
                params[f"slurm_{name}"] = getattr(s, name)
        if s.setup:
            params["slurm_setup"] = list(s.setup)
        return params

    def submit(self, tasks: list[Task]) -> Iterator[tuple[object, list[Task]]]:
        """Submit ``tasks``: one job array per (kind, GPUs) group, each job running up to the kind's
        ``stages_per_job`` tasks (:func:`packs`); yields (submitit job, its tasks) pairs as each group is submitted
        (so that a failure or an interrupt part way cancels the groups already in the queue)."""
        import submitit

        groups: dict[tuple[str, int], list[Task]] = {}
        for task in tasks:
            kind = task.kind
            groups.setdefault((kind, self.settings.resources[kind].gpus_for(task)), []).append(task)
        partitions = _partitions()
        if partitions is not None:  # refused here, with the partition's limits, rather than pending forever
            for kind, gpus in groups:
                check_resources(kind, self.settings.resources[kind], gpus, partitions, self.settings.partition)
        for (kind, gpus), group in groups.items():
            executor = submitit.AutoExecutor(folder=self.folder / "%j", cluster="slurm")
            executor.update_parameters(**self._parameters(kind, gpus))
            cut = packs(group, self.settings.resources[kind].stages_per_job)
            try:
                with executor.batch():
                    jobs = [executor.submit(slurm_job, [(t.run, t.workspace, t.config) for t in pack])
                            for pack in cut]
            except Exception as error:  # sbatch refused (a partition that does not exist, resources too large)
                message = str(error).strip().splitlines()
                raise DcslamError(f"sbatch refused the {kind} jobs ({message[-1] if message else error}); check the "
                                  "[slurm] table of --config (partition, account, qos, resources)") from None
            self.submitted += [job.job_id for job in jobs]
            yield from zip(jobs, cut)

    def run(self, tasks: list[Task]) -> Iterator[Outcome]:
        pending: dict[str, tuple[object, list[Task]]] = {}
        ran: set[str] = set()
        try:
            for job, pack in self.submit(tasks):
                pending[job.job_id] = (job, pack)
                ran.add(job.job_id)
                for task in pack:
                    self.log(f"[slurm] {task.name}: job {job.job_id}")
            vanished: dict[str, float] = {}
            while pending:
                queued = _queued_jobs()
                for job_id, (job, pack) in list(pending.items()):
                    outcomes = _finished(job, pack)
                    if outcomes is None and queued is not None and job_id not in queued:
                        vanished.setdefault(job_id, time.monotonic())
                        if time.monotonic() - vanished[job_id] > VANISHED_GRACE_S:
                            outcomes = [Outcome(task, error=f"job {job_id} left the queue without a result "
                                                            f"({_last_line(job) or 'no log line'})",
                                                job=job_id, log=_log_path(job)) for task in pack]
                    elif outcomes is None and queued is not None and queued[job_id] in NEVER_STARTS:
                        outcomes = [self._never_starts(job, task, queued[job_id]) for task in pack]
                        self.cancel([job_id])
                    if outcomes is not None:
                        del pending[job_id]
                        yield from outcomes
                if pending:
                    time.sleep(self.settings.poll_seconds)
        finally:
            if pending:
                self.cancel(list(pending))
            # a job that wrote its result may still be exiting: return with none of this run's jobs in the queue
            self.wait_gone(sorted(ran))

    def _never_starts(self, job, task: Task, reason: str) -> Outcome:
        res = self.settings.resources[task.kind]
        return Outcome(task, error=f"job {job.job_id} can never start: Slurm says {reason} (it asks {res.cpus} "
                                   f"CPUs, {res.mem_gb:g} GB, {res.time_min} min, {res.gpus_for(task)} GPUs); lower "
                                   f"[slurm.{task.kind}] of --config or choose another partition",
                       job=job.job_id, log=_existing_log(job))  # it never ran: no log

    def wait_gone(self, job_ids: list[str]) -> None:
        """Wait (at most :data:`CANCEL_WAIT_S`) until none of ``job_ids`` is in the queue."""
        deadline = time.monotonic() + CANCEL_WAIT_S
        while job_ids and time.monotonic() < deadline:
            queued = _queued_jobs()
            if queued is not None and not any(job_id in queued for job_id in job_ids):
                return
            time.sleep(0.5)

    def cancel(self, job_ids: list[str]) -> None:
        """``scancel`` ``job_ids`` and wait (at most :data:`CANCEL_WAIT_S`) until they have left the queue."""
        import signal

        previous = {}
        for signum in (signal.SIGINT, signal.SIGTERM):  # a second Ctrl-C must not leave the jobs running
            try:
                previous[signum] = signal.signal(signum, signal.SIG_IGN)
            except ValueError:  # not the main thread: signals are not ours to hold
                pass
        try:
            subprocess.run(["scancel", *job_ids], check=False, capture_output=True, timeout=60)
            self.log(f"[slurm] cancelled {len(job_ids)} job(s): {' '.join(job_ids)}")
            self.wait_gone(job_ids)
        finally:
            for signum, handler in previous.items():
                signal.signal(signum, handler)


#: Why a pending job waits, when waiting cannot help: it asks more than the partition, account or QoS allows.
NEVER_STARTS = ("PartitionConfig", "PartitionNodeLimit", "PartitionTimeLimit", "BadConstraints", "InvalidAccount",
                "InvalidQOS")


def _queued_jobs() -> dict[str, str] | None:
    """This user's jobs in the queue (pending, running, completing) → the reason a pending one waits ("" when
    running); array tasks one by one, and an array's own id for its tasks that squeue still shows folded. None when
    squeue does not answer (then every job counts as queued).

    squeue rather than submitit's ``job.state``: submitit reads ``sacct``, which answers only where the cluster
    keeps an accounting database and never gives the reason a pending job waits (what :data:`NEVER_STARTS` needs)."""
    try:
        done = subprocess.run(["squeue", "--me", "-h", "-r", "-o", "%i %T %r"], capture_output=True, text=True,
                              timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return None
    if done.returncode != 0:
        return None
    queued = {}
    for line in done.stdout.splitlines():
        job_id, state, reason = (line.split(None, 2) + ["", ""])[:3]
        why = reason.strip() if state == "PENDING" else ""
        queued[job_id] = why
        queued.setdefault(job_id.split("_")[0], why)
    return queued


def _finished(job, pack: list[Task]) -> list[Outcome] | None:
    """The outcomes of ``job``'s tasks (``pack``, in the order it ran them) if its result file is there, else None:
    those that ran, then the one that failed, then any left unrun after it."""
    if not job.paths.result_pickle.exists():
        return None
    where = {"job": job.job_id, "log": _log_path(job)}
    try:
        results = job.result()
    except Exception as error:  # the job failed outside the stages (e.g. unpickling them): traceback in the log
        lines = [line for line in str(error).splitlines() if line.strip()]
        why = f"job {job.job_id} failed: {lines[-1].strip() if lines else type(error).__name__}"
        return [Outcome(task, error=why, **where) for task in pack]
    outcomes = []
    for task, (status, value) in zip(pack, results):
        if status == "ok":
            seconds, cpu = value
            outcomes.append(Outcome(task, seconds=float(seconds), cpu_seconds=float(cpu), **where))
        else:
            outcomes.append(Outcome(task, error=f"job {job.job_id} failed: {value}" if status == "bug" else str(value),
                                    **where))
    outcomes += [Outcome(task, error=f"not run: stage {pack[len(results) - 1].name} before it in the same job "
                                     "failed", **where)
                 for task in pack[len(results):]]
    return outcomes


def _log_path(job) -> Path:
    return Path(job.paths.stderr)


def _existing_log(job) -> Path | None:
    """The job's stderr log where it exists (a job that never started has none), else None."""
    path = _log_path(job)
    return path if path.exists() else None


@dataclass(frozen=True)
class Partition:
    """What one node of a Slurm partition offers at most: ``cpus``, ``mem_gb``, ``gpus``, and the partition's time
    limit (``time_min``, None: unlimited); ``default``: the partition jobs go to without ``--partition``."""

    name: str
    cpus: int
    mem_gb: float
    time_min: int | None
    gpus: int = 0
    default: bool = False


#: The ``sinfo`` output format :func:`parse_sinfo` reads: partition, CPUs, memory (MB) per node, time limit, GRES.
SINFO_FORMAT = "%P %c %m %l %G"


def _minutes(limit: str) -> int | None:
    """A Slurm time limit (``infinite``, ``MM``, ``MM:SS``, ``HH:MM:SS``, ``D-HH[:MM[:SS]]``) in whole minutes."""
    if limit in ("infinite", "UNLIMITED", "n/a"):
        return None
    days, _, rest = limit.rpartition("-")
    parts = [int(p) for p in rest.split(":")]
    if days:
        hours, minutes = (parts + [0, 0])[:2]
    elif len(parts) == 3:
        hours, minutes = parts[:2]
    else:
        hours, minutes = 0, parts[0]
    return int(days or 0) * 1440 + hours * 60 + minutes


def _gpus(gres: str) -> int:
    """GPUs per node of a GRES field (``gpu:4``, ``gpu:a100:2(S:0-1)``, ``(null)``)."""
    total = 0
    for item in gres.split(","):
        fields_ = item.split("(")[0].split(":")
        if fields_[0] == "gpu" and fields_[-1].isdigit():
            total += int(fields_[-1])
    return total


def parse_sinfo(text: str) -> dict[str, Partition]:
    """Partitions from ``sinfo -h -o "%P %c %m %l %G"`` output: per partition the most any of its node groups
    offers. Lines that do not parse are skipped."""
    partitions: dict[str, Partition] = {}
    for line in text.splitlines():
        fields_ = line.split()
        if len(fields_) < 4:
            continue
        name, cpus, mem, limit = fields_[:4]
        try:
            found = Partition(name.rstrip("*"), int(cpus.rstrip("+")), round(int(mem.rstrip("+")) / 1024, 1),
                              _minutes(limit), _gpus(fields_[4]) if len(fields_) > 4 else 0, name.endswith("*"))
        except ValueError:
            continue
        old = partitions.get(found.name)
        if old is not None:
            found = replace(found, cpus=max(old.cpus, found.cpus), mem_gb=max(old.mem_gb, found.mem_gb),
                            gpus=max(old.gpus, found.gpus), default=old.default or found.default)
        partitions[found.name] = found
    return partitions


def _partitions() -> dict[str, Partition] | None:
    """The cluster's partitions (:func:`parse_sinfo`); None when sinfo does not answer."""
    try:
        done = subprocess.run(["sinfo", "-h", "-o", SINFO_FORMAT], capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return parse_sinfo(done.stdout) if done.returncode == 0 else None


def check_resources(kind: str, res: Resources, gpus: int, partitions: dict[str, Partition],
                    partition: str | None = None) -> None:
    """Refuse (one :class:`DcslamError` line) the jobs of ``kind`` when they ask more than one node of their
    partition (``partition``, else the cluster's default) offers, naming the partition's limits and the fix."""
    chosen = partitions.get(partition) if partition else next((p for p in partitions.values() if p.default), None)
    if chosen is None:
        if partition:
            raise DcslamError(f"[slurm] partition {partition!r} is not one of this cluster's "
                              f"({', '.join(partitions) or 'none'}); choose one in the [slurm] table of --config")
        return
    too_much = [what for what, asked, offered in (("CPUs", res.cpus, chosen.cpus), ("GB", res.mem_gb, chosen.mem_gb),
                                                  ("GPUs", gpus, chosen.gpus))
                if asked > offered]
    if chosen.time_min is not None and res.time_min > chosen.time_min:
        too_much.append("minutes")
    if too_much:
        limit = "no time limit" if chosen.time_min is None else f"{chosen.time_min} min"
        raise DcslamError(
            f"the {kind} jobs ask {res.cpus} CPUs, {res.mem_gb:g} GB, {res.time_min} min, {gpus} GPUs, more "
            f"{', '.join(too_much)} than a node of partition {chosen.name} offers ({chosen.cpus} CPUs, "
            f"{chosen.mem_gb:g} GB, {limit}, {chosen.gpus} GPUs); set cpus, mem_gb and time_min within those in "
            f"[slurm.{kind}] of --config, or choose another partition")


def _last_line(job) -> str:
    """The last line of the job's stderr log (where Slurm writes why it killed a job), if any."""
    try:
        lines = [line.strip() for line in _log_path(job).read_text(errors="replace").splitlines() if line.strip()]
    except OSError:
        return ""
    return lines[-1] if lines else ""
