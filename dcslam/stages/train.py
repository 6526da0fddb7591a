"""``dcslam train``: train a depth-completion network on the training drives of a workspace into ``runs/<name>/``
(:func:`train` keeps the run folder; the training itself is :func:`dcslam.depth.train.train_loop`).

With ``nproc`` > 1 the run is launched on that many local processes through torchrun (DistributedDataParallel),
each of which runs this module's :func:`main` on the same configuration file.
"""
from __future__ import annotations

import contextlib
import json
from dataclasses import asdict, dataclass
from pathlib import Path

from dcslam.depth.models import ARCHITECTURES
from dcslam.depth.recipes import LOSSES, LR_SCHEDULES, MASKS, POSE_WEIGHTS, check_pose_options, run_name, selection_key
from dcslam.errors import DcslamError
from dcslam.stages.config import option
from dcslam.io.atomic import write_json_atomic
from dcslam.workspace import Workspace, stage_config

MODELS = tuple(ARCHITECTURES)
CORRECTABLE = ("sparse-conv", "nconv", "nconv-guided")  # the networks with a correct_fill option


def _check_kind(kind: str) -> str:
    from dcslam.io.drive import check_input_kind

    return check_input_kind(kind)


@dataclass(frozen=True)
class TrainStageConfig:
    """Options of ``dcslam train`` (the training's own settings are passed on as a
    :class:`dcslam.depth.train.TrainConfig`)."""

    loss: str = option("mse", choices=LOSSES, help="mse, chamfer or pose (relative-pose error of differentiable "
                                                   "ICP over --pose-frames windows).")
    mask: str = option("dense", choices=MASKS, help="MSE mask: dense (pixels with ground truth) or sparse (pixels "
                                                    "with sparse input and ground truth).")
    map_frames: int = option(1, help="Frames per chamfer map: 1, or windows of up to N frames (the thesis: 8; its "
                                     "code: 7).")
    model: str = option("sparse-conv", choices=MODELS, help=f"Network: {' or '.join(MODELS)}.")
    epochs: int = option(1, help="Passes over the training drives.")
    lr: float = option(1e-3, help="AdamW learning rate.")
    weight_decay: float = option(0.01, help="AdamW weight decay.")
    max_frames: int = option(200, help="At most this many frames per drive.")
    stride: int = option(1, help="Use every N-th frame.")
    scale: float = option(1.0, help="Image scale, 1/integer (1, 0.5, 0.25).")
    crop: int = option(0, help="Keep only the bottom N rows (0 = whole image).")
    batch_size: int = option(1, help="Frames per step (MSE and 1-frame chamfer).")
    seed: int = option(0, help="Random seed.")
    device: str = option("auto", help="auto (a GPU if there is one), cpu or cuda.")
    input: str = option("sparse", validate=_check_kind, metavar="KIND",
                        help="Depth fed to the network: sparse (the drive's own), sparse@<beams> (written by "
                             "prepare-kitti --beams), dense or exact.")
    input_mix: list[str] = option(default_factory=list, validate=_check_kind, metavar="KIND",
                                  help="Density augmentation (repeatable): each frame's input drawn in turn from "
                                       "these kinds, e.g. --input-mix sparse --input-mix sparse@32 --input-mix "
                                       "sparse@16 --input-mix sparse@8 (one model for every beam count); replaces "
                                       "--input.")
    target: str = option("dense", validate=_check_kind, metavar="KIND",
                         help="Depth the loss compares with: dense (annotated) or exact (generated drives only).")
    l1_weight: float = option(0.0, help="MSE loss plus this weight times the mean absolute error (metres) over the "
                                        "same pixels (0 = MSE alone, the thesis's).")
    lr_schedule: str = option("constant", choices=LR_SCHEDULES, help="constant, or cosine: from --lr down to 0 over "
                                                                     "all the run's steps.")
    fill_holes: bool = option(False, flags=("--fill-holes/--no-fill-holes",),
                              help="sparse-conv only: fill what lies beyond its receptive field from coarser scales, "
                                   "up to the topmost measured pixel of each column (nothing above it: no sky); off: "
                                   "the paper's network.")
    correct_fill: bool = option(False, flags=("--correct-fill/--no-correct-fill",),
                                help="sparse-conv, nconv, nconv-guided: output a correction of the nearest-neighbour "
                                     "fill of the input, learned from the network's own output (untrained: the "
                                     "fill); off: the network's own depth.")
    name: str | None = option(None, help="Run name (default: mse-dense, mse-sparse, chamfer-1, ...; with another "
                                         "input or target, e.g. mse-dense-sparse16, mse-dense-to-exact).")
    resume: bool = option(False, flags=("--resume",), help="Continue an interrupted run from last.pt.")
    nproc: int = option(1, help="Processes for distributed data-parallel training (launches torchrun).")
    init: str | None = option(None, help="Start from the best model of this run (runs/<INIT>/model.pt): "
                                         "fine-tuning, e.g. --loss pose --init chamfer-8.")
    pose_frames: int = option(4, help="Pose loss: frames per window (the first at its true pose, the others "
                                      "tracked by ICP).")
    pose_weight: float = option(1.0, help="Pose loss: weight of the pose term.")
    mse_weight: float = option(0.0, help="Pose loss: weight of an added MSE term (with --mask).")
    chamfer_weight: float = option(0.0, help="Pose loss: weight of an added chamfer term (with --map-frames).")
    pose_translation_weight: float = option(1.0, help="Pose loss: weight of the translation error (per metre).")
    pose_rotation_weight: float = option(1.0, help="Pose loss: weight of the rotation error (per radian).")
    pose_iterations: int = option(10, help="Pose loss: LM iterations per ICP gate stage.")
    pose_grad_iterations: int = option(0, help="Pose loss: back-propagate through only the last N LM iterations "
                                               "of each stage (0 = all).")
    pose_max_sources: int = option(0, help="Pose loss: align at most N random valid pixels per frame (0 = all).")
    pose_source_voxel: float = option(0.2, help="Pose loss: ICP keeps one source point per voxel of this size, "
                                                "metres (0 = every point).")
    pose_weights: str = option("confidence", choices=POSE_WEIGHTS, help="Pose loss: per-pixel ICP weights: "
                               "confidence (the network's, for nconv models; others have none) or none.")

    def __post_init__(self) -> None:
        for name, choices in (("loss", LOSSES), ("mask", MASKS), ("model", MODELS), ("lr_schedule", LR_SCHEDULES)):
            if getattr(self, name) not in choices:
                raise DcslamError(f"unknown {name} {getattr(self, name)!r}; expected one of {', '.join(choices)}")
        for name in ("map_frames", "epochs", "max_frames", "stride", "batch_size", "nproc"):
            if getattr(self, name) < 1:
                raise DcslamError(f"--{name.replace('_', '-')} must be >= 1, got {getattr(self, name)}")
        if not 0 < self.lr < float("inf"):
            raise DcslamError(f"--lr must be a positive number, got {self.lr}")
        if not 0 <= self.l1_weight < float("inf"):
            raise DcslamError(f"--l1-weight must be a non-negative number, got {self.l1_weight}")
        if self.fill_holes and self.model != "sparse-conv":
            raise DcslamError(f"--fill-holes is an option of sparse-conv, not of {self.model}")
        if self.correct_fill and self.model not in CORRECTABLE:
            raise DcslamError(f"--correct-fill is an option of {', '.join(CORRECTABLE)}, not of {self.model}")
        if not 0 <= self.weight_decay < float("inf"):
            raise DcslamError(f"--weight-decay must be a non-negative number, got {self.weight_decay}")
        if self.name is not None:
            from dcslam.workspace import plain_name

            plain_name(self.name, "--name")
        from dcslam.depth.data import check_view

        check_view(self.scale, self.crop)
        _check_kind(self.input)
        _check_kind(self.target)
        if self.init is not None:
            from dcslam.workspace import plain_name

            plain_name(self.init, "--init")
        check_pose_options(self)
        for kind in self.input_mix:
            _check_kind(kind)

    @property
    def run_name(self) -> str:
        if self.name:
            return self.name
        name = run_name(self.loss, self.mask, self.map_frames, self.init)
        if self.input_mix:
            name += "-mix"
        elif self.input != "sparse":
            name += "-" + self.input.replace("@", "")
        return name + (f"-to-{self.target}" if self.target != "dense" else "")

    def model_hparams(self) -> dict:
        """The network's options that differ from its defaults (recorded in its model file)."""
        return {**({"fill_holes": True} if self.fill_holes else {}),
                **({"correct_fill": True} if self.correct_fill else {})}

    def train_config(self, train_drives: list[Path], val_drives: list[Path], init: Path | None = None):
        """The :class:`dcslam.depth.train.TrainConfig` of this run (``init``: the model file of ``--init``)."""
        from dcslam.depth.train import TrainConfig

        pose = {name: getattr(self, name) for name in POSE_OPTIONS}
        return TrainConfig(**pose, init=str(init) if init else "", loss=self.loss, mask=self.mask,
                           map_frames=self.map_frames, model=self.model, epochs=self.epochs, lr=self.lr,
                           weight_decay=self.weight_decay,
                           max_frames=self.max_frames, stride=self.stride, scale=self.scale, crop=self.crop,
                           batch_size=self.batch_size, seed=self.seed, device=self.device, input=self.input,
                           target=self.target, input_mix=list(self.input_mix), l1_weight=self.l1_weight,
                           lr_schedule=self.lr_schedule,
                           model_hparams=self.model_hparams(),
                           train_drives=train_drives, val_drives=val_drives)


