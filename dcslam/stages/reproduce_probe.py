"""``dcslam reproduce --calibrate``: the unit costs of the estimate (:mod:`dcslam.stages.reproduce_cost`) measured on
this machine by a short probe.

The probe runs a sample of Table 5.2's stages at a profile's settings (its image scale, learning rate, SLAM settings,
filters): synth, prepare-kitti, one training of each loss (mse, chamfer, pose) and one of each network that corrects a
classical fill (:data:`FILL_PROBES`: the surface experiment's on planefit's scaffold and the beams experiment's on the
nearest-neighbour fill; each computes the fill of every frame it trains on and predicts), a prediction by each trained
run and by IP-Basic and by each other classical completer (:data:`PROBE_COMPLETERS`), a filter, SLAM of sparse,
annotated dense and predicted depth and over a whole drive, and the tables; twice, on 3 generated drives of
:data:`PROBE_SIZES` frames with depth (training and SLAM on as many frames; the larger sample runs SLAM on one more
completion, so that the tables score more runs), each in a temporary workspace, with one torch thread. The larger sample
runs first and generates the drives; the smaller prepares the first frames of the same drives (synth, about half of a
sample's CPU, runs once). The larger sample's first training is measured on a second run, as the first training of a
process also sets torch up (0.3 and 0.8 CPU-s more than the next on a small training, two runs; 2.8 before the optimizer
stopped importing torch._dynamo: docs/getting-started.md; every other training measured twice gave the same within
noise). Each stage's stamp records its CPU seconds; the two samples of each kind give its fixed part per stage
(``stage_s``) and its part per unit (``unit_s``) by a line through the two (:func:`fit`; synth: per generated frame),
written for the profile into ``<workspace>/.reproduce/calibration.json`` (``reproduce_costs.json``'s layout), which
the estimate then uses.
"""
from __future__ import annotations

import os
import tempfile
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

from dcslam.errors import DcslamError
from dcslam.stages.pipeline import Pipeline, Stage
from dcslam.stages.reproduce_cost import CALIBRATION, UNDEPTHED_FRAMES, measure
from dcslam.workspace import Workspace

PROBE_SIZES = (2, 4)  # frames with depth per generated drive (and frames trained on, SLAM frames) of the 2 samples
PROBE_STAGES = ("synth", "prepare-kitti", "train-mse-dense", "train-chamfer-8", "train-pose", "predict-mse-dense",
                "predict-ip-basic-fast", "score-tables")
# SLAM layers of each sample: every SLAM kind in both (sparse, annotated dense, a completion), one more completion in
# the larger, so that scoring (its unit: the runs scored) has a slope to fit
PROBE_SLAM = (("sparse", "dense", "mse-dense"), ("sparse", "dense", "mse-dense", "ip-basic-fast"))
# classical completers other than IP-Basic (which the experiment predicts with): each predicts the test drive too
PROBE_COMPLETERS = ("ip-basic-multiscale", "scanline", "planefit")
# the surface experiment's network on planefit's scaffold, trained at the profile's scale, epochs and frames, and its
# prediction: kinds train-mse+planefit and predict+planefit
SCAFFOLD_PROBE = "scaffold-planefit"
# the beams experiment's networks correct the nearest-neighbour fill of their input: kinds train-mse+nearest and
# predict+nearest (its 64-beam input only: the probe prepares no other beam count)
NEAREST_PROBE = "fill-nearest"
FILL_PROBES = (SCAFFOLD_PROBE, NEAREST_PROBE)
# imported before the samples run: otherwise the first stage of a kind in the first sample pays them (1-2 s of CPU),
# which the fit would take for a fixed part of every stage of that kind
WARM_IMPORTS = ("torch", "matplotlib.pyplot", "dcslam.depth.train", "dcslam.depth.train_pose", "dcslam.depth.chamfer",
                "dcslam.slam.drive", "dcslam.report.plots")


class _Sample(Pipeline):
    """A pipeline that runs, in this process, only the stages ``wanted`` (a predicate on stage names) accepts;
    ``max_frames``: its prepare-kitti keeps at most that many frames with depth per drive (None: all)."""

    def __init__(self, workspace: Workspace, wanted: Callable[[str], bool], log: Callable[[str], None],
                 max_frames: int | None = None):
        super().__init__(workspace, log, force=True)
        self.wanted, self.max_frames = wanted, max_frames
        self.ran: list = []

    def run(self, stage):
        if not self.wanted(stage.name):
            return None
        if stage.name == "prepare-kitti" and self.max_frames is not None:
            stage = replace(stage, config=replace(stage.config, max_frames=self.max_frames))
        self.ran.append(stage)
        return super().run(stage)

    def run_all(self, stages, jobs: int = 1) -> None:
        super().run_all([s for s in stages if self.wanted(s.name)], 1)


