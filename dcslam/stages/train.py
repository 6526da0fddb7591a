"""``dcslam train``: train a depth-completion network on the training drives of a workspace into ``runs/<name>/``
(:func:`train` keeps the run folder; the training itself is :func:`dcslam.depth.train.train_loop`).

With ``nproc`` > 1 the run is launched on that many local processes through torchrun (DistributedDataParallel),
each of which runs this module's :func:`main` on the same configuration file.
"""
from __future__ import annotations

import contextlib
import json
import os
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path

from dcslam.depth.config import TrainConfig, TrainSettings, check_choice
from dcslam.depth.models.scaffold import FILL_OUTPUTS, FILLS
from dcslam.depth.recipes import geometry_terms, run_name, selection_key
from dcslam.errors import DcslamError
from dcslam.stages.config import option
from dcslam.io.atomic import write_json_atomic
from dcslam.locks import output_lock
from dcslam.workspace import Workspace, stage_config

CORRECTABLE = ("sparse-conv", "nconv", "nconv-guided")  # the networks with a correct_fill option
CONFIDENT = ("nconv", "nconv-guided")  # the networks whose confidence is their own (a sparse-conv's is its head's)
LOGS = ("jsonl", "tensorboard")  # --log: metrics.jsonl alone, or TensorBoard's event files beside it


@dataclass(frozen=True)
class TrainStageConfig(TrainSettings):
    """Options of ``dcslam train``: the training's settings plus the network's options, the run folder and the
    processes (the run itself is given a :class:`dcslam.depth.config.TrainConfig`)."""

    fill_holes: bool = option(False, flags=("--fill-holes/--no-fill-holes",),
                              help="sparse-conv only: fill what lies beyond its receptive field from coarser scales, "
                                   "up to the topmost measured pixel of each column (nothing above it: no sky); off: "
                                   "the paper's network.")
    correct_fill: bool = option(False, flags=("--correct-fill/--no-correct-fill",),
                                help="sparse-conv, nconv, nconv-guided: output a correction of the nearest-neighbour "
                                     "fill of the input, learned from the network's own output (untrained: the "
                                     "fill); off: the network's own depth.")
    fill: str = option("nearest", choices=FILLS,
                       help="With --correct-fill: what the corrected start is made from: nearest (the nearest-"
                            "neighbour fill of the input), scanline or planefit (the fill of a surface-preserving "
                            "scaffold: that completer's output, its holes taking the nearest scaffold pixel's depth).")
    fill_output: str = option("depth", choices=FILL_OUTPUTS,
                              help="With --correct-fill: depth (the correction is added to the start's depth) or "
                                   "inverse-residual (to its inverse depth, in which a plane is affine in the pixel "
                                   "coordinates).")
    name: str | None = option(None, help="Run name (default: mse-dense, mse-sparse, chamfer-1, ...; with another "
                                         "input or target, e.g. mse-dense-sparse16, mse-dense-to-exact; with "
                                         "geometry terms, e.g. mse-dense-normal-plane).")
    resume: bool = option(False, flags=("--resume",), help="Continue an interrupted run from last.pt.")
    log: str = option("jsonl", choices=LOGS,
                      help="Where the training curves go as the run trains: jsonl (metrics.jsonl, always written) "
                           "or tensorboard (also event files in runs/<name>/tensorboard/, for `tensorboard --logdir "
                           "runs`; needs pip install 'dcslam[tensorboard]').")
    nproc: int = option(1, help="Processes for distributed data-parallel training (launches torchrun).")
    init: str | None = option(None, help="Start from the best model of this run (runs/<INIT>/model.pt): "
                                         "fine-tuning, e.g. --loss pose --init chamfer-8.")

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.nproc < 1:
            raise DcslamError(f"--nproc must be >= 1, got {self.nproc}")
        if self.fill_holes and self.model != "sparse-conv":
            raise DcslamError(f"--fill-holes is an option of sparse-conv, not of {self.model}")
        if self.correct_fill and self.model not in CORRECTABLE:
            raise DcslamError(f"--correct-fill is an option of {', '.join(CORRECTABLE)}, not of {self.model}")
        check_choice(self, "fill", FILLS)
        check_choice(self, "log", LOGS)
        check_choice(self, "fill_output", FILL_OUTPUTS)
        if self.confidence_weight > 0 and not (self.model in CONFIDENT or (self.model == "sparse-conv" and
                                                                          self.correct_fill)):
            raise DcslamError(f"--confidence-weight needs a network that gives a confidence: sparse-conv "
                              f"--correct-fill or {', '.join(CONFIDENT)}, not {self.model}"
                              + (" without --correct-fill" if self.model == "sparse-conv" else ""))
        if (self.fill, self.fill_output) != ("nearest", "depth") and not self.correct_fill:
            raise DcslamError(f"--fill {self.fill} --fill-output {self.fill_output} are options of --correct-fill; "
                              "add --correct-fill")
        from dcslam.workspace import plain_name

        for name in ("name", "init"):
            if getattr(self, name) is not None:
                plain_name(getattr(self, name), f"--{name}")

    @property
    def run_name(self) -> str:
        if self.name:
            return self.name
        name = run_name(self.loss, self.mask, self.map_frames, self.init, self.chamfer_distance)
        if self.input_mix:
            name += "-mix"
        elif self.input != "sparse":
            name += "-" + self.input.replace("@", "")
        name += "".join(f"-{term}" for term in geometry_terms({f.name: getattr(self, f.name) for f in fields(self)}))
        return name + (f"-to-{self.target}" if self.target != "dense" else "")

    def model_hparams(self) -> dict:
        """The network's options that differ from its defaults (recorded in its model file)."""
        return {**({"fill_holes": True} if self.fill_holes else {}),
                **({"correct_fill": True} if self.correct_fill else {}),
                **({"fill": self.fill} if self.fill != "nearest" else {}),
                **({"fill_output": self.fill_output} if self.fill_output != "depth" else {}),
                # a sparse-conv's confidence is its head's gate, trained only by a confidence loss
                **({"confidence": True} if self.confidence_weight > 0 and self.model == "sparse-conv" else {})}

    def train_config(self, train_drives: list[Path], val_drives: list[Path],
                     init_model: Path | None = None) -> TrainConfig:
        """The :class:`dcslam.depth.config.TrainConfig` of this run (``init_model``: the model file of ``--init``)."""
        settings = {f.name: getattr(self, f.name) for f in fields(TrainSettings)}
        return TrainConfig(**settings, model_hparams=self.model_hparams(), train_drives=list(train_drives),
                           val_drives=list(val_drives), init_model=init_model)


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
# config.json records the drives and the model a run starts from relative to the workspace holding the run (the folder
# above runs/<name>/), so that a workspace can be moved or copied and its runs resumed; records without this marker
# (written before) hold paths as they were given
RELATIVE_PATHS = {"paths_relative_to": "workspace"}
SETTING_KEYS = {"init_model": "init"}  # a TrainConfig field recorded under another key


