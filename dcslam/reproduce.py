"""One-command reproduction of the thesis's Tables 5.1 and 5.2 (``make reproduce-table-5-2``, ``dcslam reproduce``).

The experiment, stage by stage, each a ``dcslam`` command run in a child process::

    synth (unless a KITTI root is given) → prepare-kitti → train × 4 recipes → predict (4 runs + IP-Basic)
    → filter (each model's predictions) → slam (sparse, dense, every prediction and filtered layer)
    → score tables

A stage is skipped when its outputs exist, are newer than its inputs and were made with the same command line
(recorded in ``<workspace>/.reproduce/<stage>.json``), so a rerun after a change redoes only what changed.
A profile chooses the scale: ``quick`` (the default, about half an hour on 2 CPU cores) or ``thesis`` (the
thesis's 15 / 4 / 5 drives of 200 frames, for a GPU).
"""
from __future__ import annotations

import json
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from dcslam.errors import DcslamError
from dcslam.workspace import Workspace, write_json_atomic

RECIPES = {  # run name → `dcslam train` options (Table 5.1 / 5.2 rows of the thesis)
    "chamfer-1": ["--loss", "chamfer", "--map-frames", "1"],
    "chamfer-8": ["--loss", "chamfer", "--map-frames", "8"],
    "mse-sparse": ["--loss", "mse", "--mask", "sparse"],
    "mse-dense": ["--loss", "mse", "--mask", "dense"],
}
IP_BASIC = "ip-basic-fast"


@dataclass(frozen=True)
class Profile:
    """The scale of one reproduction."""

    name: str
    drives: int                 # generated drives (split 62.5 / 16.7 / 20.8 % like the thesis's 15 / 4 / 5)
    frames: int                 # raw frames per generated drive (depth exists for frames 5 … N−6)
    train: list[str]            # options common to every `dcslam train`
    slam_frames: int            # frames of each test drive fed to SLAM (the thesis scored 30)
    filters: dict[str, list[str]] = field(default_factory=dict)  # filter name → `dcslam filter` options
    description: str = ""


PROFILES = {
    "quick": Profile(
        name="quick", drives=5, frames=42,
        train=["--epochs", "2", "--max-frames", "31", "--scale", "0.5", "--lr", "3e-3"],
        slam_frames=30,
        filters={"edges": ["--filter", "edges"]},
        description="5 generated drives of 42 frames (3 train / 1 val / 1 test), models trained 2 epochs at half "
                    "resolution, SLAM on the first 30 frames, one outlier filter"),
    "smoke": Profile(
        name="smoke", drives=3, frames=14,
        train=["--epochs", "1", "--max-frames", "2", "--scale", "0.25"],
        slam_frames=3,
        filters={"edges": ["--filter", "edges"]},
        description="a check that every stage runs (3 drives of 14 frames, tiny training): numbers mean nothing"),
    "thesis": Profile(
        name="thesis", drives=24, frames=211,
        train=["--epochs", "5", "--max-frames", "200"],
        slam_frames=30,
        filters={"thesis-range": ["--filter", "thesis-range"],
                 "thesis-bilateral": ["--filter", "thesis-bilateral"],
                 "edges": ["--filter", "edges"],
                 "outlier": ["--filter", "outlier"],
                 "hidden": ["--filter", "hidden"]},
        description="the thesis's scale: 15 / 4 / 5 drives, 200 frames per drive, full resolution (use a GPU)"),
}


@dataclass
class Stage:
    """One command of the pipeline with the files it reads and writes."""

    name: str
    args: list[str]
    outputs: Callable[[], list[Path]]
    inputs: Callable[[], list[Path]] = lambda: []


def _mtime(paths: list[Path]) -> tuple[float, float]:
    times = [p.stat().st_mtime for p in paths if p.exists()]
    return (min(times), max(times)) if times else (0.0, 0.0)


class Pipeline:
    """Runs stages in order, skipping those whose outputs are up to date."""

    def __init__(self, workspace: Workspace, log=print):
        self.ws = workspace
        self.state = workspace.root / ".reproduce"
        self.log = log
        self.timings: dict[str, float] = {}

    def _stamp(self, stage: Stage) -> Path:
        return self.state / f"{stage.name}.json"

    def up_to_date(self, stage: Stage) -> bool:
        stamp = self._stamp(stage)
        if not stamp.exists() or json.loads(stamp.read_text()).get("args") != stage.args:
            return False
        outputs, inputs = stage.outputs(), stage.inputs()
        if not outputs or not all(p.exists() for p in outputs):
            return False
        return _mtime(outputs)[0] >= _mtime(inputs)[1]

    def run(self, stage: Stage) -> None:
        if self.up_to_date(stage):
            self.log(f"[skip] {stage.name}: up to date")
            return
        command = [sys.executable, "-m", "dcslam", *stage.args, "--workspace", str(self.ws.root), "--force"]
        self.log(f"[run]  {stage.name}: dcslam {' '.join(stage.args)}")
        start = time.perf_counter()
        if subprocess.call(command) != 0:
            raise DcslamError(f"stage {stage.name} failed (dcslam {' '.join(stage.args)}); fix it and rerun: "
                              "finished stages will be skipped")
        self.timings[stage.name] = time.perf_counter() - start
        write_json_atomic(self._stamp(stage), {"args": stage.args, "seconds": self.timings[stage.name]})


