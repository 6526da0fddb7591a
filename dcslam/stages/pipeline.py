"""The stage engine of ``dcslam reproduce``: stages, their stamps, skipping, and running independent stages.

A :class:`Stage` is a stage function of a dcslam.stages module, its configuration, the files it reads and writes and
its ``kind`` (which resources an executor gives it: ``train``, ``predict``, ``filter``, ``slam``, ``score`` or
``other``). A :class:`Pipeline` runs a stage unless it is up to date: its outputs exist, are newer than its inputs,
and were made with the same configuration by the same dcslam (version and a hash of its sources, recorded in
``<workspace>/.reproduce/<stage>.json``), so a rerun after a change redoes only what changed. A stage's stamp says
"running" while it runs, so an interrupted stage is redone on the next run. Outputs that exist but were not made by
the pipeline (no stamp, or changed after a finished stage's stamp) are never overwritten without ``force``.
:meth:`Pipeline.run_all` hands independent stages to an executor (:mod:`dcslam.executor`).

An :class:`Experiment` is what ``dcslam reproduce --table NAME`` runs: its profiles, the composition of its stages
and the command that rebuilds its tables (``dcslam score tables --table NAME``); the experiments are registered in
:data:`dcslam.stages.experiments.EXPERIMENTS`. :func:`profile_options` checks a profile's stage options.
"""
from __future__ import annotations

import json
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from dcslam.errors import DcslamError
from dcslam.stages.config import Options, changed, code_version, to_dict
from dcslam.io.atomic import write_json_atomic
from dcslam.workspace import Workspace


def profile_options(profile: str, what: str, config: type, values, reserved=frozenset()) -> Options:
    """``values`` (a mapping of option → value) as :class:`Options` of ``config``; a :class:`DcslamError` naming the
    profile when a key is not a field of ``config``, has the wrong type or is one of ``reserved``."""
    try:
        options = values if isinstance(values, Options) and values.config is config else Options(config, values)
    except DcslamError as error:
        raise DcslamError(f"profile {profile}: {what}: {error}") from None
    clash = sorted(set(options) & reserved)
    if clash:
        raise DcslamError(f"profile {profile}: {what} sets {', '.join(clash)}, which the recipes or runs set")
    return options


@dataclass(frozen=True)
class Experiment:
    """One experiment of ``dcslam reproduce --table NAME``.

    ``profiles``: profile name → profile, each with at least ``name``, ``drives``, ``frames``, ``split`` and
    ``seeds`` (what the plan and its cost read); ``compose(pipe, profile, kitti_root, seed, jobs, seeds)`` hands
    every stage to ``pipe`` in order and returns the Markdown file of the table; ``tables(ws, config, force)``
    rebuilds its tables from the stage outputs in the workspace (``dcslam score tables --table NAME``; ``config`` a
    :class:`dcslam.stages.score.ScoreTablesConfig`) and returns a report whose ``written`` lists the files."""

    name: str
    help: str
    profiles: Mapping[str, object] = field(repr=False)
    compose: Callable[..., Path] = field(repr=False)
    tables: Callable[..., object] = field(repr=False)

    def profile(self, name: str):
        """The profile ``name``; a :class:`DcslamError` naming the profiles there are."""
        if name not in self.profiles:
            raise DcslamError(f"unknown profile {name!r} of --table {self.name}; expected one of "
                              f"{', '.join(self.profiles)}")
        return self.profiles[name]


@dataclass
class Stage:
    """One stage of the pipeline: a stage function, its configuration, and the files it reads and writes."""

    name: str
    run: Callable               # run(workspace, config, force=True) of a dcslam.stages module
    config: object              # that stage's configuration dataclass
    outputs: Callable[[], list[Path]]
    inputs: Callable[[], list[Path]] = lambda: []
    seed: int | None = None     # training seed of the run the stage trains or uses (None: no trained model)
    kind: str = "other"         # the executor's resources: train, predict, filter, slam, score or other

    def record(self) -> dict:
        """What the stamp compares: the stage function, its configuration and the code that runs it."""
        return {"stage": f"{self.run.__module__}.{self.run.__name__}", "config": to_dict(self.config),
                "dcslam": code_version()}