def _plain(value):
    return json.loads(json.dumps(value, default=str))


def workspace_of(run_dir: Path) -> Path:
    """The workspace folder that holds run folder ``run_dir`` (``<workspace>/runs/<name>/``)."""
    return Path(run_dir).parent.parent


def _relative(path: Path | str, root: Path) -> str:
    """``path`` relative to ``root`` where it lies inside it, else the absolute path (no link is followed)."""
    path, root = os.path.abspath(path), os.path.abspath(root)
    return os.path.relpath(path, root) if os.path.commonpath([path, root]) == root else path


def settings_record(config: TrainConfig, run_dir: Path) -> dict:
    """The settings of ``config`` as ``run_dir/config.json`` records them: plain JSON values, ``init_model`` under
    ``init`` ("" for none), paths relative to the run's workspace where they lie inside it."""
    root = workspace_of(run_dir)
    settings = {SETTING_KEYS.get(k, k): v for k, v in _plain(asdict(config)).items()}
    settings["train_drives"] = [_relative(p, root) for p in config.train_drives]
    settings["val_drives"] = [_relative(p, root) for p in config.val_drives]
    settings["init"] = _relative(config.init_model, root) if config.init_model is not None else ""
    return settings


def recorded_config(run_dir: Path) -> TrainConfig:
    """The :class:`dcslam.depth.config.TrainConfig` that ``run_dir/config.json`` records, its paths resolved (relative
    ones against the run's workspace where the record says so); settings it does not hold take their defaults."""
    path = run_dir / "config.json"
    try:
        record = json.loads(path.read_text())
        settings = record["settings"]
        if not isinstance(settings, dict):
            raise TypeError("settings is not a mapping")
    except (OSError, KeyError, TypeError, json.JSONDecodeError) as exc:
        raise DcslamError(f"{path}: cannot resume from it ({exc})") from None
    root = workspace_of(run_dir) if RELATIVE_PATHS.items() <= record.items() else None
    keys = {SETTING_KEYS.get(f.name, f.name): f.name for f in fields(TrainConfig)}
    values = {keys[k]: v for k, v in settings.items() if k in keys}

    def resolve(p) -> Path:
        return Path(p) if root is None or Path(p).is_absolute() else root / p

    for name in ("train_drives", "val_drives"):
        if name in values:
            values[name] = [resolve(p) for p in values[name]]
    if "init_model" in values:
        values["init_model"] = resolve(values["init_model"]) if values["init_model"] else None
    try:
        return TrainConfig(**values)
    except TypeError as exc:
        raise DcslamError(f"{path}: cannot resume from it ({exc})") from None