def reproduce(workspace: Workspace, profile: Profile, table: str = "5.2", kitti_root: Path | None = None,
              seed: int = 0, log=print) -> Path:
    """Run the experiment at ``profile``'s scale; return the Markdown file of the requested table."""
    if table not in ("5.1", "5.2"):
        raise DcslamError(f"unknown table {table!r}; expected 5.1 or 5.2")
    ws = workspace
    pipe = Pipeline(ws, log)
    kitti = Path(kitti_root) if kitti_root else ws.kitti
    drives = lambda: sorted(ws.drives.glob("*.h5"))  # noqa: E731
    if kitti_root is None:
        pipe.run(Stage("synth", ["synth", "--drives", str(profile.drives), "--frames", str(profile.frames),
                                 "--seed", str(seed)],
                       outputs=lambda: [ws.kitti / "SYNTHETIC"]))
    elif not kitti.exists():
        raise DcslamError(f"KITTI root {kitti} not found")
    pipe.run(Stage("prepare-kitti", ["prepare-kitti", "--kitti", str(kitti)],
                   outputs=lambda: [ws.splits, *drives()],
                   inputs=lambda: [p for p in (kitti / "SYNTHETIC",) if p.exists()]))
    from dcslam.io.drive import read_splits

    splits = read_splits(ws.splits)
    test = [ws.drives / f"{name}.h5" for name in splits["test"]]
    learn = [ws.drives / f"{name}.h5" for name in splits["train"] + splits["val"]]

    for run, options in RECIPES.items():
        pipe.run(Stage(f"train-{run}", ["train", *options, *profile.train, "--name", run, "--seed", str(seed)],
                       outputs=lambda run=run: [ws.runs / run / "model.pt", ws.runs / run / "metrics.jsonl"],
                       inputs=lambda: learn))
    if table == "5.1":
        return _tables(pipe, ws, "5.1", inputs=[ws.runs / run / "metrics.jsonl" for run in RECIPES])

    layers = {}  # layer name → (files it is made of, `dcslam slam` depth options)
    for kind in ("sparse", "dense"):
        layers[kind] = (test, ["--depth", kind])
    for run in [*RECIPES, IP_BASIC]:
        made = [ws.predictions / run / p.name for p in test]
        args = ["predict", "--run", run] if run in RECIPES else ["predict", "--model", run]
        pipe.run(Stage(f"predict-{run}", args, outputs=lambda made=made: made,
                       inputs=lambda run=run: [ws.runs / run / "model.pt", *test] if run in RECIPES else test))
        layers[run] = (made, ["--depth", "predicted", "--run", run])
    for run in RECIPES:
        for fname, options in profile.filters.items():
            name = f"{run}+{fname}"
            made = [ws.filtered / name / p.name for p in test]
            pipe.run(Stage(f"filter-{name}", ["filter", "--depth", "predicted", "--run", run, *options,
                                              "--name", name],
                           outputs=lambda made=made: made, inputs=lambda m=layers[run][0]: m))
            layers[name] = (made, ["--depth", "filtered", "--run", name])
    slam_outputs = []
    for layer, (files, depth_args) in layers.items():
        made = [ws.slam / layer / f"{p.stem}.json" for p in test]
        slam_outputs += made
        pipe.run(Stage(f"slam-{layer}", ["slam", *depth_args, "--odometry", "icp", "--frames",
                                         str(profile.slam_frames)],
                       outputs=lambda made=made: made, inputs=lambda files=files: files))
    return _tables(pipe, ws, "5.2", inputs=slam_outputs + [ws.runs / run / "metrics.jsonl" for run in RECIPES])


def _tables(pipe: Pipeline, ws: Workspace, table: str, inputs: list[Path]) -> Path:
    name = f"table_{table.replace('.', '_')}.md"
    pipe.run(Stage("score-tables", ["score", "tables"], outputs=lambda: [ws.results / name], inputs=lambda: inputs))
    return ws.results / name