def _mtime(paths: list[Path]) -> tuple[float, float]:
    times = [p.stat().st_mtime for p in paths if p.exists()]
    return (min(times), max(times)) if times else (0.0, 0.0)


class Pipeline:
    """Runs stages in order in this process, skipping those whose outputs are up to date."""

    planning = False  # True for a pipeline that only lists its stages (then ``splits`` is the split it plans with)

    def __init__(self, workspace: Workspace, log: Callable[[str], None] = lambda line: None, force: bool = False,
                 executor=None):
        self.ws = workspace
        self.force = force
        self.executor = executor  # a dcslam.executor.Executor for run_all; None: local workers (run_all's jobs)
        self.state = workspace.root / ".reproduce"
        self.log = log
        self.timings: dict[str, float] = {}
        self._workers: dict[int, object] = {}  # jobs -> the LocalExecutor whose workers run_all keeps up

    def __enter__(self) -> Pipeline:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """End the local workers that :meth:`run_all` kept up between its calls (as a ``with`` block does)."""
        for executor in self._workers.values():
            executor.close()
        self._workers.clear()

    def _stamp(self, stage: Stage) -> Path:
        return self.state / f"{stage.name}.json"

    def _record(self, stage: Stage) -> dict:
        """``stage.record()`` with paths inside the workspace written relative to it ("<workspace>/slam-long/…"), so
        that a moved or renamed workspace keeps its stages up to date; without a ``jobs`` option (how many processes
        made the outputs is not what they are)."""
        roots = {str(self.ws.root), str(self.ws.root.resolve())}

        def relative(value):
            for root in roots:
                if isinstance(value, str) and (value == root or value.startswith(root + "/")):
                    return "<workspace>" + value[len(root):]
            if isinstance(value, list):
                return [relative(v) for v in value]
            if isinstance(value, dict):
                return {k: relative(v) for k, v in value.items()}
            return value

        record = stage.record()
        record["config"] = {k: v for k, v in record["config"].items() if k != "jobs"}  # never changes the outputs
        return relative(record)

    def up_to_date(self, stage: Stage) -> bool:
        stamp = self._stamp(stage)
        if not stamp.exists():
            return False
        try:
            made = json.loads(stamp.read_text())
        except json.JSONDecodeError:
            return False
        if {k: made.get(k) for k in ("stage", "config", "dcslam")} != self._record(stage) or not made.get("complete"):
            return False
        outputs, inputs = stage.outputs(), stage.inputs()
        if not outputs or not all(p.exists() for p in outputs):
            return False
        return _mtime(outputs)[0] >= _mtime(inputs)[1]

    def foreign_output(self, stage: Stage) -> Path | None:
        """The first existing output of ``stage`` this pipeline did not make (no stamp, or changed after it)."""
        existing = [p for p in stage.outputs() if p.exists()]
        if not existing:
            return None
        stamp = self._stamp(stage)
        if not stamp.exists():
            return existing[0]
        try:
            if not json.loads(stamp.read_text()).get("complete"):
                return None  # this pipeline was interrupted while making them
        except json.JSONDecodeError:
            return existing[0]
        made = stamp.stat().st_mtime
        return next((p for p in existing if p.stat().st_mtime > made), None)

    def run(self, stage: Stage):
        """Run ``stage`` unless it is up to date; returns its result (None when skipped).

        Refuses (:class:`DcslamError`) to overwrite outputs the pipeline did not make unless ``force``.
        """
        if self.up_to_date(stage):
            self.log(f"[skip] {stage.name}: up to date")
            return None
        self.close()  # no idle worker while this process works: a Ctrl-C meant for it would end them with a traceback
        self._claim(stage)
        options = " ".join(f"{k}={v}" for k, v in changed(stage.config).items())
        self.log(f"[run]  {stage.name}: {stage.run.__module__.rsplit('.', 1)[-1]} {options}".rstrip())
        from dcslam.workers import cpu_clock

        start, cpu = time.perf_counter(), cpu_clock()
        try:
            result = stage.run(self.ws, stage.config, force=True)
        except DcslamError as error:
            raise DcslamError(f"stage {stage.name} failed ({error}); fix it and rerun: finished stages will be "
                              "skipped") from None
        self._done(stage, time.perf_counter() - start, cpu_clock() - cpu)
        return result

    def _claim(self, stage: Stage) -> None:
        """Refuse outputs this pipeline did not make (unless ``force``); stamp ``stage`` as running."""
        foreign = None if self.force else self.foreign_output(stage)
        if foreign is not None:
            raise DcslamError(f"stage {stage.name} would overwrite {foreign}, which `dcslam reproduce` did not make; "
                              "move it away or pass --force to overwrite it")
        write_json_atomic(self._stamp(stage), {**self._record(stage), "complete": False})  # claims nothing until done

    def _done(self, stage: Stage, seconds: float, cpu_seconds: float | None) -> None:
        """Stamp ``stage`` as complete with its measured cost: ``seconds`` (wall) and ``cpu_seconds`` (CPU time of
        the process that ran it, and its ended children; None when the executor did not say)."""
        self.timings[stage.name] = seconds
        write_json_atomic(self._stamp(stage), {**self._record(stage), "complete": True, "seconds": seconds,
                                               "cpu_seconds": cpu_seconds})

    def run_all(self, stages: list[Stage], jobs: int = 1) -> None:
        """Run independent ``stages`` (none reads another's outputs) through the pipeline's executor (default: a
        :class:`~dcslam.executor.LocalExecutor` of ``jobs`` worker processes; in this process when ``jobs`` is 1).

        Each stage is stamped as it finishes, so an interrupt keeps the finished ones. A stage that fails stops the
        others (workers terminated, Slurm jobs cancelled) and raises :class:`DcslamError` naming it (and, on Slurm,
        its job and log); it and the stopped ones stay stamped as not complete."""
        from dcslam.executor import LocalExecutor, Task

        todo = []
        for stage in stages:
            if self.up_to_date(stage):
                self.log(f"[skip] {stage.name}: up to date")
            else:
                todo.append(stage)
        if not todo:
            return
        # local workers are kept up between calls (the next round of stages reuses them, without importing torch
        # again) until an in-process stage runs or the pipeline closes
        executor = self.executor or self._workers.setdefault(jobs, LocalExecutor(jobs, keep=True))
        if executor.in_process(len(todo)):
            for stage in todo:
                self.run(stage)
            return
        by_name = {}
        for stage in todo:
            self._claim(stage)
            options = " ".join(f"{k}={v}" for k, v in changed(stage.config).items())
            where = "worker" if isinstance(executor, LocalExecutor) else "job"
            self.log(f"[run]  {stage.name}: {stage.run.__module__.rsplit('.', 1)[-1]} {options} ({where})"
                     if options else f"[run]  {stage.name}: {stage.run.__module__.rsplit('.', 1)[-1]} ({where})")
            by_name[stage.name] = stage
        outcomes = executor.run([Task(s.name, s.run, s.config, self.ws, kind=s.kind) for s in todo])
        try:
            for outcome in outcomes:
                stage = by_name[outcome.task.name]
                if not outcome.ok:
                    details = outcome.task.labels()
                    if outcome.job is not None:
                        details.append(f"Slurm job {outcome.job}" + (f", log {outcome.log}" if outcome.log else ""))
                    raise DcslamError(f"stage {stage.name} failed ({outcome.error})"
                                      f"{''.join(f'; {d}' for d in details)}; fix it and rerun: finished stages will "
                                      "be skipped")
                self._done(stage, outcome.seconds, outcome.cpu_seconds)
        finally:
            outcomes.close()  # stops what is still running when this gave up early
