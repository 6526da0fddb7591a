"""Training a depth-completion network with the thesis's recipes.

Losses: masked MSE (``sparse`` or ``dense`` mask), chamfer between maps of predicted and ground-truth depth built
with ground-truth poses (``map_frames`` frames per map), or the pose loss (:mod:`dcslam.depth.pose`: the relative-pose
error of differentiable frame-to-model ICP over windows of ``pose_frames`` frames, plus optional MSE and chamfer
terms; its loss object, confidence weights and validation pass are in :mod:`dcslam.depth.train_pose`); ``init``
starts from another run's model file (fine-tuning). AdamW (lr 1e-3, weight decay 0.01); at most 200 frames per
drive; the training drives in turn; after each epoch a validation pass without back-propagation averaged over the
validation drives (chamfer, MSE, MAE, RMSE; and the pose error for pose runs); the best validation checkpoint (by the
run's own loss) is kept. Beyond the thesis: an L1
term added to the MSE (``l1_weight``), a cosine learning-rate schedule over the run's steps (``lr_schedule``), and
density augmentation (``input_mix``: each frame's input drawn in turn from several depth kinds, e.g. the sparse
depth of 64, 32, 16 and 8 LiDAR beams; see :class:`dcslam.depth.data.DriveFrames`), and geometry terms added to any
of the losses (``normal_weight``, ``plane_weight``, ``edge_weight``: :class:`dcslam.depth.losses.GeometryTerms`
against the training target, logged and validated beside the loss).

:func:`train_loop` writes into a run folder ``metrics.jsonl`` (one JSON object per training step and per validation),
``model.pt`` (best validation) and ``last.pt`` (resume state, written after every drive); the run folder itself (its
``config.json``, ``curves.png``, overwriting and resuming) is :func:`dcslam.stages.train.train`'s. The loop itself
only takes the steps; the schedule, the metrics file, validation and selection, checkpoints and any added behaviour
(a writer, early stopping) are hooks (:mod:`dcslam.depth.hooks`); the objective and the validation pass are in
:mod:`dcslam.depth.objective`.
Distributed training (DistributedDataParallel) is used when ``torch.distributed`` is initialised: the chunks of
frames of each epoch are dealt out round-robin to the ranks (each rank the same number), rank 0 validates and
writes every file.
"""
from __future__ import annotations

import json
import random
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from dcslam.depth.config import TrainConfig
from dcslam.depth.data import DriveFrames, frame_windows
from dcslam.depth.forward import gives_confidence, run_model, run_model_with_confidence
from dcslam.depth.hooks import Hook, TrainState, default_hooks
from dcslam.depth.models import build_model
from dcslam.depth.objective import Objective
from dcslam.depth.optimizer import adamw
from dcslam.errors import DcslamError
from dcslam.progress import Bar


@dataclass
class TrainResult:
    run_dir: Path
    steps: int
    epochs: int
    best: dict | None
    last_val: dict | None
    model: object = None


def rank_and_world() -> tuple[int, int]:
    """(rank, world size) of the running torch.distributed group, (0, 1) without one."""
    import torch.distributed as dist

    if dist.is_available() and dist.is_initialized():
        return dist.get_rank(), dist.get_world_size()
    return 0, 1


def barrier() -> None:
    import torch.distributed as dist

    if dist.is_available() and dist.is_initialized():
        dist.barrier()


def seed_all(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


def initial_model(config: TrainConfig):
    """A new network of ``config.model``, or, with ``config.init_model``, the network of that model file (which must
    be of the same architecture; its hyperparameters come with it)."""
    if config.init_model is None:
        return build_model(config.model, **config.model_hparams)
    from dcslam.depth.models import model_from_record, read_torch_file

    path = Path(config.init_model)
    if not path.exists():
        raise DcslamError(f"--init model {path} not found; train that run first (`dcslam train --name ...`)")
    record = read_torch_file(path, "model file", "retrain that run with `dcslam train --force`")
    if isinstance(record, dict) and record.get("arch") != config.model:
        raise DcslamError(f"--init {path} is a {record.get('arch')} network, not {config.model}; pass "
                          f"--model {record.get('arch')}")
    return model_from_record(record, str(path))


def _chunks(drives: list[DriveFrames], chunk: int) -> list[tuple[int, range]]:
    """(drive index, frame positions) of every optimisation step of one epoch: drives in turn."""
    return [(d, window) for d, frames in enumerate(drives) for window in frame_windows(len(frames), chunk)]


def read_checkpoint(path: Path, model, optimizer) -> dict:
    """The resume checkpoint ``path``, loaded into ``model`` and ``optimizer``; any broken file is a DcslamError."""
    from dcslam.depth.models import read_torch_file

    fix = "start the run again with --force (without --resume)"
    state = read_torch_file(path, "training checkpoint", fix)
    try:
        model.load_state_dict(state["model"]["state_dict"])
        optimizer.load_state_dict(state["optimizer"])
        json.loads(state["best"] or "null")
        for key in ("epoch", "next_chunk", "step", "metrics_lines"):
            int(state[key])
        torch.set_rng_state(state["rng"])
    except Exception as exc:  # missing keys, wrong shapes or types: the file is not one of this run's checkpoints
        reason = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:160]
        raise DcslamError(f"{path}: not a checkpoint of this run ({type(exc).__name__}: {reason}); {fix}") from None
    return state


def _continue(state: TrainState, checkpoint: dict) -> None:
    """Continue from a resume checkpoint (:func:`read_checkpoint`): its epoch, step, best row and metrics rows."""
    state.epoch, state.start, state.step = checkpoint["epoch"], checkpoint["next_chunk"], checkpoint["step"]
    state.best = json.loads(checkpoint["best"]) if checkpoint["best"] else None
    state.resumed_lines = checkpoint["metrics_lines"]


