"""``dcslam predict``: complete the sparse depth of drives with a trained run or a classical completer, writing one
prediction layer per drive under ``predictions/<name>/`` (the name is the run's, or the completer's registered
name: ``--model ip-basic`` writes ``predictions/ip-basic-fast/``, the layer ``score tables`` looks for)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dcslam.depth.models import ALIASES, CLASSICAL
from dcslam.errors import DcslamError
from dcslam.io.drive import check_input_kind
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
    output: Path | None = option(None, flags=("--out",), aliases=("--output",),
                                 help="Output folder (default predictions/<run>/, or predictions/<run>-"
                                      "sparse16/ for --input sparse@16).")
    device: str = option("auto", help="auto, cpu or cuda.")
    input: str | None = option(None, validate=lambda kind: check_input_kind(kind), metavar="KIND",
                               show_default="the run's training input, else sparse",
                               help="Depth to complete: sparse, or sparse@<beams> (written by prepare-kitti --beams).")

    def __post_init__(self) -> None:
        if (self.run is None) == (self.model is None):
            raise DcslamError("give one of --run NAME or --model " + "|".join([*ALIASES, *CLASSICAL]))
        if self.split not in SPLITS:
            raise DcslamError(f"unknown split {self.split!r}; expected train, val or test")
        if self.input is not None:
            check_input_kind(self.input)


@dataclass
class PredictResult:
    out_dir: Path
    layers: list[Path]
    made_by: str
    empty_share: float | None = None  # share of all the layers' pixels left without depth


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
        check_architecture(run_dir, model.ARCH, config["train_settings"])
    return Predictor(NetworkCompleter(model, device, scale, run_dir.name), run_dir.name, config)


def check_architecture(run_dir: Path, arch: str, settings: dict) -> None:
    """Refuse a run whose ``model.pt`` holds another network than its ``config.json`` says it trained (a model file
    copied in from another run would be used under this run's name)."""
    trained = settings.get("model") if isinstance(settings, dict) else None
    if trained and str(trained) != arch:
        raise DcslamError(f"{run_dir / 'model.pt'} holds a {arch} network but {run_dir / 'config.json'} says the run "
                          f"trained {trained}; put the run's own model back or retrain it with `dcslam train "
                          f"--name {run_dir.name} --force`")


def predict_drive(predictor, drive_path: Path | str, out_path: Path | str, force: bool = False,
                  progress: bool = True, input: str = "sparse") -> Path:
    """Complete every frame's depth of kind ``input`` (``sparse``, ``sparse@16``, ...) of a drive and write the layer
    ``out_path`` atomically.

    The layer holds ``depth`` (N, H, W) float32 metres, the same frames as the drive (and ``confidence`` when the
    completer gives one); its configuration records the input kind and its LiDAR beams (``input``,
    ``input_beams``), and ``empty_share``, the share of its pixels left without depth (completers that leave a
    pixel empty rather than guess say how much they left).
    """
    from dcslam.io.drive import DriveFile, Layer, input_beams, write_layer
    from dcslam.progress import track

    out_path = Path(out_path)
    if out_path.exists() and not force:
        raise DcslamError(f"{out_path} exists; pass --force to overwrite it")
    with DriveFile(drive_path) as drive:
        n, h, w = drive.shape
        depth = np.zeros((n, h, w), np.float32)
        with_confidence = getattr(predictor.completer, "has_confidence", False)
        confidence = np.zeros((n, h, w), np.float32) if with_confidence else None
        frames = range(n)
        for i in (track(frames, f"predict {drive.name}") if progress else frames):
            if with_confidence:
                rgb = drive.rgb(i) if getattr(predictor.completer, "guided", False) else None
                depth[i], confidence[i] = predictor.completer.complete(drive.depth(input, i), rgb)
            else:
                depth[i] = predictor.completer(drive.depth(input, i))
        layer = Layer(depth=depth, confidence=confidence, drive=drive.path.name, frame_ids=drive.frame_ids,
                      made_by=predictor.made_by,
                      config={**predictor.config, "drive_file": str(drive.path), "input": input,
                              "input_beams": input_beams(input), "empty_share": float((depth == 0).mean())})
    return write_layer(out_path, layer, force=force)


def predictor(ws: Workspace, config: PredictConfig):
    """The :class:`dcslam.depth.predict.Predictor` of ``config`` (a classical completer, or a run's best model)."""
    from dcslam.depth.models import classical_name
    from dcslam.depth.predict import classical_predictor
    from dcslam.device import resolve_device
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
    kind = config.input or chosen.config.get("train_settings", {}).get("input", "sparse")
    trained_on = chosen.config.get("train_settings", {}).get("input", "sparse")
    suffix = "" if kind == trained_on else "-" + kind.replace("@", "")
    out_dir = output_folder(config.output or ws.predictions / f"{chosen.made_by}{suffix}", "--out")
    outputs = [out_dir / Path(p).name for p in paths]
    from dcslam.locks import output_lock

    with output_lock(out_dir, "layer"):  # before anything is checked, removed or written: one writer at a time
        empty = _write_layers(ws, config, chosen, kind, paths, out_dir, outputs, force)
    return PredictResult(out_dir, outputs, chosen.made_by, empty)


def _write_layers(ws: Workspace, config: PredictConfig, chosen, kind: str, paths: list, out_dir: Path,
                  outputs: list[Path], force: bool) -> float | None:
    """Write the layers and ``config.json`` (with the identity of the model they were predicted by, under
    ``made_from``); returns the share of their pixels left empty."""
    existing = [p for p in outputs if p.exists()]
    if existing and not force:
        raise DcslamError(f"{existing[0]} exists; pass --force to overwrite it")
    from dcslam.io.atomic import AtomicSet
    from dcslam.io.drive import DriveFile
    from dcslam.workspace import new_folder

    for path in paths:  # every input checked before the output folder is made
        with DriveFile(path) as drive:
            if len(drive):
                drive.depth(kind, 0)  # a kind the drive lacks: one line naming it and how to write it
    empty, pixels = 0.0, 0
    with new_folder(out_dir), AtomicSet() as files:  # the layers appear together: Ctrl-C or a bad drive leaves none
        for path, out in zip(paths, outputs):
            share, size = _empty_share(predict_drive(chosen, path, files.stage(out), force=True, input=kind))
            empty, pixels = empty + share * size, pixels + size
    from dcslam.io.atomic import write_json_atomic
    from dcslam.io.lineage import MADE_FROM, made_from
    from dcslam.stages.config import to_dict
    from dcslam.workspace import stage_config

    model_file = chosen.config.get("model_file")
    record = stage_config("predict", {**to_dict(config), "made_by": chosen.made_by, "input": kind})
    record[MADE_FROM] = made_from({"model": Path(model_file) if model_file else None}, out_dir)
    write_json_atomic(out_dir / "config.json", record, force=True)
    return empty / pixels if pixels else None


def _empty_share(layer_path: Path) -> tuple[float, int]:
    """The ``empty_share`` a layer's configuration records and its pixel count, without reading its depth."""
    import json

    import h5py

    with h5py.File(layer_path, "r") as h5:
        return float(json.loads(h5.attrs["config"])["empty_share"]), int(np.prod(h5["depth"].shape))
