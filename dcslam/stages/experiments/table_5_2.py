"""The thesis's Tables 5.1 and 5.2 (``dcslam reproduce``, ``make reproduce-table-5-2``): its recipes, profiles and
the composition of its stages::

    synth (unless a KITTI root is given) → prepare-kitti → train × 4 recipes (+ 3 pose-loss runs) → predict
    (7 runs + IP-Basic) → filter (each thesis recipe's predictions) → slam (sparse, dense, every prediction and
    filtered layer; and the profile's ``long_layers`` over whole test drives, into ``slam-long/``) → score tables

A profile chooses the scale: ``quick`` (the default: at least 4 test drives, about half an hour on 2 CPU cores),
``smoke`` (a check that every stage runs), ``thesis`` (the thesis's 15 / 4 / 5 drives of 200 frames, for a GPU) or
``study`` (3 training seeds over 8 test drives). ``seeds`` trains every trained run that many times, the ``k``-th
named :func:`dcslam.report.seeds.seed_run_name` (``<run>`` for k = 0; ``<run>-s<k>`` after) with seed ``seed + k``,
and predicts, filters and runs SLAM on each; the untrained layers run once. Every stage carries the training seed of
the run it trains or uses. Profiles and recipes are :class:`dcslam.stages.config.Options` of the stage
configurations, checked when made. Table 5.1 is the same experiment stopped after training.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

from dcslam.errors import DcslamError
from dcslam.stages import filter as filter_stage
from dcslam.stages import predict, score, slam, train
from dcslam.report.seeds import seed_run_name
from dcslam.stages.experiments.common import make_drives, train_options, training_rounds
from dcslam.stages.pipeline import Experiment, Pipeline, Stage, profile_options
from dcslam.workspace import Workspace

RECIPES = {  # run name → `dcslam train` options (Table 5.1 / 5.2 rows of the thesis)
    "chamfer-1": train_options(loss="chamfer", map_frames=1),
    "chamfer-8": train_options(loss="chamfer", map_frames=8),
    "mse-sparse": train_options(loss="mse", mask="sparse"),
    "mse-dense": train_options(loss="mse", mask="dense"),
}
POSE_RECIPES = {  # the pose loss, from scratch and fine-tuned from a chamfer and an MSE run (trained first)
    "pose": train_options(loss="pose"),
    "pose-from-chamfer-8": train_options(loss="pose", init="chamfer-8"),
    "pose-from-mse-dense": train_options(loss="pose", init="mse-dense"),
}
IP_BASIC = "ip-basic-fast"
# what a recipe decides and a profile may not (a profile setting one would silently change the recipe); the run's
# name and seed are set per run
RECIPE_KEYS = frozenset().union(*RECIPES.values(), *POSE_RECIPES.values(), ("name", "seed"))


@dataclass(frozen=True)
class Profile:
    """The scale of one reproduction. ``train``, ``slam`` and ``pose`` are checked against the fields of the stage
    configurations they feed when the profile is made (a misspelt option fails at import, not when a stage runs)."""

    name: str
    drives: int                 # generated drives (split 62.5 / 16.7 / 20.8 % like the thesis's 15 / 4 / 5)
    frames: int                 # raw frames per generated drive (depth exists for frames 5 … N−6)
    train: Mapping              # options common to every training run (fields of TrainStageConfig)
    slam_frames: int            # frames of each test drive fed to SLAM (the thesis scored 30)
    filters: dict[str, list[str]] = field(default_factory=dict)  # filter name → filter specs of `dcslam filter`
    description: str = ""
    split: tuple[int, int, int] | None = None  # (train, val, test) drive counts; None: the thesis's proportion
    slam: Mapping = field(default_factory=dict)  # SLAM settings other than the defaults (fields of SlamStageConfig)
    long_layers: tuple[str, ...] = ()           # layers also run by SLAM over whole test drives (slam-long/)
    pose: Mapping = field(default_factory=dict)  # options of the pose-loss runs over ``train`` (TrainStageConfig)
    seeds: int = 1              # training seeds per trained run (``dcslam reproduce --seeds`` overrides it)

    def __post_init__(self) -> None:
        object.__setattr__(self, "train", profile_options(self.name, "train", train.TrainStageConfig, self.train,
                                                          RECIPE_KEYS))
        object.__setattr__(self, "pose", profile_options(self.name, "pose", train.TrainStageConfig, self.pose,
                                                         RECIPE_KEYS))
        object.__setattr__(self, "slam", profile_options(self.name, "slam", slam.SlamStageConfig, self.slam,
                                                         frozenset(("depth", "drive", "frames", "out"))))
        if self.seeds < 1:
            raise DcslamError(f"profile {self.name}: seeds must be >= 1, got {self.seeds}")
        if self.split is not None and (sum(self.split) != self.drives or min(self.split) < 1):
            raise DcslamError(f"profile {self.name}: split {self.split} must be >= 1 drive each and add up to "
                              f"{self.drives} drives")
        unknown = [layer for layer in self.long_layers if layer not in ("sparse", "dense", IP_BASIC, *RECIPES)]
        if unknown:
            raise DcslamError(f"profile {self.name}: long_layers {unknown} are not sparse, dense, {IP_BASIC} or a "
                              f"recipe ({', '.join(RECIPES)})")

    def train_config(self, run: str, seed: int, k: int = 0) -> train.TrainStageConfig:
        """The ``dcslam train`` configuration of recipe ``run`` (of :data:`RECIPES` or :data:`POSE_RECIPES`) for
        the ``k``-th training seed: named :func:`seed_run_name` (``run``, k), trained with seed ``seed + k``, and
        fine-tuned from the ``k``-th run of the recipe it starts from."""
        options = RECIPES.get(run) or POSE_RECIPES[run]
        options = options | self.train | (self.pose if run in POSE_RECIPES else {})
        if options.get("init") is not None:
            options = options | {"init": seed_run_name(options["init"], k)}
        return options.build(name=seed_run_name(run, k), seed=seed + k)


PROFILES = {
    "quick": Profile(
        name="quick", drives=8, frames=42, train={"epochs": 2, "max_frames": 31, "scale": 0.5, "lr": 3e-3},
        slam_frames=30, filters={"edges": ["edges"]}, split=(3, 1, 4), long_layers=("sparse", "dense", IP_BASIC),
        pose={"epochs": 1, "max_frames": 16, "lr": 1e-3, "pose_grad_iterations": 2, "pose_max_sources": 2000},
        description="8 generated drives of 42 frames (3 train / 1 val / 4 test), models trained 2 epochs at half "
                    "resolution, SLAM on the first 30 frames of each test drive, one outlier filter; sparse, dense "
                    "and IP-Basic also over whole test drives (32 frames: too short for KITTI drift)"),
    "smoke": Profile(
        name="smoke", drives=3, frames=12, train={"epochs": 1, "max_frames": 2, "scale": 0.25},
        slam_frames=2, filters={"edges": ["edges"]}, slam={"iterations": 3, "voxel_size": 0.2},
        long_layers=("sparse", "dense", IP_BASIC),
        description="a check that every stage runs (3 drives of 12 frames, tiny training, SLAM over 2 frames with "
                    "3 ICP iterations and a coarse map): numbers mean nothing"),
    "thesis": Profile(
        name="thesis", drives=24, frames=211, train={"epochs": 5, "max_frames": 200},
        slam_frames=30,
        filters={"thesis-range": ["thesis-range"], "thesis-bilateral": ["thesis-bilateral"], "edges": ["edges"],
                 "outlier": ["outlier"], "hidden": ["hidden"]},
        long_layers=("sparse", "dense", IP_BASIC, *RECIPES),
        description="the thesis's scale: 15 / 4 / 5 drives, 200 frames per drive, full resolution (use a GPU); "
                    "sparse, dense, IP-Basic and the four models also over whole test drives (about 200 m)"),
    "study": Profile(
        name="study", drives=14, frames=42, train={"epochs": 2, "max_frames": 31, "scale": 0.5, "lr": 3e-3},
        slam_frames=30, filters={"edges": ["edges"]}, split=(5, 1, 8), long_layers=("sparse", "dense", IP_BASIC),
        pose={"epochs": 1, "max_frames": 16, "lr": 1e-3, "pose_grad_iterations": 2, "pose_max_sources": 2000},
        seeds=3,
        description="the quick profile's recipes and training at a scale whose rows can be told apart: 14 generated "
                    "drives of 42 frames (5 train / 1 val / 8 test), every trained run with 3 training seeds, SLAM "
                    "on the first 30 frames of each test drive; intervals over seeds and drives"),
}
def compose(pipe: Pipeline, profile: Profile, kitti_root: Path | None = None, seed: int = 0, jobs: int = 1,
            seeds: int = 1, *, table: str = "5.2") -> Path:
    """Hand every stage of the experiment to ``pipe`` in order; return the Markdown file of ``table``.

    Every recipe is trained ``seeds`` times (the ``k``-th run named :func:`seed_run_name` (recipe, k), trained with
    seed ``seed + k``; a fine-tuned recipe starts from the ``k``-th run of its source), and every run is predicted,
    filtered and run through SLAM; the untrained layers (sparse, dense, IP-Basic) once."""
    if table not in ("5.2", "5.1"):
        raise DcslamError(f"unknown table {table!r}; expected 5.1 or 5.2 (the other experiments: "
                          "dcslam.stages.experiments.EXPERIMENTS)")
    if seeds < 1:
        raise DcslamError(f"seeds must be >= 1, got {seeds}")
    ws = pipe.ws
    test, learn = make_drives(pipe, drives=profile.drives, frames=profile.frames, split=profile.split,
                              kitti_root=kitti_root, seed=seed, jobs=jobs)
    runs = _train(pipe, profile, learn, seed, jobs, seeds)
    if table == "5.1":
        return _tables(pipe, ws, "5.1", inputs=[ws.runs / r / "metrics.jsonl" for r in runs])
    layers = {kind: (test, kind, None) for kind in ("sparse", "dense")}  # layer → (files, reference, seed or None)
    layers.update(_predict(pipe, runs, test, jobs))
    layers.update(_filter(pipe, profile, runs, layers, test, jobs))
    slam_stages = [_slam_stage(ws, profile, layer, reference, drive, source, seed=run_seed)
                   for layer, (files, reference, run_seed) in layers.items() for drive, source in zip(test, files)]
    long_layers = [seed_run_name(layer, k) if layer in RECIPES else layer
                   for layer in profile.long_layers for k in range(seeds if layer in RECIPES else 1)]
    slam_stages += [_slam_stage(ws, profile, layer, layers[layer][1], drive, source, whole=True,
                                seed=layers[layer][2])
                    for layer in long_layers for drive, source in zip(test, layers[layer][0])]
    slam_outputs = [path for stage in slam_stages for path in stage.outputs()]
    pipe.run_all(slam_stages, jobs)
    return _tables(pipe, ws, "5.2", inputs=slam_outputs + [ws.runs / r / "metrics.jsonl" for r in runs])


def _train(pipe: Pipeline, profile: Profile, learn: list[Path], seed: int, jobs: int,
           seeds: int) -> dict[str, tuple[str, int]]:
    """Train every recipe ``seeds`` times, in rounds (those that fine-tune another run wait for it); returns run name
    → (its recipe, its training seed), seed by seed in the recipes' order."""
    ws = pipe.ws
    recipes = {**RECIPES, **POSE_RECIPES}
    runs = {}
    trainings = {}  # run name → its stage
    for k in range(seeds):
        for recipe in recipes:
            config = profile.train_config(recipe, seed, k)
            run_name = config.name
            runs[run_name] = (recipe, seed + k)
            init = [ws.runs / config.init / "model.pt"] if config.init else []
            made = [ws.runs / run_name / "model.pt", ws.runs / run_name / "metrics.jsonl"]
            trainings[run_name] = Stage(f"train-{run_name}", train.run, config, outputs=lambda made=made: made,
                                        inputs=lambda init=init: learn + init, seed=seed + k, kind="train")
    for names in training_rounds({name: recipes[recipe] for name, (recipe, _) in runs.items()}):
        pipe.run_all([trainings[r] for r in names], jobs)
    return runs