POSE_OPTIONS = ("pose_frames", "pose_weight", "mse_weight", "chamfer_weight", "pose_translation_weight",
                "pose_rotation_weight", "pose_iterations", "pose_grad_iterations", "pose_max_sources",
                "pose_source_voxel", "pose_weights")
RUN_FILES = ("model.pt", "last.pt", "metrics.jsonl", "config.json", "curves.png")


def _check_run_dir(run_dir: Path, force: bool, resume: bool) -> list[str]:
    """The run's files that exist; raises if they may not be overwritten, or if there is nothing to resume."""
    if run_dir.exists() and not run_dir.is_dir():
        raise DcslamError(f"{run_dir} is a file; remove it or choose another --name")
    existing = [name for name in RUN_FILES if (run_dir / name).exists()]
    if resume:
        if not (run_dir / "last.pt").exists():
            raise DcslamError(f"{run_dir / 'last.pt'} not found; nothing to resume (start the run without --resume)")
    elif existing and not force:
        raise DcslamError(f"run {run_dir} exists; pass --force to overwrite it or --resume to continue it")
    return existing


def _prepare_run_dir(run_dir: Path, force: bool, resume: bool) -> None:
    existing = _check_run_dir(run_dir, force, resume)
    if resume:
        return
    for name in existing:
        (run_dir / name).unlink()
    run_dir.mkdir(parents=True, exist_ok=True)


