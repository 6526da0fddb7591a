"""``dcslam reproduce --table beams`` (``make reproduce-beams``): does completed depth help SLAM when the LiDAR has
fewer beams? (RESULTS.md, "Beams")

The experiment composes the other stages through the stage engine (:mod:`dcslam.stages.pipeline`: the same stamps,
the same skipping of finished stages, the same ``jobs``) as Table 5.2 does::

    synth (unless a KITTI root is given) → prepare-kitti --beams 32,16,8 (plus depth/exact on generated drives)
    → train SparseConvNet (against annotated depth, exact depth, exact depth + geometry losses; the last two only on
      generated drives), nconv, nconv-guided, then nconv-pose (nconv fine-tuned through the pose loss, its
      confidence as ICP weights) → predict each (and IP-Basic) at every beam count
    → filter nconv's predictions by confidence ("masked") → slam over every (input, beam count, test drive), the
      completions and exact depth again with measured ICP sources (the B-beam pixels against the completed map)
    → score: the beams table, its per-drive CSV, the rank correlation of its depth metrics with localisation
      and a plot of localisation against beam count (``dcslam score tables --table beams`` rebuilds them)

The trainings (those fine-tuned from another run after the others), the predictions and the SLAM runs are each
independent of one another, so ``jobs`` > 1 runs each group in that many worker processes (one torch thread each). A
profile sets the scale; its ``train`` is the one dict of training options (run name → options of ``dcslam train``).
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from dcslam.errors import DcslamError
from dcslam.eval.trajectory import EVO_MAX_TIME_DIFF_S
from dcslam.report.results import FAILURE_THRESHOLD
from dcslam.report.table_beams import (CLASSICAL_RUNS, FULL_BEAMS, INPUTS, IP_BASIC_RUN, LEARNED, MEASURED,
                                       TRAINED, layer_name, prediction_name, slam_name, sparse_kind)
from dcslam.stages import filter as filter_stage
from dcslam.stages import predict, prepare, slam, train
from dcslam.stages.config import option
from dcslam.report.seeds import seed_run_name
from dcslam.stages.experiments.common import make_drives, train_options, training_rounds
from dcslam.stages.pipeline import Experiment, Pipeline, Stage, profile_options
from dcslam.workspace import Workspace


@dataclass(frozen=True)
class BeamsProfile:
    """The scale of one beams experiment."""

    name: str
    drives: int                          # generated drives
    frames: int                          # raw frames per generated drive (depth exists for frames 5 … N−6)
    train: Mapping[str, Mapping]         # run name (TRAINED: sparse-conv…, nconv…) → `dcslam train`
                                         # options (checked against TrainStageConfig's fields when the profile is
                                         # made); a run with ``init`` is trained after the run it starts from
    slam_frames: int                     # frames of each test drive fed to SLAM
    beams: tuple[int, ...] = (64, 32, 16, 8)
    # nconv's "masked" rows keep each frame's most confident quarter of pixels: a fixed threshold (0.5) emptied the
    # layers of a briefly trained nconv, whose confidence scale varies by model and beam count; keeping the top
    # quarter localised best of 25/50/75 % (RESULTS.md, "Confidence in SLAM")
    confidence_keep: float = 0.25
    split: tuple[int, int, int] | None = None
    slam: Mapping = field(default_factory=dict)  # SLAM settings other than the defaults (fields of SlamStageConfig)
    description: str = ""
    seeds: int = 1                       # training seeds per trained run (``dcslam reproduce --seeds`` overrides it)

    def __post_init__(self) -> None:
        fixed = frozenset(("name", "seed"))
        object.__setattr__(self, "train", {run: profile_options(f"beams {self.name}", f"train[{run!r}]",
                                                                train.TrainStageConfig, options, fixed)
                                           for run, options in self.train.items()})
        object.__setattr__(self, "slam", profile_options(f"beams {self.name}", "slam", slam.SlamStageConfig,
                                                         self.slam, frozenset(("depth", "drive", "frames", "out"))))
        if self.seeds < 1:
            raise DcslamError(f"beams profile {self.name}: seeds must be >= 1, got {self.seeds}")
        if set(self.train) != set(TRAINED):
            raise DcslamError(f"beams profile {self.name}: train must hold options for exactly "
                              f"{', '.join(TRAINED)}, got {', '.join(self.train) or 'none'}")
        if FULL_BEAMS not in self.beams:
            raise DcslamError(f"beams profile {self.name}: beams {self.beams} must include {FULL_BEAMS} (the "
                              "drive's own sparse depth, the reference of the others)")
        for b in self.beams:
            prepare.check_beams(b)
        for run, options in self.train.items():
            if options.get("init") is not None and (options["init"] not in self.train or
                                                    self.train[options["init"]].get("init") is not None):
                raise DcslamError(f"beams profile {self.name}: run {run} starts from {options['init']}, which is "
                                  "not a run of the profile trained from scratch")
        if self.split is not None and (sum(self.split) != self.drives or min(self.split) < 1):
            raise DcslamError(f"beams profile {self.name}: split {self.split} must be >= 1 drive each and add up "
                              f"to {self.drives} drives")

    def train_config(self, run: str, seed: int, k: int = 0) -> train.TrainStageConfig:
        """The ``dcslam train`` configuration of run ``run`` (its ``model`` defaults to the run's name) for the
        ``k``-th training seed: named :func:`seed_run_name` (``run``, k), trained with seed ``seed + k`` and
        fine-tuned from the ``k``-th run of the run it starts from."""
        options = self.train[run]
        if options.get("init") is not None:
            options = options | {"init": seed_run_name(options["init"], k)}
        return (train_options(model=run) | options).build(name=seed_run_name(run, k), seed=seed + k)

    def stages_of_training(self, exact: bool = True) -> list[list[str]]:
        """The runs in the order they can be trained: those from scratch, then those fine-tuned from them; without
        ``exact`` (drives without the generator's exact depth) not the runs trained against it."""
        return training_rounds({run: self.train[run] for run in TRAINED if exact or run not in _NEEDS_EXACT})


_QUICK = {"epochs": 2, "max_frames": 31, "scale": 0.5}  # as the Table 5.2 quick profile
# Every learned completer corrects a nearest-neighbour fill of its input (untrained: the fill), trained on the 64-beam
# input three frames in six and on 32, 16 and 8 beams one each, MSE plus 30 x L1 (MAE is what the plain networks lost
# to the fill on), lr 1e-3 with a cosine schedule: the recipe that beat the fill and its untrained self at 64, 32, 16
# and 8 beams, MAE and RMSE, for all three networks in benchmarks/beams_quality.py (chosen on the seed-7 drives,
# confirmed on the seed-11 drives with 2 training seeds; RESULTS.md, "Fill correction")
# (also what the cost probe of `dcslam reproduce --calibrate` trains: the fill is the training's default, nearest)
FILL_RECIPE = {"correct_fill": True, "input_mix": ["sparse", "sparse", "sparse", "sparse@32", "sparse@16", "sparse@8"],
               "l1_weight": 30.0, "lr": 1e-3, "lr_schedule": "cosine"}
# nconv fine-tuned through the pose loss: the network's confidence is each pixel's ICP weight, so this
# loss is the one that can teach the confidence which pixels ICP should trust
_POSE = {"model": "nconv", "loss": "pose", "init": "nconv"}
# SparseConvNet against the exact depth (the target's effect alone), and with the geometry losses added, each
# weighted to the order of MSE + 30 x L1 at the start of training (docs/training.md, "Geometry losses")
_EXACT = {"model": "sparse-conv", "target": "exact"}
_GEOMETRY = {**_EXACT, "normal_weight": 100.0, "plane_weight": 7.0, "edge_weight": 10.0}
_RECIPES = {"sparse-conv-exact": _EXACT, "sparse-conv-geometry": _GEOMETRY}
_NEEDS_EXACT = frozenset(i.completer for i in INPUTS if i.needs_exact and i.completer in TRAINED)


def _corrected(options: Mapping) -> dict:
    """``options`` (a fill-correcting recipe's) for every SparseConvNet run: the plain one, then the exact and
    geometry ones (:data:`_RECIPES`) with their own target and losses."""
    return {"sparse-conv": dict(options), **{run: {**options, **recipe} for run, recipe in _RECIPES.items()}}
# its scale in the quick profile, as Table 5.2's quick pose runs: 1 epoch of 16 frames per drive (12 windows of 4),
# the last 2 LM iterations with gradient, at most 2000 sources per frame
_POSE_QUICK = {"epochs": 1, "max_frames": 16, "scale": 0.5, "lr": 1e-3, "pose_grad_iterations": 2,
               "pose_max_sources": 2000}
PROFILES = {
    "quick": BeamsProfile(
        name="quick", drives=8, frames=42, split=(3, 1, 4), slam_frames=30,
        train={**_corrected({**_QUICK, **FILL_RECIPE}), "nconv": {**_QUICK, **FILL_RECIPE},
               "nconv-guided": {**_QUICK, **FILL_RECIPE}, "nconv-pose": {**_POSE, **_POSE_QUICK}},
        description="8 generated drives of 42 frames (3 train / 1 val / 4 test, the drives of the Table 5.2 quick "
                    "profile), 64/32/16/8 beams, SparseConvNet (against the annotated depth, the exact depth, and the "
                    "exact depth with the geometry losses), nconv and nconv-guided each correcting a "
                    "nearest-neighbour fill of its input, trained 2 epochs at half resolution on the 64-beam input "
                    "(half the frames) and the 32/16/8-beam inputs, nconv then fine-tuned 1 epoch through the pose "
                    "loss, SLAM on the first 30 frames of each test drive, with the depth's own and with the "
                    "measured ICP sources"),
    "smoke": BeamsProfile(
        name="smoke", drives=3, frames=12, beams=(64, 16), slam_frames=2,
        train={run: {"epochs": 1, "max_frames": 2, "scale": 0.25,
                     **(_POSE if run == "nconv-pose" else {"correct_fill": True, **_RECIPES.get(run, {})})}
               for run in TRAINED},
        slam={"iterations": 3, "voxel_size": 0.2},
        description="a check that every stage runs (3 drives of 12 frames, 64 and 16 beams, tiny training, SLAM "
                    "over 2 frames): numbers mean nothing"),
    "thesis": BeamsProfile(
        name="thesis", drives=24, frames=211, slam_frames=30,
        train={**_corrected({"epochs": 5, "max_frames": 200, **FILL_RECIPE}),
               "nconv": {"epochs": 5, "max_frames": 200, **FILL_RECIPE},
               "nconv-guided": {"epochs": 5, "max_frames": 200, **FILL_RECIPE},
               "nconv-pose": {**_POSE, "epochs": 1, "max_frames": 200}},
        description="the thesis's scale: 15 / 4 / 5 drives of 200 frames, full resolution (use a GPU)"),
    "study": BeamsProfile(
        name="study", drives=14, frames=42, split=(5, 1, 8), slam_frames=30, beams=(64, 16, 8), seeds=3,
        train={**_corrected({**_QUICK, **FILL_RECIPE}), "nconv": {**_QUICK, **FILL_RECIPE},
               "nconv-guided": {**_QUICK, **FILL_RECIPE}, "nconv-pose": {**_POSE, **_POSE_QUICK}},
        description="the quick profile's training at a scale whose rows can be told apart: 14 generated drives of "
                    "42 frames (5 train / 1 val / 8 test, the drives of the Table 5.2 study profile), 64/16/8 "
                    "beams, every trained completer with 3 training seeds, SLAM on the first 30 frames of each test "
                    "drive; intervals over seeds and drives"),
}


@dataclass(frozen=True)
class BeamsTableConfig:
    """What the scoring stage of the beams experiment reads (its record in the pipeline's stamp)."""

    beams: list[int] = option(default_factory=lambda: [64, 32, 16, 8], help="Beam counts (rows).")
    drive: list[str] = option(default_factory=list, help="Test drives.")
    out_dir: Path | None = option(None, help="Output folder (default: <workspace>/results).")
    max_time_diff: float = option(EVO_MAX_TIME_DIFF_S, min=0.0, help="Trajectory association tolerance (s).")
    failure_threshold: float = option(FAILURE_THRESHOLD, min=0.0, help="Localisation above which a drive failed.")
    jobs: int = option(1, internal=True, help="Worker processes that score the rows (not part of the stamp).")
    inputs: list[str] | None = option(None, help="Rows to score, by input label (default: every input).")


def run_table(ws: Workspace, config: BeamsTableConfig, *, force: bool = False, name: str = "beams",
              catalogue: tuple = INPUTS):
    """Write the beams table, its per-drive table and the plot (:func:`dcslam.report.table_beams.build_beams_report`)
    and the configuration beside them (``table_beams.json``); ``name`` and ``catalogue``: another experiment's tables
    over its own inputs (``table_<name>.json``, its stage ``score-<name>``)."""
    from dcslam.io.atomic import write_json_atomic
    from dcslam.report.table_beams import build_beams_report
    from dcslam.stages.config import to_dict
    from dcslam.workspace import select_drives, stage_config

    report = build_beams_report(ws, list(config.beams), select_drives(ws, config.drive), out_dir=config.out_dir,
                                force=force, max_time_diff=config.max_time_diff,
                                failure_threshold=config.failure_threshold, jobs=config.jobs,
                                inputs=config.inputs, name=name, catalogue=catalogue)
    write_json_atomic(report.written[0].parent / f"table_{name}.json", stage_config(f"score-{name}", to_dict(config)),
                      force=True)
    return report


def _init_model(ws: Workspace, options: dict) -> list[Path]:
    """The model file a run fine-tunes (``init``), as a list of inputs of its stage (empty for a run from scratch)."""
    return [ws.runs / options["init"] / "model.pt"] if options.get("init") is not None else []


def have_exact(drives: list[Path]) -> bool:
    """Whether every drive file holds the generator's exact depth (``depth/exact``)."""
    from dcslam.io.drive import EXACT, DriveFile

    for path in drives:
        with DriveFile(path) as drive:
            if EXACT not in drive.kinds:
                return False
    return True


def compose(pipe: Pipeline, profile: BeamsProfile, kitti_root: Path | None = None, seed: int = 0,
            jobs: int = 1, seeds: int = 1) -> Path:
    """Hand every stage of the beams experiment to ``pipe`` in order; return the Markdown file of its table. Every
    learned completer is trained ``seeds`` times (the ``k``-th run :func:`seed_run_name` (run, k), seed
    ``seed + k``) and each run predicted, filtered and run through SLAM; IP-Basic and the untrained layers once."""
    if seeds < 1:
        raise DcslamError(f"seeds must be >= 1, got {seeds}")
    ws = pipe.ws
    test, learn = make_drives(pipe, drives=profile.drives, frames=profile.frames, split=profile.split,
                              kitti_root=kitti_root, seed=seed, jobs=jobs,
                              beams=tuple(b for b in profile.beams if b != FULL_BEAMS))
    exact = kitti_root is None if pipe.planning else have_exact(test + learn)
    if not exact and not pipe.planning:
        pipe.log("[note] the drives have no exact depth (real KITTI): the rows that need it (exact, "
                 f"{', '.join(sorted(_NEEDS_EXACT))}) are left out")
    _train(pipe, profile, learn, exact, seed, jobs, seeds)
    made_runs = [run for run in TRAINED if exact or run not in _NEEDS_EXACT]
    completers = [(IP_BASIC_RUN, None)] + [(seed_run_name(run, k), seed + k) for k in range(seeds)
                                           for run in made_runs]
    pipe.run_all(predict_stages(ws, profile.beams, test, completers), jobs)
    _mask(pipe, profile, test, seed, jobs, seeds)
    slam_stages = make_slam_stages(ws, profile, test, exact, seed, seeds)
    pipe.run_all(slam_stages, jobs)
    slam_outputs = [path for stage in slam_stages for path in stage.outputs()]
    table = BeamsTableConfig(beams=list(profile.beams), drive=[p.stem for p in test], jobs=jobs)
    pipe.run(Stage("score-beams", run_table, table, outputs=lambda: [ws.results / "table_beams.md",
                                                                      ws.results / "table_beams_correlation.md"],
                   inputs=lambda: slam_outputs, kind="score"))
    return ws.results / "table_beams.md"


def _train(pipe: Pipeline, profile: BeamsProfile, learn: list[Path], exact: bool, seed: int, jobs: int,
           seeds: int) -> None:
    """Train every learned completer ``seeds`` times, in rounds (those fine-tuned from another run after it)."""
    for runs in profile.stages_of_training(exact):
        pipe.run_all([train_stage(pipe.ws, profile.train_config(run, seed, k), learn, seed + k)
                      for k in range(seeds) for run in runs], jobs)


def train_stage(ws: Workspace, config: train.TrainStageConfig, learn: list[Path], seed: int) -> Stage:
    """The stage that trains ``config`` (its run ``runs/<config.name>/``) on the drives ``learn`` with ``seed``."""
    return Stage(f"train-{config.name}", train.run, config,
                 outputs=lambda: [ws.runs / config.name / "model.pt", ws.runs / config.name / "metrics.jsonl"],
                 inputs=lambda: learn + _init_model(ws, {"init": config.init}), seed=seed, kind="train")


def predict_stages(ws: Workspace, beams, test: list[Path], completers: list[tuple[str, int | None]]) -> list[Stage]:
    """The predictions of the test drives at every beam count of ``beams`` by each of ``completers`` (``(name,
    training seed)``: a classical completer of :data:`CLASSICAL_RUNS`, seed None, or a trained run)."""
    stages = []
    for b in beams:
        for completer, run_seed in completers:
            out = ws.predictions / prediction_name(completer, b)
            made = [out / p.name for p in test]
            classical = completer in CLASSICAL_RUNS
            config = (predict.PredictConfig(model=completer, input=sparse_kind(b), output=out) if classical else
                      predict.PredictConfig(run=completer, input=sparse_kind(b), output=out))
            needs = [] if classical else [ws.runs / completer / "model.pt"]
            stages.append(Stage(f"predict-{out.name}", predict.run, config, outputs=lambda m=made: m,
                                inputs=lambda n=needs: [*n, *test], seed=run_seed, kind="predict"))
    return stages


def _mask(pipe: Pipeline, profile: BeamsProfile, test: list[Path], seed: int, jobs: int, seeds: int) -> None:
    """Keep the most confident pixels of the predictions of every masked input (its "masked" rows)."""
    ws = pipe.ws
    masked = []
    for item in (i for i in INPUTS if i.masked):
        for k in range(seeds):
            run = seed_run_name(item.completer, k)
            for b in profile.beams:
                name, source = layer_name(item, b, run), prediction_name(run, b)
                made = [ws.filtered / name / p.name for p in test]
                config = filter_stage.FilterConfig(filters=[f"confidence:min=0,keep={profile.confidence_keep:g}"],
                                                   depth="predicted", run=source, name=name)
                masked.append(Stage(f"filter-{name}", filter_stage.run, config, outputs=lambda m=made: m,
                                    inputs=lambda s=source: [ws.predictions / s / p.name for p in test],
                                    seed=seed + k, kind="filter"))
    pipe.run_all(masked, jobs)


def make_slam_stages(ws: Workspace, profile, test: list[Path], exact: bool, seed: int, seeds: int,
                     inputs: tuple = INPUTS) -> list[Stage]:
    """The SLAM runs of every input of ``inputs`` (each training seed of a trained one), beam count and test drive
    (``profile``: its ``beams``, ``slam`` settings and ``slam_frames``)."""
    stages = []
    for item in inputs:
        if item.needs_exact and not exact:
            continue
        trained = item.completer in LEARNED
        for k in range(seeds if trained else 1):
            run = seed_run_name(item.completer, k) if trained else None
            for b in (profile.beams if item.per_beam else [None]):
                layer, name = layer_name(item, b, run), slam_name(item, b, run)
                folder = None if item.completer in (None, "") else (ws.filtered if item.masked else ws.predictions)
                reference = layer if folder is None else f"{'filtered' if item.masked else 'predicted'}/{layer}"
                # measured: the B-beam pixels are the ICP sources, named (not left to the layer's record)
                # so that exact, which has no beam count of its own, takes each one
                mode = ({"sources": MEASURED, "measured": sparse_kind(b), "out": ws.slam / name}
                        if item.sources == MEASURED else {})
                for drive in test:
                    made = [ws.slam / name / f"{drive.stem}{suffix}"
                            for suffix in (".json", ".txt", ".kitti.txt", ".done")]
                    config = slam.SlamStageConfig(**{"odometry": "icp", **profile.slam}, depth=reference,
                                                  drive=[drive.stem], frames=profile.slam_frames, **mode)
                    source = [] if folder is None else [folder / layer / drive.name]
                    stages.append(Stage(f"slam-{name}-{drive.stem}", slam.run, config,
                                        outputs=lambda m=made: m, inputs=lambda d=drive, s=source: [d, *s],
                                        seed=seed + k if trained else None, kind="slam"))
    return stages


def workspace_beams(ws: Workspace, drives: list[str], stage: str = "score-beams") -> list[int]:
    """The beam counts of a workspace's beams table: those the experiment's scoring stage last ran with (its stamp in
    ``.reproduce/``), else those the drive files hold (64, their own sparse depth, and every ``sparse@B`` that
    ``prepare-kitti --beams`` added), most beams first."""
    import json

    from dcslam.io.drive import DriveFile
    from dcslam.workspace import drive_file

    stamp = ws.root / ".reproduce" / f"{stage}.json"
    try:
        beams = json.loads(stamp.read_text())["config"]["beams"] if stamp.exists() else None
    except (json.JSONDecodeError, KeyError, TypeError):
        beams = None  # a broken stamp: the drive files say
    if isinstance(beams, list) and beams and all(isinstance(b, int) for b in beams):
        return beams
    with DriveFile(drive_file(ws, drives[0])) as drive:
        kinds = drive.kinds
    extra = {int(k.partition("@")[2]) for k in kinds if k.startswith("sparse@") and k.partition("@")[2].isdigit()}
    return sorted({FULL_BEAMS} | extra, reverse=True)


def rebuild_tables(ws: Workspace, config, *, force: bool = False):
    """``dcslam score tables --table beams``: the beams table, its per-drive table, correlation and plot from the
    workspace's SLAM runs (``config``: a :class:`dcslam.stages.score.ScoreTablesConfig`; the beam counts those the
    drive files hold, :func:`workspace_beams`)."""
    from dcslam.workspace import select_drives

    drives = select_drives(ws, config.drive)
    table = BeamsTableConfig(beams=workspace_beams(ws, drives), drive=list(drives), out_dir=config.out_dir,
                             max_time_diff=config.max_time_diff, failure_threshold=config.failure_threshold)
    return run_table(ws, table, force=force)


BEAMS = Experiment("beams", "the beams experiment: every input at 64/32/16/8 LiDAR beams", PROFILES, compose,
                   rebuild_tables)