def _predict(pipe: Pipeline, runs: dict[str, tuple[str, int]], test: list[Path], jobs: int) -> dict[str, tuple]:
    """Predict the test drives with every run and IP-Basic; returns layer → (files, reference, training seed)."""
    ws = pipe.ws
    layers, predictions = {}, []
    for run_name in [*runs, IP_BASIC]:
        made = [ws.predictions / run_name / p.name for p in test]
        config = predict.PredictConfig(run=run_name) if run_name in runs else predict.PredictConfig(model=run_name)
        run_seed = runs[run_name][1] if run_name in runs else None
        predictions.append(Stage(f"predict-{run_name}", predict.run, config, outputs=lambda made=made: made,
                                 inputs=lambda r=run_name: [ws.runs / r / "model.pt", *test] if r in runs else test,
                                 seed=run_seed, kind="predict"))
        layers[run_name] = (made, f"predicted/{run_name}", run_seed)
    pipe.run_all(predictions, jobs)
    return layers


def _filter(pipe: Pipeline, profile: Profile, runs: dict[str, tuple[str, int]], layers: dict[str, tuple],
            test: list[Path], jobs: int) -> dict[str, tuple]:
    """Filter each thesis recipe's predictions with each of the profile's filters (independent of one another:
    each reads one run's predictions); returns layer → (files, reference, training seed)."""
    ws = pipe.ws
    filtered, filters = {}, []
    for run_name, (recipe, run_seed) in runs.items():
        if recipe not in RECIPES:  # the thesis's recipes only: filtering the pose runs too would lengthen the profile
            continue
        for fname, specs in profile.filters.items():
            name = f"{run_name}+{fname}"
            made = [ws.filtered / name / p.name for p in test]
            config = filter_stage.FilterConfig(filters=list(specs), depth="predicted", run=run_name, name=name)
            filters.append(Stage(f"filter-{name}", filter_stage.run, config, outputs=lambda made=made: made,
                                 inputs=lambda m=layers[run_name][0]: m, seed=run_seed, kind="filter"))
            filtered[name] = (made, f"filtered/{name}", run_seed)
    pipe.run_all(filters, jobs)
    return filtered


