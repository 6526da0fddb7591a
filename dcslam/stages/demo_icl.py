"""``dcslam demo-icl``: the thesis's appendix C.2 experiment, depth denoising learnt through the map.

The data are ``drives`` (a drive file, or a folder with splits.json), else indoor rooms generated in the ICL-NUIM
layout and prepared under ``<workspace>/demo-icl/`` (kept for the next run; the last room is held out). The
experiment (:func:`run_denoising`; the algorithm in :mod:`dcslam.depth.denoise`) writes
``<workspace>/results/demo-icl/``.
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, fields
from pathlib import Path

from dcslam.depth.config import DenoiseConfig, DenoiseSettings
from dcslam.errors import DcslamError
from dcslam.stages.config import option
from dcslam.io.atomic import write_json_atomic, write_text_atomic
from dcslam.workspace import Workspace, stage_config

OUTPUT_FILES = ("model.pt", "results.json", "results.csv", "results.md", "denoising.png")


@dataclass(frozen=True)
class DemoIclConfig(DenoiseSettings):
    """Options of ``dcslam demo-icl``: the experiment's settings plus the data it runs on."""

    frames: int = option(30, help="Frames per generated sequence.")
    sequences: int = option(4, help="Generated sequences (rooms); the last one is held out.")
    drives: Path | None = option(None, help="A drive file or a folder of drive files with splits.json, instead of "
                                            "generated rooms.")

    def denoise_config(self, train_drives: list | None = None, test_drives: list | None = None) -> DenoiseConfig:
        """The :class:`dcslam.depth.config.DenoiseConfig` of this run."""
        settings = {f.name: getattr(self, f.name) for f in fields(DenoiseSettings)}
        return DenoiseConfig(**settings, train_drives=list(train_drives or []), test_drives=list(test_drives or []))


@dataclass
class DenoiseResult:
    out_dir: Path
    table: object               # a dcslam.report.tables.Table
    scores: dict
    losses: list
    seconds: float


def run_denoising(out_dir: Path | str, config, *, force: bool = False,
                  map_builder=None) -> DenoiseResult:
    """The whole experiment into ``out_dir`` (see :mod:`dcslam.depth.denoise`); fails before any work if an output
    exists
    and ``force`` is false."""
    import torch

    from dcslam.depth.denoise import DepthDenoiser, pointfusion_builder, split_frames, train_denoiser
    from dcslam.depth.models import build_model, save_model
    from dcslam.device import resolve_device
    from dcslam.report.denoising import evaluate, plot_denoising, results_table
    from dcslam.report.scores import check_outputs

    out_dir = Path(out_dir)
    if not config.train_drives:
        raise DcslamError("no training drives; run `dcslam prepare-tum` first, or give --drives")
    check_outputs([out_dir / name for name in OUTPUT_FILES], force)
    start = time.perf_counter()
    device = resolve_device(config.device)
    torch.manual_seed(config.seed)
    map_builder = map_builder or pointfusion_builder(config.map_voxel_m)
    train_frames, test_frames = split_frames(config)
    net = build_model("dncnn", channels=1, features=config.features, depth=config.layers)
    with torch.no_grad():  # the residual layer starts at zero: training starts from the identity (output = input)
        net.body[-1].weight.zero_()
        net.body[-1].bias.zero_()
    model = DepthDenoiser(net, config.depth_scale_m).to(device)
    losses = train_denoiser(model, train_frames, config, device, map_builder)
    scores = evaluate(model, test_frames, config, device, map_builder)
    table = results_table(scores, config)
    seconds = time.perf_counter() - start

    settings = {**asdict(config), "train_drives": [str(p) for p in config.train_drives],
                "test_drives": [str(p) for p in config.test_drives], "resolved_device": str(device)}
    split = {"train": {f.name: f.frame_ids for f in train_frames}, "test": {f.name: f.frame_ids for f in test_frames}}
    save_model(out_dir / "model.pt", net, meta={"experiment": "demo-icl", "depth_scale_m": config.depth_scale_m,
                                               "sigma_m": config.sigma_m, "scale": config.scale,
                                               "steps": config.steps})
    record = stage_config("denoise", settings)
    record.update(scores={k: scores[k] for k in ("noisy", "denoised", "frames", "pixels")}, frames=split,
                  losses=losses, seconds=seconds)
    write_json_atomic(out_dir / "results.json", record)
    write_text_atomic(out_dir / "results.csv", table.to_csv())
    write_text_atomic(out_dir / "results.md", table.to_markdown())
    plot_denoising(out_dir / "denoising.png", scores["examples"], config.sigma_m)
    return DenoiseResult(out_dir, table, scores, losses, seconds)