def _discard_unstarted(run_dir: Path, made: bool) -> None:
    """Remove the files of a run that failed before its first epoch (and its folder, if this run ``made`` it)."""
    for name in RUN_FILES:
        (run_dir / name).unlink(missing_ok=True)
    if made:
        with contextlib.suppress(OSError):
            run_dir.rmdir()


RESUMABLE = ("epochs", "device")  # what a resumed run may change: more epochs, another device


def _plain(value):
    return json.loads(json.dumps(value, default=str))


def _saved_config(run_dir: Path, config):
    """On resume: the run's own configuration, with the number of epochs and the device taken from ``config``.

    Raises :class:`DcslamError` naming every other option in which ``config`` differs from the run's."""
    from dcslam.depth.train import TrainConfig

    path = run_dir / "config.json"
    try:
        settings = json.loads(path.read_text())["settings"]
        if not isinstance(settings, dict):
            raise TypeError("settings is not a mapping")
    except (OSError, KeyError, TypeError, json.JSONDecodeError) as exc:
        raise DcslamError(f"{path}: cannot resume from it ({exc})") from None
    known = {k: v for k, v in settings.items() if k in TrainConfig.__dataclass_fields__}
    given = _plain(asdict(config))
    differ = [f"--{k.replace('_', '-')} {given[k]!r} (the run has {known[k]!r})" for k in sorted(known)
              if k not in RESUMABLE and _plain(known[k]) != given.get(k)]
    if differ:
        raise DcslamError(f"cannot resume {run_dir} with other options: {'; '.join(differ)}; resume with the run's "
                          "own options (only --epochs and --device may change), or start again with --force")
    known["epochs"] = config.epochs
    known["device"] = config.device
    return TrainConfig(**known)


