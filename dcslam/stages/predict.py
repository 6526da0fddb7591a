"""``dcslam predict``: complete the sparse depth of drives with a trained run or a classical completer, writing one
prediction layer per drive under ``predictions/<name>/`` (the name is the run's, or the completer's registered
name: ``--model ip-basic`` writes ``predictions/ip-basic-fast/``, the layer ``score tables`` looks for)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dcslam.depth.models import ALIASES, CLASSICAL
from dcslam.errors import DcslamError
from dcslam.stages.config import option
from dcslam.workspace import Workspace

SPLITS = ("train", "val", "test")


@dataclass(frozen=True)
class PredictConfig:
    """Options of ``dcslam predict``."""

    run: str | None = option(None, help=f"Run name under runs/ (or a completer: {', '.join(CLASSICAL)}).")
    model: str | None = option(None, choices=(*ALIASES, *CLASSICAL),
                               help=f"A completer that needs no run folder: {', '.join([*ALIASES, *CLASSICAL])}.")
    split: str = option("test", choices=SPLITS, help="Split whose drives to predict (train, val, test).")
    drive: list[Path] = option(default_factory=list, help="Drive file(s) to predict instead of a split.")
    output: Path | None = option(None, help="Output folder (default predictions/<run>/).")
    device: str = option("auto", help="auto, cpu or cuda.")

    def __post_init__(self) -> None:
        if (self.run is None) == (self.model is None):
            raise DcslamError("give one of --run NAME or --model " + "|".join([*ALIASES, *CLASSICAL]))
        if self.split not in SPLITS:
            raise DcslamError(f"unknown split {self.split!r}; expected train, val or test")


@dataclass
class PredictResult:
    out_dir: Path
    layers: list[Path]
    made_by: str


def run_predictor(run_dir: Path | str, device):
    """The best model of a training run (``runs/<run>/model.pt``), with the run's scale, as a
    :class:`dcslam.depth.predict.Predictor`."""
    import json

    from dcslam.depth.models import load_model
    from dcslam.depth.predict import NetworkCompleter, Predictor

    run_dir = Path(run_dir)
    model, meta = load_model(run_dir / "model.pt", device=str(device))
    scale = float(meta.get("scale", 1.0))
    config = {"run": run_dir.name, "model_file": str(run_dir / "model.pt"), "arch": model.ARCH,
              "hparams": model.hparams, "scale": scale,
              "checkpoint": {k: meta[k] for k in ("epoch", "step") if k in meta}}
    config_path = run_dir / "config.json"
    if config_path.exists():
        config["train_settings"] = json.loads(config_path.read_text()).get("settings", {})
    return Predictor(NetworkCompleter(model, device, scale, run_dir.name), run_dir.name, config)


def predict_drive(predictor, drive_path: Path | str, out_path: Path | str, force: bool = False,
                  progress: bool = True) -> Path:
    """Complete every frame's sparse depth of a drive and write the layer ``out_path`` atomically.

    The layer holds ``depth`` (N, H, W) float32 metres, the same frames as the drive.
    """
    from dcslam.io.drive import DriveFile, Layer, write_layer
    from dcslam.progress import track

    out_path = Path(out_path)
    if out_path.exists() and not force:
        raise DcslamError(f"{out_path} exists; pass --force to overwrite it")
    with DriveFile(drive_path) as drive:
        n, h, w = drive.shape
        depth = np.zeros((n, h, w), np.float32)
        frames = range(n)
        for i in (track(frames, f"predict {drive.name}") if progress else frames):
            depth[i] = predictor.completer(drive.depth("sparse", i))
        layer = Layer(depth=depth, drive=drive.path.name, made_by=predictor.made_by,
                      config={**predictor.config, "drive_file": str(drive.path)})
    return write_layer(out_path, layer, force=force)


def predictor(ws: Workspace, config: PredictConfig):
    """The :class:`dcslam.depth.predict.Predictor` of ``config`` (a classical completer, or a run's best model)."""
    from dcslam.depth.models import classical_name
    from dcslam.depth.predict import classical_predictor
    from dcslam.depth.train import resolve_device
    from dcslam.workspace import require

    name = config.model or config.run
    if classical_name(name) is not None:
        return classical_predictor(name)
    return run_predictor(require(ws.runs / name, "dcslam train"), resolve_device(config.device))


def run(ws: Workspace, config: PredictConfig, *, force: bool = False) -> PredictResult:
    """Write ``<out>/<drive>.h5`` for every drive of the split (or ``config.drive``); nothing is overwritten without
    ``force`` (checked before any work)."""
    from dcslam.io.drive import read_splits
    from dcslam.workspace import output_folder, require

    chosen = predictor(ws, config)
    if config.drive:
        paths = list(config.drive)
    else:
        splits = read_splits(ws.splits)
        paths = [require(ws.drives / f"{name}.h5", "dcslam prepare-kitti") for name in splits[config.split]]
        if not paths:
            raise DcslamError(f"split {config.split!r} of {ws.splits} has no drives")
    out_dir = output_folder(config.output or ws.predictions / chosen.made_by, "--output")
    outputs = [out_dir / Path(p).name for p in paths]
    existing = [p for p in outputs if p.exists()]
    if existing and not force:
        raise DcslamError(f"{existing[0]} exists; pass --force to overwrite it")
    from dcslam.io.atomic import AtomicSet

    out_dir.mkdir(parents=True, exist_ok=True)
    with AtomicSet() as files:  # the layers appear together: Ctrl-C or a bad drive leaves none of them
        for path, out in zip(paths, outputs):
            predict_drive(chosen, path, files.stage(out), force=True)
    from dcslam.stages.config import to_dict
    from dcslam.io.atomic import write_json_atomic
    from dcslam.workspace import stage_config

    write_json_atomic(out_dir / "config.json", stage_config("predict", {**to_dict(config), "made_by": chosen.made_by}),
                      force=True)
    return PredictResult(out_dir, outputs, chosen.made_by)