def run(ws: Workspace, config: DemoIclConfig, *, force: bool = False):
    """Generate (or reuse) the data, run the experiment; returns a :class:`DenoiseResult`."""
    from dcslam.progress import Bar
    from dcslam.report.scores import check_outputs

    out_dir = ws.results / "demo-icl"
    drives = config.drives
    if drives is None:
        check_outputs([out_dir / name for name in OUTPUT_FILES], force)
        with Bar("indoor rooms", total=config.sequences * config.frames) as bar:
            drives = demo_drives(ws.root / "demo-icl", sequences=config.sequences, frames=config.frames,
                                 seed=config.seed, force=force, on_frame=bar.advance)
    train, test = drives_of(drives)
    return run_denoising(out_dir, config.denoise_config(train, test), force=force)


def demo_drives(root: Path | str, *, sequences: int = 4, frames: int = 30, seed: int = 0, force: bool = False,
                on_frame=None) -> Path:
    """The demo's indoor data under ``root``: ``sequences`` generated rooms in the ICL-NUIM layout (``root/tum``,
    :func:`dcslam.synth.indoor.generate_indoor`) converted to drive files + ``splits.json`` (``root/drives``,
    :func:`dcslam.stages.prepare_tum.prepare_tum`; the last room is the test split). Kept when ``root/data.json`` says
    it
    was made with the same settings; made again when they differ only with ``force``. Returns the drives folder."""
    import json

    from dcslam.stages.prepare_tum import prepare_tum
    from dcslam.synth.indoor import generate_indoor

    if sequences < 2:
        raise DcslamError(f"the demo needs at least 2 sequences (one held out), got {sequences}")
    root = Path(root)
    settings = {"sequences": sequences, "frames": frames, "seed": seed}
    stamp, drives = root / "data.json", root / "drives"
    if stamp.exists():
        try:
            made = json.loads(stamp.read_text()).get("settings")
        except json.JSONDecodeError:
            made = None
        if made == settings and (drives / "splits.json").exists():
            return drives
        if not force:
            raise DcslamError(f"{root} holds indoor data made with other settings ({made}); pass --force to make "
                              "it again, or --drives to use it")
    generate_indoor(root / "tum", sequences=sequences, frames=frames, seed=seed, force=True, on_frame=on_frame)
    prepare_tum(root / "tum", drives, force=True)
    write_json_atomic(stamp, stage_config("demo-icl data", settings))
    return drives


def drives_of(path: Path | str) -> tuple[list[Path], list[Path]]:
    """(training drives, test drives) of a drive file (no test drives: its last frames are held out) or of a folder
    with ``splits.json`` (train and val drives train, test drives are held out)."""
    from dcslam.io.drive import read_splits

    path = Path(path)
    if path.is_file():
        return [path], []
    if not path.is_dir():
        raise DcslamError(f"{path} not found; give a drive file or a folder with splits.json "
                          "(run `dcslam prepare-tum` first)")
    splits = read_splits(path / "splits.json")
    named = lambda names: [path / f"{name}.h5" for name in names]  # noqa: E731
    train, test = named(splits["train"] + splits["val"]), named(splits["test"])
    missing = [p for p in train + test if not p.exists()]
    if missing:
        raise DcslamError(f"{missing[0]} (named in {path / 'splits.json'}) not found; run `dcslam prepare-tum` again")
    return train, test
