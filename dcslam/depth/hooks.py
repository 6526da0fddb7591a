"""The training loop's hooks (:func:`dcslam.depth.train.train_loop`): everything a run does besides its steps.

The loop runs the optimisation steps of each epoch and calls, in the order of its list of hooks,
``before_train`` once, ``before_step`` / ``after_step`` around every step, ``after_epoch`` after every epoch and
``after_train`` once at the end (also when training stops on an exception: it releases what ``before_train`` took).
Every hook reads and updates one :class:`TrainState`. Metrics rows (one per training step and per validation) go
through :meth:`TrainState.log` to every hook's :meth:`Hook.write`, so a writer is a hook that overrides ``write``.

The hooks of a run (:func:`default_hooks`), in order: :class:`LRSchedule` (every rank), then on rank 0 only
:class:`MetricsJsonl` (``metrics.jsonl``), :class:`Validation` (validation pass, best-checkpoint selection,
``model.pt``) or :class:`KeepLatest` without validation drives, :class:`Checkpointer` (``last.pt``), and
:class:`EpochCallback`. A new writer (e.g. TensorBoard) or early stopping (set :attr:`TrainState.stop` in
``after_epoch``) is one more :class:`Hook` passed to ``train_loop(hooks=[...])``; such extra hooks run on rank 0, after
the run's own.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import torch

from dcslam.depth.config import TrainConfig
from dcslam.depth.data import DriveFrames
from dcslam.depth.models import model_record, save_model, save_torch
from dcslam.depth.objective import Objective, validate
from dcslam.depth.recipes import LR_SCHEDULES, map_frames_of, selection_key
from dcslam.depth.train_pose import validate_pose
from dcslam.errors import DcslamError


@dataclass
class TrainState:
    """What the loop and its hooks share. ``chunks`` are this rank's optimisation steps of every epoch, (drive index,
    frame positions); ``position`` indexes them (the next step's, or after a step the one just taken) and ``start`` is
    where the current epoch began (a resumed run starts mid-epoch). ``step`` counts the steps taken, ``loss`` is the
    last step's; ``best`` is the selected validation row, ``last_val`` the latest; ``resumed_lines`` is, on resume,
    the number of metrics rows that ``last.pt`` covers (None for a fresh run). A hook sets ``stop`` in
    ``after_epoch`` to end the run after that epoch."""

    run_dir: Path
    config: TrainConfig
    device: torch.device
    model: torch.nn.Module  # the network itself, not its DistributedDataParallel wrapper
    optimizer: torch.optim.Optimizer
    objective: Objective
    train_frames: list[DriveFrames]
    val_frames: list[DriveFrames]
    chunks: list[tuple[int, range]]
    rank: int = 0
    hooks: list[Hook] = field(default_factory=list)
    epoch: int = 0
    start: int = 0
    position: int = 0
    step: int = 0
    loss: float = math.nan
    best: dict | None = None
    last_val: dict | None = None
    resumed_lines: int | None = None
    stop: bool = False

    @property
    def total_steps(self) -> int:
        """The optimisation steps of the whole run on this rank."""
        return self.config.epochs * len(self.chunks)

    def log(self, row: dict) -> None:
        """Hand one metrics row to every hook's :meth:`Hook.write`."""
        for hook in self.hooks:
            hook.write(self, row)


class Hook:
    """A behaviour of the training loop; every method does nothing unless overridden (see the module docstring)."""

    def before_train(self, state: TrainState) -> None:
        pass

    def before_step(self, state: TrainState) -> None:
        pass

    def after_step(self, state: TrainState) -> None:
        pass

    def after_epoch(self, state: TrainState) -> None:
        pass

    def after_train(self, state: TrainState) -> None:
        pass

    def write(self, state: TrainState, row: dict) -> None:
        """One metrics row: ``{"kind": "train" | "val", "epoch", "step", ...}``."""


def lr_factor(schedule: str, step: int, total: int) -> float:
    """The learning rate of optimisation step ``step`` of ``total``, as a fraction of ``--lr``: ``constant`` 1;
    ``cosine`` 0.5 · (1 + cos(π · step / total)), from 1 down to (almost) 0 at the last step."""
    if schedule == "constant":
        return 1.0
    if schedule == "cosine":
        return 0.5 * (1.0 + math.cos(math.pi * min(step, total) / max(total, 1)))
    raise DcslamError(f"unknown lr schedule {schedule!r}; expected one of {', '.join(LR_SCHEDULES)}")


class LRSchedule(Hook):
    """Sets the learning rate of every step: ``--lr`` times :func:`lr_factor` of ``--lr-schedule``."""

    def before_step(self, state: TrainState) -> None:
        lr = state.config.lr * lr_factor(state.config.lr_schedule, state.step, state.total_steps)
        for group in state.optimizer.param_groups:
            group["lr"] = lr


class MetricsJsonl(Hook):
    """``metrics.jsonl``: one JSON object per row, flushed as written. A fresh run starts it empty; a resumed one
    drops the rows written after its checkpoint."""

    def __init__(self) -> None:
        self._file = None

    def before_train(self, state: TrainState) -> None:
        path = state.run_dir / "metrics.jsonl"
        if state.resumed_lines is None:
            path.write_text("")
        else:
            lines = path.read_text().splitlines(keepends=True) if path.exists() else []
            path.write_text("".join(lines[:state.resumed_lines]))
        self._file = open(path, "a")

    def write(self, state: TrainState, row: dict) -> None:
        self._file.write(json.dumps(row) + "\n")
        self._file.flush()

    def after_train(self, state: TrainState) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None


def _model_meta(state: TrainState, selected_by: str, val: dict) -> dict:
    return {"run": state.run_dir.name, "epoch": state.epoch, "step": state.step, "selected_by": selected_by, **val,
            "scale": state.config.scale, "crop": state.config.crop}


class Validation(Hook):
    """After every epoch: the validation pass (:func:`dcslam.depth.objective.validate`, and the pose loss's for pose
    runs) logged as a ``val`` row; ``model.pt`` is rewritten when the run's own loss
    (:func:`dcslam.depth.recipes.selection_key`) beats the best so far. ``map_builder``: the chamfer's map builder."""

    def __init__(self, map_builder=None) -> None:
        self.map_builder = map_builder

    def after_epoch(self, state: TrainState) -> None:
        config, objective = state.config, state.objective
        val = validate(state.model, state.val_frames, map_frames_of(config.loss, config.map_frames), state.device,
                       self.map_builder, objective.geometry)
        if objective.pose is not None:
            val.update(validate_pose(state.model, state.val_frames, objective.pose, config.pose_frames, state.device,
                                     config.pose_weights == "confidence"))
        state.last_val = val
        state.log({"kind": "val", "epoch": state.epoch, "step": state.step, **val})
        key = selection_key(config.loss)
        if state.best is None or val[key] < state.best[key]:
            state.best = {**val, "epoch": state.epoch, "step": state.step}
            save_model(state.run_dir / "model.pt", state.model, meta=_model_meta(state, key, val))


class KeepLatest(Hook):
    """Without validation drives: ``model.pt`` holds the latest epoch's weights."""

    def after_epoch(self, state: TrainState) -> None:
        save_model(state.run_dir / "model.pt", state.model, meta=_model_meta(state, "last", {}))


class Checkpointer(Hook):
    """``last.pt``, the resume state (:func:`dcslam.depth.train.read_checkpoint` reads it): written after the last
    step of each drive within an epoch and after every epoch, so an interrupted run loses at most one drive."""

    def after_step(self, state: TrainState) -> None:
        following = state.position + 1
        if following < len(state.chunks) and state.chunks[following][0] != state.chunks[state.position][0]:
            self.save(state, state.epoch, following)

    def after_epoch(self, state: TrainState) -> None:
        self.save(state, state.epoch + 1, 0)

    @staticmethod
    def save(state: TrainState, epoch: int, next_chunk: int) -> None:
        """Resume at step ``next_chunk`` of epoch ``epoch``."""
        metrics = state.run_dir / "metrics.jsonl"
        checkpoint = {"model": model_record(state.model), "optimizer": state.optimizer.state_dict(), "epoch": epoch,
                      "next_chunk": next_chunk, "step": state.step,
                      "best": json.dumps(state.best) if state.best else "", "rng": torch.get_rng_state(),
                      "metrics_lines": len(metrics.read_text().splitlines()) if metrics.exists() else 0}
        save_torch(state.run_dir / "last.pt", checkpoint)


class EpochCallback(Hook):
    """Calls ``callback()`` after every epoch (e.g. redraw the training curves)."""

    def __init__(self, callback) -> None:
        self.callback = callback

    def after_epoch(self, state: TrainState) -> None:
        self.callback()


class TensorBoardLog(Hook):
    """The metrics rows also as TensorBoard event files in ``<run>/tensorboard/`` (``dcslam train --log tensorboard``;
    needs the ``tensorboard`` package), written as they come so the curves can be watched while the run trains. A
    fresh run starts the folder empty; a resumed one drops the events after its checkpoint."""

    FOLDER = "tensorboard"

    def __init__(self) -> None:
        self._writer = None

    def before_train(self, state: TrainState) -> None:
        from dcslam.depth.tensorboard import TensorBoardWriter

        log_dir = state.run_dir / self.FOLDER
        if state.resumed_lines is None and log_dir.is_dir():
            for old in log_dir.glob("events.out.tfevents.*"):
                old.unlink()
        self._writer = TensorBoardWriter(log_dir, purge_step=None if state.resumed_lines is None else state.step)

    def write(self, state: TrainState, row: dict) -> None:
        self._writer.write(row)

    def after_train(self, state: TrainState) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None


def default_hooks(rank: int, validation: bool, map_builder=None, on_epoch=None) -> list[Hook]:
    """The hooks of a run on process ``rank``: the schedule everywhere; files, validation and ``on_epoch`` on rank 0
    (``validation``: whether the run has validation drives)."""
    if rank != 0:
        return [LRSchedule()]
    selection = Validation(map_builder) if validation else KeepLatest()
    return [LRSchedule(), MetricsJsonl(), selection, Checkpointer(),
            *([EpochCallback(on_epoch)] if on_epoch is not None else [])]