def _record_resume(run_dir: Path, config) -> None:
    """Write the resumed run's epochs and device into its ``config.json`` (so it says what the run was trained to)."""
    path = run_dir / "config.json"
    record = json.loads(path.read_text())
    record["settings"]["epochs"], record["settings"]["device"] = config.epochs, config.device
    resumed = stage_config("train --resume", {"epochs": config.epochs, "device": config.device})
    record.setdefault("resumed", []).append({k: resumed[k] for k in ("dcslam_version", "written", "settings")})
    write_json_atomic(path, record)


def train(run_dir: Path | str, config, *, force: bool = False, resume: bool = False, map_builder=None):
    """Train one run (a :class:`dcslam.depth.train.TrainConfig`) into ``run_dir`` and return its
    :class:`dcslam.depth.train.TrainResult`.

    The folder gets ``config.json`` (the settings, resolved device and world size), ``curves.png`` (after every
    epoch) and what :func:`dcslam.depth.train.train_loop` writes. An existing run fails without ``force`` (which
    removes its files first); ``resume`` continues it from ``last.pt`` with its own settings (only the number of
    epochs and the device are taken from ``config``).
    """
    import torch

    from dcslam.depth.data import DriveFrames
    from dcslam.depth.models import is_guided
    from dcslam.io.drive import input_beams
    from dcslam.depth.train import barrier, rank_and_world, resolve_device, seed_all, train_loop
    from dcslam.report.plots import plot_training_curves

    run_dir = Path(run_dir)
    rank, world = rank_and_world()
    device = resolve_device(config.device)  # before the run's folder is made: a missing GPU leaves nothing behind
    made = not run_dir.exists()
    if rank == 0:
        _prepare_run_dir(run_dir, force, resume)
    barrier()
    if resume:
        config = _saved_config(run_dir, config)
    config.check()
    if world > 1 and device.type == "cuda":
        device = torch.device("cuda", rank % torch.cuda.device_count())
    seed_all(config.seed)

    open_drives = []
    try:
        guided = is_guided(config.model)
        train_frames = [DriveFrames(p, config.max_frames, config.stride, config.scale, config.crop, config.input,
                                    config.target, rgb=guided, mix=config.input_mix) for p in config.train_drives]
        open_drives += train_frames
        val_frames = [DriveFrames(p, config.max_frames, config.stride, config.scale, config.crop, config.input,
                                  config.target, rgb=guided, mix=config.input_mix) for p in config.val_drives]
        open_drives += val_frames
        if rank == 0 and not resume:
            settings = asdict(config)
            settings["train_drives"] = [str(p) for p in config.train_drives]
            settings["val_drives"] = [str(p) for p in config.val_drives]
            settings["resolved_device"] = str(device)
            settings["world_size"] = world
            settings["input_beams"] = input_beams(config.input)
            if config.input_mix:
                settings["input_beams"] = [input_beams(kind) for kind in config.input_mix]
            write_json_atomic(run_dir / "config.json", stage_config("train", settings))
        result = train_loop(run_dir, config, device, train_frames, val_frames, resume, map_builder, rank, world,
                            on_epoch=lambda: plot_training_curves(run_dir / "curves.png", run_dir / "metrics.jsonl"))
        if resume and rank == 0:  # only once the epochs are trained
            _record_resume(run_dir, config)
        return result
    except BaseException:
        if rank == 0 and not resume and not (run_dir / "last.pt").exists():
            _discard_unstarted(run_dir, made)  # failed before its first epoch: its rerun must not find "run exists"
        raise
    finally:
        for frames in open_drives:
            frames.close()