def _slam_stage(ws: Workspace, profile: Profile, layer: str, reference: str, drive: Path, source,
                whole: bool = False, seed: int | None = None) -> Stage:
    """SLAM of ``layer`` (depth ``reference``) over one test drive: its first ``profile.slam_frames`` frames into
    ``slam/<layer>/`` (Table 5.2), or with ``whole`` every frame into ``slam-long/<layer>/`` (its long-drive table)."""
    out = (ws.slam_long if whole else ws.slam) / layer
    config = slam.SlamStageConfig(**{"odometry": "icp", **profile.slam}, depth=reference, drive=[drive.stem],
                                  frames=0 if whole else profile.slam_frames, out=out if whole else None)
    made = [out / f"{drive.stem}{suffix}" for suffix in (".json", ".txt", ".kitti.txt", ".done")]
    return Stage(f"{'slam-long' if whole else 'slam'}-{layer}-{drive.stem}", slam.run, config,
                 outputs=lambda: made, inputs=lambda: [drive, source], seed=seed, kind="slam")


def _tables(pipe: Pipeline, ws: Workspace, table: str, inputs: list[Path]) -> Path:
    name = f"table_{table.replace('.', '_')}.md"
    made = [ws.results / name] + ([ws.results / "table_5_2_correlation.md"] if table == "5.2" else [])
    pipe.run(Stage("score-tables", score.run_tables, score.ScoreTablesConfig(), outputs=lambda: made,
                   inputs=lambda: inputs, kind="score"))
    return ws.results / name


def rebuild_tables(ws: Workspace, config: score.ScoreTablesConfig, *, force: bool = False):
    """``dcslam score tables --table 5.2`` (or 5.1): Tables 5.1 and 5.2 from the workspace's runs and SLAM runs."""
    return score.run_thesis_tables(ws, config, force=force)


_HELP_5_2 = "Table 5.2: every recipe's completed depth through SLAM on the test drives (and Table 5.1)"
TABLE_5_2 = Experiment("5.2", _HELP_5_2, PROFILES, partial(compose, table="5.2"), rebuild_tables)
TABLE_5_1 = Experiment("5.1", "Table 5.1: the recipes' validation (stops after training)", PROFILES,
                       partial(compose, table="5.1"), rebuild_tables)