def probe_profile(profile, frames: int):
    """``profile`` (of Table 5.2) shrunk to a probe sample: 3 generated drives of ``frames`` frames with depth, one
    epoch on at most ``frames`` frames of each, SLAM on ``frames`` frames, one seed; every other setting kept."""
    return replace(profile, name=f"{profile.name}-probe", drives=3, frames=frames + UNDEPTHED_FRAMES, split=(1, 1, 1),
                   slam_frames=frames, seeds=1, train=profile.train | {"max_frames": frames, "epochs": 1},
                   pose=profile.pose | {"max_frames": frames, "epochs": 1})


def _wanted(profile, layers: tuple[str, ...]) -> Callable[[str], bool]:
    names = set(PROBE_STAGES) | {f"filter-mse-dense+{name}" for name in list(profile.filters)[:1]} \
        | {f"predict-{name}" for name in (*PROBE_COMPLETERS, *FILL_PROBES)} | {f"train-{name}" for name in FILL_PROBES}
    prefixes = tuple(f"slam-{layer}-" for layer in layers) + tuple(f"slam-long-{layer}-" for layer in
                                                                     profile.long_layers if layer in layers)
    return lambda name: name in names or name.startswith(prefixes)


def sample(profile, frames: int, layers: tuple[str, ...], root: Path,
           log: Callable[[str], None] = lambda line: None,
           kitti: Path | None = None, first: bool = False) -> dict[str, tuple[float, float, int]]:
    """Run one probe sample of ``profile`` (:func:`probe_profile` of ``frames``; SLAM of ``layers``) in the empty
    folder ``root``; ``{kind: (CPU seconds, units, stages)}`` its stamps measured (:func:`measure`). ``kitti``: the
    generated drives of a larger sample, of which it prepares the first ``frames`` frames with depth (no synth);
    ``first``: the process's first sample, whose first training is measured again."""
    from dcslam.stages import predict
    from dcslam.stages.experiments.table_5_2 import compose
    from dcslam.stages.slam import torch_threads

    small = probe_profile(profile, frames)
    ws = Workspace(root)
    with torch_threads(1):
        pipe = _Sample(ws, _wanted(small, layers), log, None if kitti is None else frames)
        compose(pipe, small, kitti_root=kitti)
        for name in PROBE_COMPLETERS:
            made = ws.predictions / name
            pipe.run(Stage(f"predict-{name}", predict.run, predict.PredictConfig(model=name),
                           outputs=lambda made=made: [made], kind="predict"))
        for name in FILL_PROBES:
            _fill_network(pipe, small, name)
        trainings = [s for s in pipe.ran if s.name.startswith("train-")]
        if first and trainings:  # measured again: the first training of a process also sets torch up
            (ws.root / ".reproduce" / f"{trainings[0].name}.json").unlink()
            pipe.run(trainings[0])
    return measure(root)


def _fill_config(small, name: str):
    """The training configuration of fill probe ``name`` (:data:`FILL_PROBES`) at the sample profile ``small``'s
    settings: its experiment's recipe on the sparse input alone (the probe prepares no other beam count)."""
    from dcslam.stages.experiments.beams import FILL_RECIPE
    from dcslam.stages.experiments.common import train_options
    from dcslam.stages.experiments.surface import SCAFFOLD_RECIPE

    recipe = {SCAFFOLD_PROBE: SCAFFOLD_RECIPE, NEAREST_PROBE: FILL_RECIPE}[name]
    mine = {key: value for key, value in recipe.items() if key != "input_mix"}
    return (train_options(model="sparse-conv") | small.train | mine).build(name=name, seed=0)


def _fill_network(pipe: _Sample, small, name: str) -> None:
    """Train fill probe ``name`` (:func:`_fill_config`) on the sample's train and val drives, and predict the test
    drive with it."""
    from dcslam.io.drive import read_splits
    from dcslam.stages import predict
    from dcslam.stages.experiments.beams import train_stage

    ws = pipe.ws
    splits = read_splits(ws.drives / "splits.json")
    learn = [ws.drives / f"{drive}.h5" for drive in splits["train"] + splits["val"]]
    pipe.run(train_stage(ws, _fill_config(small, name), learn, 0))
    made = ws.predictions / name
    pipe.run(Stage(f"predict-{name}", predict.run, predict.PredictConfig(run=name, output=made),
                   outputs=lambda: [made], kind="predict"))