def _uses_confidence(config: TrainConfig, model) -> bool:
    """Whether the step's loss needs the network's confidence: the pose loss weighting its ICP by it (nconv
    networks with --pose-weights confidence), or a confidence loss (--confidence-weight)."""
    if not gives_confidence(model):
        return False
    return config.confidence_weight > 0 or (config.loss == "pose" and config.pose_weights == "confidence")


def _my_chunks(config: TrainConfig, train_frames: list[DriveFrames], rank: int, world: int) -> list[tuple[int, range]]:
    """This rank's steps of every epoch: the epoch's chunks dealt out round-robin, the same number to each rank."""
    chunks = _chunks(train_frames, config.chunk)
    if config.loss == "pose":  # a pose window needs a frame pair
        chunks = [(d, window) for d, window in chunks if len(window) >= 2]
    per_rank = len(chunks) // world
    if per_rank == 0:
        raise DcslamError(f"{len(chunks)} training steps per epoch cannot be shared by {world} processes")
    return chunks[rank::world][:per_rank]


def _forward(state: TrainState, wrapped, batch) -> torch.Tensor:
    """The step's loss: through the network's confidence for pose runs with confidence weights (one process only:
    not through DistributedDataParallel), else through ``wrapped`` (the network or its DDP wrapper)."""
    if _uses_confidence(state.config, state.model):
        pred, confidence = run_model_with_confidence(state.model, batch)
        return state.objective(pred, batch, confidence)
    return state.objective(run_model(wrapped, batch), batch)


def _train_step(state: TrainState, wrapped) -> None:
    """One optimisation step on chunk ``state.position``; logs its ``train`` row."""
    d, window = state.chunks[state.position]
    frames = state.train_frames[d]
    batch = frames.load(window, state.epoch).to(state.device)
    for hook in state.hooks:
        hook.before_step(state)
    loss = _forward(state, wrapped, batch)
    if not torch.isfinite(loss):
        raise DcslamError(f"training loss became {float(loss)} at step {state.step} ({frames.name})")
    state.optimizer.zero_grad(set_to_none=True)
    if loss.requires_grad:  # a pose window whose every ICP step was rejected has no gradient
        loss.backward()
        state.optimizer.step()
    state.loss = float(loss.detach())
    state.log({"kind": "train", "epoch": state.epoch, "step": state.step, "drive": frames.name, "loss": state.loss,
               "lr": state.optimizer.param_groups[0]["lr"], **state.objective.parts})
    state.step += 1


def _stop_agreed(state: TrainState) -> bool:
    """Rank 0's :attr:`TrainState.stop` on every rank (the hooks that may stop a run run on rank 0)."""
    import torch.distributed as dist

    if not (dist.is_available() and dist.is_initialized()):
        return state.stop
    flag = torch.tensor([int(state.stop)], device=state.device)
    dist.broadcast(flag, src=0)
    return bool(flag.item())


def train_loop(run_dir: Path, config: TrainConfig, device, train_frames: list[DriveFrames],
               val_frames: list[DriveFrames], resume: bool = False, map_builder=None, rank: int = 0, world: int = 1,
               on_epoch=None, hooks: list[Hook] | tuple[Hook, ...] = ()) -> TrainResult:
    """The training of one run (see the module docstring) on opened drives; ``run_dir`` exists.

    Runs the steps of every epoch and, around them, :func:`dcslam.depth.hooks.default_hooks` (``metrics.jsonl``,
    ``last.pt`` after every drive and epoch, ``model.pt`` by validation, ``on_epoch()`` after each epoch: all on rank
    0) followed by ``hooks`` (rank 0 only). With ``resume``, continues from ``last.pt``.
    """
    model = initial_model(config).to(device)
    optimizer = adamw(model.parameters(), config.lr, config.weight_decay)
    checkpoint = read_checkpoint(run_dir / "last.pt", model, optimizer) if resume else None
    if _uses_confidence(config, model) and world > 1:
        raise DcslamError("a loss through the network's confidence (the pose loss with confidence weights, "
                          "--confidence-weight) runs in one process; pass --nproc 1 (or --pose-weights none)")
    state = TrainState(run_dir, config, device, model, optimizer, Objective(config, map_builder), train_frames,
                       val_frames, _my_chunks(config, train_frames, rank, world), rank)
    if checkpoint is not None:
        _continue(state, checkpoint)
    state.hooks = default_hooks(rank, bool(val_frames), map_builder, on_epoch) + (list(hooks) if rank == 0 else [])
    wrapped = model
    if world > 1:
        from torch.nn.parallel import DistributedDataParallel

        wrapped = DistributedDataParallel(model, device_ids=[device.index] if device.type == "cuda" else None)
    model.train()
    total = (config.epochs - state.epoch) * len(state.chunks) - state.start
    with Bar(f"train {run_dir.name}", total=max(total, 0)) as bar:
        for hook in state.hooks:
            hook.before_train(state)
        try:
            while state.epoch < config.epochs and not state.stop:
                for position in range(state.start, len(state.chunks)):
                    state.position = position
                    _train_step(state, wrapped)
                    bar.advance(status=f"epoch {state.epoch} loss {state.loss:.4g}")
                    for hook in state.hooks:
                        hook.after_step(state)
                for hook in state.hooks:
                    hook.after_epoch(state)
                state.epoch, state.start = state.epoch + 1, 0
                barrier()
                state.stop = _stop_agreed(state)
        finally:
            for hook in reversed(state.hooks):
                hook.after_train(state)
    return TrainResult(run_dir=run_dir, steps=state.step, epochs=state.epoch, best=state.best,
                       last_val=state.last_val, model=model)