def _drive_paths(ws: Workspace, names: list[str]) -> list[Path]:
    from dcslam.workspace import require

    return [require(ws.drives / f"{name}.h5", "dcslam prepare-kitti") for name in names]


def read_result(run_dir: Path):
    """A :class:`dcslam.depth.train.TrainResult` read back from a finished run's ``metrics.jsonl``."""
    from dcslam.depth.train import TrainResult

    metrics = run_dir / "metrics.jsonl"
    if not metrics.exists():
        raise DcslamError(f"{metrics} not found; the distributed run wrote no metrics")
    rows = [json.loads(line) for line in metrics.read_text().splitlines() if line.strip()]
    settings = json.loads((run_dir / "config.json").read_text()).get("settings", {})
    key = selection_key(settings.get("loss"))
    val = [r for r in rows if r["kind"] == "val"]
    best = min(val, key=lambda r: r[key]) if val else None
    return TrainResult(run_dir=run_dir, steps=sum(r["kind"] == "train" for r in rows),
                       epochs=1 + max((r["epoch"] for r in rows), default=-1), best=best,
                       last_val=val[-1] if val else None)


def run(ws: Workspace, config: TrainStageConfig, *, force: bool = False):
    """Train ``config``'s run into ``runs/<name>/``; returns a :class:`dcslam.depth.train.TrainResult` (on every
    rank of a distributed run; only rank 0 writes files)."""
    from dcslam.depth import distributed

    run_dir = ws.runs / config.run_name
    if config.nproc > 1 and not distributed.in_torchrun():
        import tempfile

        _check_run_dir(run_dir, force, config.resume)  # here, not in every worker

        from dcslam.stages.config import to_toml

        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "train.toml"
            path.write_text(to_toml(config))
            args = ["--workspace", str(ws.root), "--config", str(path)] + (["--force"] if force else [])
            code = distributed.launch(config.nproc, "dcslam.stages.train", args)
        if code != 0:
            raise DcslamError(f"distributed training of {run_dir} failed (torchrun exit code {code})")
        return read_result(run_dir)

    from dcslam.depth.train import resolve_device
    from dcslam.io.drive import read_splits

    splits = read_splits(ws.splits)
    init = None
    if config.init:
        from dcslam.workspace import require

        init = require(ws.runs / config.init / "model.pt", f"dcslam train --name {config.init}")
    train_config = config.train_config(_drive_paths(ws, splits["train"]), _drive_paths(ws, splits["val"]), init)
    if distributed.in_torchrun():
        distributed.init_from_env(resolve_device(config.device).type)
    try:
        return train(run_dir, train_config, force=force, resume=config.resume)
    finally:
        distributed.shutdown()


def main(argv: list[str] | None = None) -> int:
    """One process of a distributed run (what torchrun starts): ``--workspace DIR --config FILE [--force]``."""
    import argparse

    from dcslam.stages.config import from_mapping, read_config_file

    parser = argparse.ArgumentParser(prog="python -m dcslam.stages.train")
    parser.add_argument("--workspace", required=True)
    parser.add_argument("--config", required=True)
    parser.add_argument("--force", action="store_true")
    args = parser.parse_args(argv)
    config = from_mapping(TrainStageConfig, read_config_file(args.config), args.config)
    run(Workspace(Path(args.workspace)), config, force=args.force)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