def fit(small: dict[str, tuple[float, float, int]], large: dict[str, tuple[float, float, int]]) -> dict[str, dict]:
    """Each kind's ``{"stage_s", "unit_s", "samples"}`` from its two samples ``(CPU seconds, units, stages)``: the
    line through the two per-stage points; a negative part (noise) is 0 and the other fits both samples' sums. A kind
    only the large sample has (synth: the small one reuses its drives) is priced per unit, without a fixed part."""
    fitted = {}
    for kind in sorted(large.keys() - small.keys()):
        seconds, units, stages = large[kind]
        if units > 0:
            fitted[kind] = {"stage_s": 0.0, "unit_s": round(seconds / units, 4),
                            "samples": [[round(seconds, 3), units, stages]]}
    for kind in sorted(small.keys() & large.keys()):
        (s1, u1, n1), (s2, u2, n2) = small[kind], large[kind]
        x1, y1, x2, y2 = u1 / n1, s1 / n1, u2 / n2, s2 / n2
        unit = (y2 - y1) / (x2 - x1) if x2 != x1 else 0.0
        stage = y1 - unit * x1
        if unit < 0 or x2 == x1:  # no slope to measure: the mean per stage
            unit, stage = 0.0, (s1 + s2) / (n1 + n2)
        elif stage < 0:
            unit, stage = (s1 + s2) / (u1 + u2), 0.0
        fitted[kind] = {"stage_s": round(stage, 4), "unit_s": round(unit, 4),
                        "samples": [[round(s1, 3), u1, n1], [round(s2, 3), u2, n2]]}
    return fitted


def machine() -> str:
    """This machine in words: its processor (:func:`dcslam.report.provenance.cpu_name`), cores and load (what a
    calibration's source names: unit costs differ between CPUs of one model name)."""
    from dcslam.report.provenance import cpu_name

    return f"{cpu_name()}, {os.cpu_count()} CPU cores, load {os.getloadavg()[0]:.1f}"


def calibrate(ws: Workspace, profile, log: Callable[[str], None] = lambda line: None) -> Path:
    """Run the probe of ``profile`` (of Table 5.2; its name keys the result) and write its unit costs into
    ``<workspace>/.reproduce/calibration.json`` (other profiles' kept); returns that file."""
    import json

    from dcslam.io.atomic import write_json_atomic

    import importlib

    for name in WARM_IMPORTS:
        importlib.import_module(name)
    began, start = machine(), time.perf_counter()
    # the larger sample first: the smaller one prepares the first frames of its generated drives
    with tempfile.TemporaryDirectory(prefix="dcslam-probe-") as folder:
        log(f"[calibrate] probe sample of {PROBE_SIZES[1]} frames with depth per drive")
        large = sample(profile, PROBE_SIZES[1], PROBE_SLAM[1], Path(folder) / "large", log, first=True)
        log(f"[calibrate] probe sample of {PROBE_SIZES[0]} frames with depth per drive (the same drives)")
        small = sample(profile, PROBE_SIZES[0], PROBE_SLAM[0], Path(folder) / "small", log,
                       kitti=Path(folder) / "large" / "kitti")
    kinds = fit(small, large)
    if not kinds:
        raise DcslamError(f"profile {profile.name}: the probe measured no stage; rerun `dcslam reproduce --calibrate`")
    path = ws.root / ".reproduce" / CALIBRATION
    data = {"profiles": {}}
    if path.exists():
        try:
            data = json.loads(path.read_text())
            data["profiles"].items()
        except (json.JSONDecodeError, KeyError, TypeError, AttributeError):
            data = {"profiles": {}}  # an unreadable calibration is measured again, not kept
    source = (f"dcslam reproduce --calibrate --profile {profile.name} on {began} (after: load "
              f"{os.getloadavg()[0]:.1f}), {time.strftime('%Y-%m-%d')}, probe {time.perf_counter() - start:.0f} s")
    data["profiles"][profile.name] = {"source": source, "kinds": kinds}
    path.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(path, data)
    log(f"[calibrate] unit costs of profile {profile.name} written to {path}")
    return path