def _saved_config(run_dir: Path, config: TrainConfig) -> TrainConfig:
    """On resume: the run's own configuration, with the number of epochs and the device taken from ``config``.

    Raises :class:`DcslamError` naming every other option in which ``config`` differs from the run's."""
    saved = recorded_config(run_dir)
    held = json.loads((run_dir / "config.json").read_text())["settings"]
    mine, given = settings_record(saved, run_dir), settings_record(config, run_dir)
    differ = [f"--{k.replace('_', '-')} {given[k]!r} (the run has {mine[k]!r})" for k in sorted(mine)
              if k in held and k not in RESUMABLE and mine[k] != given[k]]
    if differ:
        raise DcslamError(f"cannot resume {run_dir} with other options: {'; '.join(differ)}; resume with the run's "
                          "own options (only --epochs and --device may change), or start again with --force")
    return replace(saved, epochs=config.epochs, device=config.device)


def _record_resume(run_dir: Path, config) -> None:
    """Write the resumed run's epochs and device into its ``config.json`` (so it says what the run was trained to)."""
    path = run_dir / "config.json"
    record = json.loads(path.read_text())
    record["settings"]["epochs"], record["settings"]["device"] = config.epochs, config.device
    resumed = stage_config("train --resume", {"epochs": config.epochs, "device": config.device})
    record.setdefault("resumed", []).append({k: resumed[k] for k in ("dcslam_version", "written", "settings")})
    write_json_atomic(path, record)


def _open_frames(config: TrainConfig, paths: list[Path], opened: list) -> list:
    """The :class:`dcslam.depth.data.DriveFrames` of ``paths`` as ``config`` views them, each appended to ``opened``
    as it opens (the caller closes them)."""
    from dcslam.depth.data import DriveFrames
    from dcslam.depth.models import is_guided

    guided = is_guided(config.model)
    frames = []
    for path in paths:
        frames.append(DriveFrames(path, config.max_frames, config.stride, config.scale, config.crop, config.input,
                                  config.target, rgb=guided, mix=config.input_mix))
        opened.append(frames[-1])
    return frames


def _write_run_config(run_dir: Path, config: TrainConfig, device, world: int) -> None:
    """``config.json`` of a new run: its settings, the resolved device, the world size and the input's beams."""
    from dcslam.io.drive import input_beams

    settings = settings_record(config, run_dir)
    settings["resolved_device"] = str(device)
    settings["world_size"] = world
    settings["input_beams"] = input_beams(config.input)
    if config.input_mix:
        settings["input_beams"] = [input_beams(kind) for kind in config.input_mix]
    write_json_atomic(run_dir / "config.json", {**stage_config("train", settings), **RELATIVE_PATHS})


def train(run_dir: Path | str, config: TrainConfig, *, force: bool = False, resume: bool = False, map_builder=None,
          hooks=()):
    """Train one run (a :class:`dcslam.depth.config.TrainConfig`) into ``run_dir`` and return its
    :class:`dcslam.depth.train.TrainResult`.

    The folder gets ``config.json`` (the settings, resolved device and world size; paths relative to the workspace
    holding ``run_dir``, see :func:`settings_record`), ``curves.png`` (after every epoch) and what
    :func:`dcslam.depth.train.train_loop` writes. An existing run fails without ``force`` (which removes its files
    first); ``resume`` continues it from ``last.pt`` with its own settings (only the number of epochs and the device
    are taken from ``config``). ``hooks``: :class:`dcslam.depth.hooks.Hook` objects added to the loop's own.
    """
    from dcslam.depth.train import rank_and_world
    from dcslam.device import resolve_device

    run_dir = Path(run_dir)
    rank, world = rank_and_world()
    device = resolve_device(config.device)  # before the run's folder is made: a missing GPU leaves nothing behind
    # one writer at a time, from before --force removes the run's files to the end; the processes of a distributed
    # run are one writer, whose launcher (:func:`run`) holds the lock
    with output_lock(run_dir, "run") if world == 1 else contextlib.nullcontext():
        return _train(run_dir, config, device, force, resume, map_builder, hooks)


