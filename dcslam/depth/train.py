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
``config.json``, ``curves.png``, overwriting and resuming) is :func:`dcslam.stages.train.train`'s.
Distributed training (DistributedDataParallel) is used when ``torch.distributed`` is initialised: the chunks of
frames of each epoch are dealt out round-robin to the ranks (each rank the same number), rank 0 validates and
writes every file.
"""
from __future__ import annotations

import json
import math
import random
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from dcslam.depth.config import TrainConfig
from dcslam.depth.data import DriveFrames, frame_windows
from dcslam.depth.losses import GeometryTerms, MaskedMSE, batch_depth_errors
from dcslam.depth.maps import MapChamfer
from dcslam.depth.recipes import LR_SCHEDULES, map_frames_of, selection_key
from dcslam.depth.train_pose import pose_loss_of, run_model_with_confidence, validate_pose
from dcslam.depth.models import build_model, model_record, save_model
from dcslam.errors import DcslamError
from dcslam.progress import Bar
from dcslam.io.atomic import atomic_output



def lr_factor(schedule: str, step: int, total: int) -> float:
    """The learning rate of optimisation step ``step`` of ``total``, as a fraction of ``--lr``: ``constant`` 1;
    ``cosine`` 0.5 · (1 + cos(π · step / total)), from 1 down to (almost) 0 at the last step."""
    if schedule == "constant":
        return 1.0
    if schedule == "cosine":
        return 0.5 * (1.0 + math.cos(math.pi * min(step, total) / max(total, 1)))
    raise DcslamError(f"unknown lr schedule {schedule!r}; expected one of {', '.join(LR_SCHEDULES)}")


@dataclass
class TrainResult:
    run_dir: Path
    steps: int
    epochs: int
    best: dict | None
    last_val: dict | None
    model: object = None


def resolve_device(device: str) -> torch.device:
    """``auto`` → the first GPU if there is one, else the CPU."""
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        resolved = torch.device(device)
    except RuntimeError:
        raise DcslamError(f"unknown device {device!r}; expected auto, cpu or cuda") from None
    if resolved.type == "cuda" and not torch.cuda.is_available():
        raise DcslamError("--device cuda, but no GPU is available")
    return resolved


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


def run_model(model, batch):
    """The network's prediction (B, 1, h, w) for a batch: ``model(sparse, mask)``, with ``batch.rgb`` as a third
    argument when the batch carries the colour image (guided networks)."""
    mask = (batch.sparse > 0).to(batch.sparse.dtype)
    return model(batch.sparse, mask) if batch.rgb is None else model(batch.sparse, mask, batch.rgb)


class Objective:
    """The training loss of a configuration: ``objective(pred, batch)`` → scalar; :attr:`parts` holds the terms of
    the last call (pose loss: ``pose``, its mean ``pose_translation_m`` and ``pose_rotation_rad`` per step, and
    ``mse`` / ``chamfer`` when weighted in; with geometry terms (``normal_weight``, ``plane_weight``,
    ``edge_weight``): those of them weighted in, ``normal`` / ``plane`` / ``edge``, beside the loss's own term,
    ``mse`` or ``chamfer``, which they are added to)."""

    def __init__(self, config: TrainConfig, map_builder=None):
        self.loss = config.loss
        self.mse = MaskedMSE(config.mask, config.l1_weight)
        self.chamfer = MapChamfer(config.map_frames, map_builder, config.chamfer_distance)
        self.pose = pose_loss_of(config) if config.loss == "pose" else None
        self.geometry = GeometryTerms(config.normal_weight, config.plane_weight, config.edge_weight)
        self.weights = {"pose": config.pose_weight, "mse": config.mse_weight, "chamfer": config.chamfer_weight}
        self.parts: dict = {}

    def __call__(self, pred, batch, confidence=None):
        """``confidence`` (B, 1, h, w) or None: per-pixel ICP weights of the pose loss."""
        geometry = self.geometry(pred, batch.dense, batch.K)
        if self.loss in ("mse", "chamfer"):
            own = self.mse(pred, batch.sparse, batch.dense) if self.loss == "mse" else \
                self.chamfer(pred, batch.dense, batch.K, batch.T_world_cam)
            if geometry:
                self.parts = {k: float(v.detach()) for k, v in {self.loss: own, **geometry}.items()}
            return own + self.geometry.weighted(geometry)
        pose, details = self.pose(pred, batch.K, batch.T_world_cam, confidence)
        terms = {"pose": pose}
        if self.weights["mse"] > 0:
            terms["mse"] = self.mse(pred, batch.sparse, batch.dense)
        if self.weights["chamfer"] > 0:
            terms["chamfer"] = self.chamfer(pred, batch.dense, batch.K, batch.T_world_cam)
        self.parts = {**{k: float(v.detach()) for k, v in {**terms, **geometry}.items()},
                      "pose_translation_m": float(details["translation_m"].mean()),
                      "pose_rotation_rad": float(details["rotation_rad"].mean()), "pose_rejected": details["rejected"]}
        return sum(self.weights[k] * v for k, v in terms.items()) + self.geometry.weighted(geometry)


def validate(model, drives: list[DriveFrames], map_frames: int, device, map_builder=None,
             geometry: GeometryTerms | None = None) -> dict:
    """The validation pass: no back-propagation, metrics per drive averaged over the drives.

    Returns ``{"chamfer": m², "mse": m², "mae_mm": mm, "rmse_mm": mm}``, and the mean over the windows of each of the
    ``geometry`` terms (``normal``, ``plane``, ``edge``) weighted in; chamfer uses maps of ``map_frames`` frames.
    """
    chamfer = MapChamfer(map_frames, map_builder)
    geometry = geometry or GeometryTerms()
    per_drive = []
    model.eval()
    with torch.no_grad():
        for frames in drives:
            sq, ab, n, chamfers, terms = 0.0, 0.0, 0, [], {t: [] for t in geometry.weights}
            for window in frame_windows(len(frames), map_frames):
                batch = frames.load(window).to(device)
                pred = run_model(model, batch)
                chamfers.append(float(chamfer(pred, batch.dense, batch.K, batch.T_world_cam)))
                for term, value in geometry(pred, batch.dense, batch.K).items():
                    terms[term].append(float(value))
                e = batch_depth_errors(pred, batch.dense)
                if e["pixels"]:
                    sq += e["mse"] * e["pixels"]
                    ab += e["mae_mm"] * e["pixels"]
                    n += e["pixels"]
            if n == 0:
                raise DcslamError(f"validation drive {frames.name} has no ground-truth depth")
            mse = sq / n
            per_drive.append({"chamfer": float(np.mean(chamfers)), "mse": mse, "mae_mm": ab / n,
                              "rmse_mm": math.sqrt(mse) * 1000.0, **{t: float(np.mean(v)) for t, v in terms.items()}})
    model.train()
    return {key: float(np.mean([d[key] for d in per_drive]))
            for key in ("chamfer", "mse", "mae_mm", "rmse_mm", *geometry.weights)}


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


def _read_last(path: Path, model, optimizer) -> dict:
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


def train_loop(run_dir: Path, config: TrainConfig, device, train_frames: list[DriveFrames],
               val_frames: list[DriveFrames],
               resume: bool = False, map_builder=None, rank: int = 0, world: int = 1, on_epoch=None) -> TrainResult:
    """The training of one run (see the module docstring) on opened drives; ``run_dir`` exists.

    Writes ``metrics.jsonl``, ``last.pt`` (after every drive and epoch) and ``model.pt`` (best validation) on rank 0,
    and calls ``on_epoch()`` there after each epoch. With ``resume``, continues from ``last.pt``.
    """
    model = initial_model(config).to(device)
    optimizer = torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    metrics_path = run_dir / "metrics.jsonl"
    epoch, next_chunk, step, best, last_val = 0, 0, 0, None, None
    if resume:
        state = _read_last(run_dir / "last.pt", model, optimizer)
        epoch, next_chunk, step = state["epoch"], state["next_chunk"], state["step"]
        best = json.loads(state["best"]) if state["best"] else None
        if rank == 0:  # drop log lines written after the checkpoint
            lines = metrics_path.read_text().splitlines(keepends=True) if metrics_path.exists() else []
            metrics_path.write_text("".join(lines[:state["metrics_lines"]]))
    elif rank == 0:
        metrics_path.write_text("")

    wrapped = model
    if world > 1:
        from torch.nn.parallel import DistributedDataParallel

        wrapped = DistributedDataParallel(model, device_ids=[device.index] if device.type == "cuda" else None)
    objective = Objective(config, map_builder)
    use_confidence = config.loss == "pose" and config.pose_weights == "confidence" and \
        hasattr(model, "forward_with_confidence")
    if use_confidence and world > 1:
        raise DcslamError("the pose loss with confidence weights runs in one process; pass --pose-weights none or "
                          "--nproc 1")
    chunks = _chunks(train_frames, config.chunk)
    if config.loss == "pose":  # a pose window needs a frame pair
        chunks = [(d, window) for d, window in chunks if len(window) >= 2]
    per_rank = len(chunks) // world
    if per_rank == 0:
        raise DcslamError(f"{len(chunks)} training steps per epoch cannot be shared by {world} processes")
    mine = chunks[rank::world][:per_rank]
    map_frames_val = map_frames_of(config.loss, config.map_frames)
    model.train()

    def checkpoint(epoch_, next_chunk_):
        if rank != 0:
            return
        state = {"model": model_record(model), "optimizer": optimizer.state_dict(), "epoch": epoch_,
                 "next_chunk": next_chunk_, "step": step, "best": json.dumps(best) if best else "",
                 "rng": torch.get_rng_state(), "metrics_lines": len(metrics_path.read_text().splitlines())}
        with atomic_output(run_dir / "last.pt", force=True) as tmp:
            torch.save(state, tmp)

    total = (config.epochs - epoch) * per_rank - next_chunk
    with Bar(f"train {run_dir.name}", total=max(total, 0)) as bar, open(metrics_path, "a") as log:
        def write(row):
            if rank == 0:
                log.write(json.dumps(row) + "\n")
                log.flush()

        while epoch < config.epochs:
            for position in range(next_chunk, per_rank):
                d, window = mine[position]
                batch = train_frames[d].load(window, epoch).to(device)
                for group in optimizer.param_groups:
                    group["lr"] = config.lr * lr_factor(config.lr_schedule, step, config.epochs * per_rank)
                if use_confidence:  # (not through DistributedDataParallel: refused above)
                    pred, confidence = run_model_with_confidence(model, batch)
                    loss = objective(pred, batch, confidence)
                else:
                    loss = objective(run_model(wrapped, batch), batch)
                if not torch.isfinite(loss):
                    raise DcslamError(f"training loss became {float(loss)} at step {step} ({train_frames[d].name})")
                optimizer.zero_grad(set_to_none=True)
                if loss.requires_grad:  # a pose window whose every ICP step was rejected has no gradient
                    loss.backward()
                    optimizer.step()
                write({"kind": "train", "epoch": epoch, "step": step, "drive": train_frames[d].name,
                       "loss": float(loss.detach()), "lr": optimizer.param_groups[0]["lr"], **objective.parts})
                step += 1
                bar.advance(status=f"epoch {epoch} loss {float(loss.detach()):.4g}")
                last_of_drive = position + 1 == per_rank or mine[position + 1][0] != d
                if last_of_drive and position + 1 < per_rank:
                    checkpoint(epoch, position + 1)
            if rank == 0 and val_frames:
                last_val = validate(model, val_frames, map_frames_val, device, map_builder, objective.geometry)
                if objective.pose is not None:
                    last_val.update(validate_pose(model, val_frames, objective.pose, config.pose_frames, device,
                                                  config.pose_weights == "confidence"))
                write({"kind": "val", "epoch": epoch, "step": step, **last_val})
                key = selection_key(config.loss)
                if best is None or last_val[key] < best[key]:
                    best = {**last_val, "epoch": epoch, "step": step}
                    save_model(run_dir / "model.pt", model, meta={"run": run_dir.name, "epoch": epoch, "step": step,
                                                                  "selected_by": key, **last_val,
                                                                  "scale": config.scale, "crop": config.crop})
            elif rank == 0:  # no validation drives: keep the latest weights as the model
                save_model(run_dir / "model.pt", model, meta={"run": run_dir.name, "epoch": epoch, "step": step,
                                                              "selected_by": "last", "scale": config.scale,
                                                              "crop": config.crop})
            epoch, next_chunk = epoch + 1, 0
            checkpoint(epoch, 0)
            if rank == 0 and on_epoch is not None:
                on_epoch()
            barrier()
    return TrainResult(run_dir=run_dir, steps=step, epochs=epoch, best=best, last_val=last_val, model=model)