def _train(run_dir: Path, config: TrainConfig, device, force: bool, resume: bool, map_builder, hooks):
    """:func:`train` with the run's lock held."""
    import torch

    from dcslam.depth.train import barrier, rank_and_world, seed_all, train_loop
    from dcslam.report.plots import plot_training_curves

    rank, world = rank_and_world()
    made = not run_dir.exists()
    if rank == 0:
        _prepare_run_dir(run_dir, force, resume)
    barrier()
    if resume:
        config = _saved_config(run_dir, config)
    if not config.train_drives:
        raise DcslamError("no training drives; run `dcslam prepare-kitti` (or `dcslam synth`) first")
    if world > 1 and device.type == "cuda":
        device = torch.device("cuda", rank % torch.cuda.device_count())
    seed_all(config.seed)

    open_drives = []
    try:
        train_frames = _open_frames(config, config.train_drives, open_drives)
        val_frames = _open_frames(config, config.val_drives, open_drives)
        if rank == 0 and not resume:
            _write_run_config(run_dir, config, device, world)
        result = train_loop(run_dir, config, device, train_frames, val_frames, resume, map_builder, rank, world,
                            on_epoch=lambda: plot_training_curves(run_dir / "curves.png", run_dir / "metrics.jsonl"),
                            hooks=hooks)
        if resume and rank == 0:  # only once the epochs are trained
            _record_resume(run_dir, config)
        return result
    except BaseException as exc:
        if rank == 0 and not resume and not (run_dir / "last.pt").exists():
            _discard_unstarted(run_dir, made)  # failed before its first epoch: its rerun must not find "run exists"
        elif rank == 0 and isinstance(exc, KeyboardInterrupt):
            from dcslam import interrupt

            interrupt.keep(f"the run folder {run_dir} is kept with last.pt (the last saved point of the training); "
                           "continue it with the same command and --resume, or start again with --force")
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


def log_hooks(log: str) -> list:
    """The hooks of ``--log``: none for ``jsonl`` (the loop writes metrics.jsonl itself), a
    :class:`dcslam.depth.hooks.TensorBoardLog` for ``tensorboard``; a missing package fails here, before any work."""
    if log != "tensorboard":
        return []
    import importlib.util

    if importlib.util.find_spec("tensorboard") is None:
        from dcslam.depth.tensorboard import INSTALL

        raise DcslamError(f"--log tensorboard needs the tensorboard package: {INSTALL}")
    from dcslam.depth.hooks import TensorBoardLog

    return [TensorBoardLog()]


def run(ws: Workspace, config: TrainStageConfig, *, force: bool = False):
    """Train ``config``'s run into ``runs/<name>/``; returns a :class:`dcslam.depth.train.TrainResult` (on every
    rank of a distributed run; only rank 0 writes files)."""
    from dcslam.depth import distributed

    run_dir = ws.runs / config.run_name
    hooks = log_hooks(config.log)  # a missing package fails before any work
    if config.nproc > 1 and not distributed.in_torchrun():
        import tempfile

        from dcslam.stages.config import to_toml

        with output_lock(run_dir, "run"), tempfile.TemporaryDirectory() as tmp:
            _check_run_dir(run_dir, force, config.resume)  # here, not in every worker
            path = Path(tmp) / "train.toml"
            path.write_text(to_toml(config))
            args = ["--workspace", str(ws.root), "--config", str(path)] + (["--force"] if force else [])
            code = distributed.launch(config.nproc, "dcslam.stages.train", args)
        if code != 0:
            raise DcslamError(f"distributed training of {run_dir} failed (torchrun exit code {code})")
        return read_result(run_dir)

    from dcslam.device import resolve_device
    from dcslam.io.drive import read_splits

    splits = read_splits(ws.splits)
    init = None
    if config.init is not None:
        from dcslam.workspace import require

        init = require(ws.runs / config.init / "model.pt", f"dcslam train --name {config.init}")
    train_config = config.train_config(_drive_paths(ws, splits["train"]), _drive_paths(ws, splits["val"]), init)
    if distributed.in_torchrun():
        distributed.init_from_env(resolve_device(config.device).type)
    try:
        return train(run_dir, train_config, force=force, resume=config.resume, hooks=hooks)
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
