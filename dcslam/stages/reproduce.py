"""``dcslam reproduce``: the thesis's Tables 5.1 and 5.2 in one command (``make reproduce-table-5-2``).

The experiment composes the other stages' configurations and runs them in this process::

    synth (unless a KITTI root is given) → prepare-kitti → train × 4 recipes (+ 3 pose-loss runs) → predict
    (7 runs + IP-Basic) → filter (each thesis recipe's predictions) → slam (sparse, dense, every prediction and
    filtered layer; and the profile's ``long_layers`` over whole test drives, into ``slam-long/``) → score tables

A stage is skipped when its outputs exist, are newer than its inputs, and were made with the same configuration by
the same dcslam (version and a hash of its sources, recorded in ``<workspace>/.reproduce/<stage>.json``), so a rerun
after a change redoes only what changed. A stage's stamp says "running" while it runs, so an interrupted stage is
redone on the next run. Outputs that exist but were not made by this pipeline (no stamp, or changed after a finished
stage's stamp: a run trained by hand, a layer filtered by hand) are never overwritten without ``force`` (``dcslam
reproduce --force``); the error names the stage and the file. Training with several processes (``nproc``) still
launches through torchrun.
A profile chooses the scale: ``quick`` (the default: at least 4 test drives, about half an hour on 2 CPU cores),
``smoke`` (a check that every stage runs) or ``thesis`` (the thesis's 15 / 4 / 5 drives of 200 frames, for a GPU).
SLAM runs one stage per (layer, test drive); they are independent, so ``jobs`` > 1 runs them in that many worker
processes with one torch thread each. ``table="beams"`` runs the beams experiment instead
(:mod:`dcslam.stages.reproduce_beams`, which reuses this module's pipeline and :func:`make_drives`).

``seeds`` (``--seeds``, or the profile's; the ``study`` profile: 3) trains every trained run that many times, the
``k``-th named :func:`dcslam.report.seeds.seed_run_name` (``<run>`` for k = 0, so one seed keeps today's names and
tables; ``<run>-s<k>`` after) with seed ``seed + k``, and predicts, filters and runs SLAM on each; the untrained
layers run once. Every :class:`Stage` carries the training seed of the run it trains or uses. Before it starts,
:func:`run` logs the stages and their estimated cost (:mod:`dcslam.stages.reproduce_cost`; ``--dry-run``: only that).
Profiles and recipes are :class:`dcslam.stages.config.Options` of the stage configurations, checked when made.
"""
from __future__ import annotations

import json
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from dcslam.errors import DcslamError
from dcslam.stages import filter as filter_stage
from dcslam.stages import predict, prepare, score, slam, synth, train
from dcslam.report.seeds import seed_run_name
from dcslam.stages.config import Options, changed, code_version, option, to_dict
from dcslam.io.atomic import write_json_atomic
from dcslam.workspace import Workspace

def train_options(**values) -> Options:
    """Options of ``dcslam train`` (fields of :class:`dcslam.stages.train.TrainStageConfig`), checked when made."""
    return Options(train.TrainStageConfig, values)


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


def profile_options(profile: str, what: str, config: type, values, reserved=frozenset()) -> Options:
    """``values`` (a mapping of option → value) as :class:`Options` of ``config``; a :class:`DcslamError` naming the
    profile when a key is not a field of ``config``, has the wrong type or is one of ``reserved``."""
    try:
        options = values if isinstance(values, Options) and values.config is config else Options(config, values)
    except DcslamError as error:
        raise DcslamError(f"profile {profile}: {what}: {error}") from None
    clash = sorted(set(options) & reserved)
    if clash:
        raise DcslamError(f"profile {profile}: {what} sets {', '.join(clash)}, which the recipes or runs set")
    return options


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
TABLES = ("5.2", "5.1", "beams")
EXECUTORS = ("local", "slurm")


@dataclass(frozen=True)
class ReproduceConfig:
    """Options of ``dcslam reproduce``."""

    table: str = option("5.2", choices=TABLES, help="Table to print: 5.2 or 5.1 (5.1 stops after training), or "
                        "beams (the beams experiment: every input at 64/32/16/8 LiDAR beams; "
                        "dcslam.stages.reproduce_beams).")
    profile: str = option("quick", choices=tuple(PROFILES), help="quick (about 30 min on 2 CPU cores), smoke (a "
                          "few minutes; checks the stages, its numbers mean nothing), thesis (15/4/5 drives of 200 "
                          "frames; for a GPU) or study (3 seeds x 8 test drives; see --dry-run for its cost).")
    kitti: Path | None = option(None, help="Real KITTI root (raw/ and depth_completion/); default: generate "
                                           "KITTI-format drives with `dcslam synth`.")
    seed: int = option(0, help="Seed of the generated drives and of training.")
    force: bool = option(False, flags=("--force",), help="Overwrite outputs in the workspace that `dcslam "
                         "reproduce` did not make itself (runs trained, layers made by hand).")
    jobs: int = option(1, min=1, help="Worker processes for the SLAM runs (one per layer and test drive, one torch "
                                      "thread each); e.g. the number of CPU cores.")
    executor: str = option("local", choices=EXECUTORS, help="Where the independent stages (trainings of a round, "
                           "predictions, filters, SLAM runs) run: local (--jobs worker processes) or slurm (one "
                           "Slurm job each, through submitit; the workspace on a filesystem the nodes share; "
                           "partition, account, resources: the [slurm] table of --config).")
    slurm: dict = option(default_factory=dict, file_only=True, help="The [slurm] table of a --config file "
                         "(dcslam.executor.SlurmSettings): partition, account, qos, sbatch options, setup lines, "
                         "poll_seconds and [slurm.<kind>] resources (cpus, mem_gb, time_min, gpus).")
    seeds: int | None = option(None, min=1, help="Train every trained run with N seeds (seed, seed+1, ...; runs "
                               "<run>, <run>-s1, ...), each predicted, filtered and run through SLAM; the tables "
                               "report the spread over seeds and drives. Default: the profile's (1; study: 3).")
    dry_run: bool = option(False, flags=("--dry-run",), help="Print the stages it would run and their estimated "
                           "cost, then exit without running or writing anything.")
    costs_from: Path | None = option(None, help="Workspace of a finished reproduction whose stage timings give the "
                                     "estimate's unit costs (default: this workspace's, else a quick run's "
                                     "measured here, shipped with dcslam).")

    def __post_init__(self) -> None:
        if self.jobs < 1:
            raise DcslamError(f"--jobs must be >= 1, got {self.jobs}")
        if self.seeds is not None and self.seeds < 1:
            raise DcslamError(f"--seeds must be >= 1, got {self.seeds}")
        if self.table not in TABLES:
            raise DcslamError(f"unknown table {self.table!r}; expected 5.2, 5.1 or beams")
        if self.profile not in PROFILES:
            raise DcslamError(f"unknown profile {self.profile!r}; expected one of {', '.join(PROFILES)}")
        if self.executor not in EXECUTORS:
            raise DcslamError(f"unknown executor {self.executor!r}; expected local or slurm")
        from dcslam.executor import SlurmSettings

        SlurmSettings.from_table(self.slurm)  # a mistake in [slurm] fails before anything runs


@dataclass
class Stage:
    """One stage of the pipeline: a stage function, its configuration, and the files it reads and writes."""

    name: str
    run: Callable               # run(workspace, config, force=True) of a dcslam.stages module
    config: object              # that stage's configuration dataclass
    outputs: Callable[[], list[Path]]
    inputs: Callable[[], list[Path]] = lambda: []
    seed: int | None = None     # training seed of the run the stage trains or uses (None: no trained model)

    def record(self) -> dict:
        """What the stamp compares: the stage function, its configuration and the code that runs it."""
        return {"stage": f"{self.run.__module__}.{self.run.__name__}", "config": to_dict(self.config),
                "dcslam": code_version()}


def _mtime(paths: list[Path]) -> tuple[float, float]:
    times = [p.stat().st_mtime for p in paths if p.exists()]
    return (min(times), max(times)) if times else (0.0, 0.0)


class Pipeline:
    """Runs stages in order in this process, skipping those whose outputs are up to date."""

    planning = False  # True for a pipeline that only lists its stages (then ``splits`` is the split it plans with)

    def __init__(self, workspace: Workspace, log: Callable[[str], None] = lambda line: None, force: bool = False,
                 executor=None):
        self.ws = workspace
        self.force = force
        self.executor = executor  # a dcslam.executor.Executor for run_all; None: local workers (run_all's jobs)
        self.state = workspace.root / ".reproduce"
        self.log = log
        self.timings: dict[str, float] = {}

    def _stamp(self, stage: Stage) -> Path:
        return self.state / f"{stage.name}.json"

    def _record(self, stage: Stage) -> dict:
        """``stage.record()`` with paths inside the workspace written relative to it ("<workspace>/slam-long/…"), so
        that a moved or renamed workspace keeps its stages up to date; without a ``jobs`` option (how many processes
        made the outputs is not what they are)."""
        roots = {str(self.ws.root), str(self.ws.root.resolve())}

        def relative(value):
            for root in roots:
                if isinstance(value, str) and (value == root or value.startswith(root + "/")):
                    return "<workspace>" + value[len(root):]
            if isinstance(value, list):
                return [relative(v) for v in value]
            if isinstance(value, dict):
                return {k: relative(v) for k, v in value.items()}
            return value

        record = stage.record()
        record["config"] = {k: v for k, v in record["config"].items() if k != "jobs"}  # never changes the outputs
        return relative(record)

    def up_to_date(self, stage: Stage) -> bool:
        stamp = self._stamp(stage)
        if not stamp.exists():
            return False
        try:
            made = json.loads(stamp.read_text())
        except json.JSONDecodeError:
            return False
        if {k: made.get(k) for k in ("stage", "config", "dcslam")} != self._record(stage) or not made.get("complete"):
            return False
        outputs, inputs = stage.outputs(), stage.inputs()
        if not outputs or not all(p.exists() for p in outputs):
            return False
        return _mtime(outputs)[0] >= _mtime(inputs)[1]

    def foreign_output(self, stage: Stage) -> Path | None:
        """The first existing output of ``stage`` this pipeline did not make (no stamp, or changed after it)."""
        existing = [p for p in stage.outputs() if p.exists()]
        if not existing:
            return None
        stamp = self._stamp(stage)
        if not stamp.exists():
            return existing[0]
        try:
            if not json.loads(stamp.read_text()).get("complete"):
                return None  # this pipeline was interrupted while making them
        except json.JSONDecodeError:
            return existing[0]
        made = stamp.stat().st_mtime
        return next((p for p in existing if p.stat().st_mtime > made), None)

    def run(self, stage: Stage):
        """Run ``stage`` unless it is up to date; returns its result (None when skipped).

        Refuses (:class:`DcslamError`) to overwrite outputs the pipeline did not make unless ``force``.
        """
        if self.up_to_date(stage):
            self.log(f"[skip] {stage.name}: up to date")
            return None
        self._claim(stage)
        options = " ".join(f"{k}={v}" for k, v in changed(stage.config).items())
        self.log(f"[run]  {stage.name}: {stage.run.__module__.rsplit('.', 1)[-1]} {options}".rstrip())
        start = time.perf_counter()
        try:
            result = stage.run(self.ws, stage.config, force=True)
        except DcslamError as error:
            raise DcslamError(f"stage {stage.name} failed ({error}); fix it and rerun: finished stages will be "
                              "skipped") from None
        self._done(stage, time.perf_counter() - start)
        return result

    def _claim(self, stage: Stage) -> None:
        """Refuse outputs this pipeline did not make (unless ``force``); stamp ``stage`` as running."""
        foreign = None if self.force else self.foreign_output(stage)
        if foreign is not None:
            raise DcslamError(f"stage {stage.name} would overwrite {foreign}, which `dcslam reproduce` did not make; "
                              "move it away or pass --force to overwrite it")
        write_json_atomic(self._stamp(stage), {**self._record(stage), "complete": False})  # claims nothing until done

    def _done(self, stage: Stage, seconds: float) -> None:
        self.timings[stage.name] = seconds
        write_json_atomic(self._stamp(stage), {**self._record(stage), "complete": True, "seconds": seconds})

    def run_all(self, stages: list[Stage], jobs: int = 1) -> None:
        """Run independent ``stages`` (none reads another's outputs) through the pipeline's executor (default: a
        :class:`~dcslam.executor.LocalExecutor` of ``jobs`` worker processes; in this process when ``jobs`` is 1).

        Each stage is stamped as it finishes, so an interrupt keeps the finished ones. A stage that fails stops the
        others (workers terminated, Slurm jobs cancelled) and raises :class:`DcslamError` naming it (and, on Slurm,
        its job and log); it and the stopped ones stay stamped as not complete."""
        from dcslam.executor import LocalExecutor, Task

        todo = []
        for stage in stages:
            if self.up_to_date(stage):
                self.log(f"[skip] {stage.name}: up to date")
            else:
                todo.append(stage)
        executor = self.executor or LocalExecutor(jobs)
        if not todo:
            return
        if executor.in_process(len(todo)):
            for stage in todo:
                self.run(stage)
            return
        by_name = {}
        for stage in todo:
            self._claim(stage)
            options = " ".join(f"{k}={v}" for k, v in changed(stage.config).items())
            where = "worker" if isinstance(executor, LocalExecutor) else "job"
            self.log(f"[run]  {stage.name}: {stage.run.__module__.rsplit('.', 1)[-1]} {options} ({where})"
                     if options else f"[run]  {stage.name}: {stage.run.__module__.rsplit('.', 1)[-1]} ({where})")
            by_name[stage.name] = stage
        outcomes = executor.run([Task(s.name, s.run, s.config, self.ws) for s in todo])
        try:
            for outcome in outcomes:
                stage = by_name[outcome.task.name]
                if not outcome.ok:
                    details = outcome.task.labels()
                    if outcome.job is not None:
                        details.append(f"Slurm job {outcome.job}, log {outcome.log}")
                    raise DcslamError(f"stage {stage.name} failed ({outcome.error})"
                                      f"{''.join(f'; {d}' for d in details)}; fix it and rerun: finished stages will "
                                      "be skipped")
                self._done(stage, outcome.seconds)
        finally:
            outcomes.close()  # stops what is still running when this gave up early


def profile_of(config: ReproduceConfig):
    """The profile ``config`` names: a :class:`Profile`, or for the beams table a
    :class:`dcslam.stages.reproduce_beams.BeamsProfile`."""
    if config.table == "beams":
        from dcslam.stages.reproduce_beams import PROFILES as BEAMS_PROFILES

        return BEAMS_PROFILES[config.profile]
    return PROFILES[config.profile]


def seeds_of(config: ReproduceConfig) -> int:
    """Training seeds per trained run: ``--seeds``, else the profile's."""
    return config.seeds if config.seeds is not None else profile_of(config).seeds


def run(ws: Workspace, config: ReproduceConfig, *, log: Callable[[str], None] = lambda line: None) -> Path | None:
    """Run the experiment at the profile's scale; return the Markdown file of the requested table. Logs what it will
    run and its estimated cost first (:mod:`dcslam.stages.reproduce_cost`); with ``dry_run`` that is all (None)."""
    from dcslam.stages.reproduce_cost import plan_text

    if config.kitti is not None and not config.dry_run:
        check_kitti_root(config.kitti)  # before the plan: a wrong root is one line, not a plan and then an error
    executor = None if config.dry_run else make_executor(ws, config, log)  # a missing submitit/sbatch: one line too
    log(plan_text(ws, config))
    if config.dry_run:
        return None
    seeds = seeds_of(config)
    if config.table == "beams":
        from dcslam.stages import reproduce_beams

        return reproduce_beams.reproduce(ws, profile_of(config), kitti_root=config.kitti, seed=config.seed, log=log,
                                         force=config.force, jobs=config.jobs, seeds=seeds,
                                         executor=executor)
    return reproduce(ws, PROFILES[config.profile], table=config.table, kitti_root=config.kitti, seed=config.seed,
                     log=log, force=config.force, jobs=config.jobs, seeds=seeds, executor=executor)


def make_executor(ws: Workspace, config: ReproduceConfig, log: Callable[[str], None] = lambda line: None):
    """The executor ``config`` asks for: None (local workers, ``jobs`` of them) or a
    :class:`~dcslam.executor.SlurmExecutor` whose job folders and logs are ``<workspace>/logs/slurm/``."""
    if config.executor == "local":
        return None
    from dcslam.executor import SlurmExecutor, SlurmSettings

    return SlurmExecutor(ws.root / "logs" / "slurm", SlurmSettings.from_table(config.slurm), log=log)


def split_by_counts(names: list[str], counts: tuple[int, int, int]) -> dict[str, list[str]]:
    """The profile's split of drive ``names`` (sorted): the first ``counts[0]`` train, then val, then test."""
    n_train, n_val, _ = counts
    names = sorted(names)
    return {"train": names[:n_train], "val": names[n_train:n_train + n_val], "test": names[n_train + n_val:]}


def _split_file(ws: Workspace) -> Path:
    return ws.root / ".reproduce" / "splits.json"


def generated_names(kitti: Path, counts: tuple[int, int, int]) -> list[str] | None:
    """The drive names of a generated root (``dcslam synth``'s ``SYNTHETIC`` marker) holding as many drives as a
    profile splits (``counts``), sorted; None for real KITTI, a missing root or another number of drives (which
    ``prepare-kitti`` then splits in the thesis's proportion)."""
    from dcslam.io.kitti import dataset_source, find_drives

    if not Path(kitti).is_dir() or dataset_source(kitti) != "synthetic":
        return None
    names = sorted({d.name for d in find_drives(kitti)})
    return names if len(names) == sum(counts) else None


def _profile_splits(ws: Workspace, kitti: Path, counts: tuple[int, int, int]) -> Path:
    """Write the profile's split of the generated drives (sorted by name: train, then val, then test)."""
    from dcslam.io.kitti import find_drives

    names = sorted({d.name for d in find_drives(kitti)})
    if len(names) != sum(counts):
        raise DcslamError(f"{kitti}: {len(names)} drives, the profile splits {sum(counts)}; remove {kitti} and rerun")
    path = _split_file(ws)
    import json

    splits = split_by_counts(names, counts)
    if not path.exists() or json.loads(path.read_text()) != splits:
        write_json_atomic(path, splits, force=True)
    return path


def training_rounds(runs: dict[str, dict]) -> list[list[str]]:
    """Run names (keys of ``runs``: name → training options) in the order they can be trained, as two rounds of
    independent runs: those from scratch, then those that fine-tune one of them (``init``)."""
    first = [name for name, options in runs.items() if options.get("init") is None]
    return [first, [name for name in runs if name not in first]]


def check_kitti_root(kitti: Path) -> None:
    """A :class:`DcslamError` unless ``kitti`` is a folder."""
    if not Path(kitti).is_dir():
        raise DcslamError(f"KITTI root {kitti} does not exist or is not a folder; pass --kitti DIR")


def make_drives(pipe: Pipeline, *, drives: int, frames: int, split: tuple[int, int, int] | None,
                kitti_root: Path | None = None, seed: int = 0, beams: tuple[int, ...] = (), jobs: int = 1
                ) -> tuple[list[Path], list[Path]]:
    """The synth (unless ``kitti_root``; ``jobs`` drives at once) and prepare-kitti stages (``beams``: the extra
    sparse inputs of ``prepare-kitti --beams``); returns the drive files (test, train + val). A planning pipeline
    (``--print-config``) runs nothing and reads the split it plans with."""
    ws = pipe.ws
    kitti = Path(kitti_root) if kitti_root else ws.kitti
    if kitti_root is None:
        pipe.run(Stage("synth", synth.run, synth.SynthConfig(drives=drives, frames=frames, seed=seed, jobs=jobs),
                       outputs=lambda: [ws.kitti / "SYNTHETIC"]))
    elif not pipe.planning:  # a plan may name a root that is not mounted here
        check_kitti_root(kitti)
    split_file = None
    if kitti_root is None and split:
        split_file = _split_file(ws) if pipe.planning else _profile_splits(ws, kitti, split)
    elif split and not pipe.planning and generated_names(kitti, split) is not None:
        # drives generated before (`dcslam synth`, or another workspace's kitti/) split as the profile splits its own
        split_file = _profile_splits(ws, kitti, split)
    pipe.run(Stage("prepare-kitti", prepare.run, prepare.PrepareConfig(kitti=kitti, splits=split_file,
                                                                       beams=list(beams)),
                   outputs=lambda: [ws.splits, *sorted(ws.drives.glob("*.h5"))],
                   inputs=lambda: [p for p in (kitti / "SYNTHETIC", split_file) if p is not None and p.exists()]))
    from dcslam.io.drive import read_splits

    splits = pipe.splits if pipe.planning else read_splits(ws.splits)
    return ([ws.drives / f"{name}.h5" for name in splits["test"]],
            [ws.drives / f"{name}.h5" for name in splits["train"] + splits["val"]])


def reproduce(workspace: Workspace, profile: Profile, table: str = "5.2", kitti_root: Path | None = None,
              seed: int = 0, log: Callable[[str], None] = lambda line: None, force: bool = False,
              jobs: int = 1, seeds: int = 1, executor=None) -> Path:
    """Run the experiment at ``profile``'s scale; return the Markdown file of the requested table.

    ``force``: overwrite outputs this pipeline did not make (see :meth:`Pipeline.run`); ``jobs``: worker processes
    for the independent SLAM stages; ``seeds``: training seeds per trained run (``seed`` … ``seed + seeds − 1``);
    ``executor``: where independent stages run instead (e.g. a :class:`~dcslam.executor.SlurmExecutor`; None:
    ``jobs`` local workers)."""
    return compose(Pipeline(workspace, log, force=force, executor=executor), profile, table, kitti_root, seed, jobs,
                   seeds)


def compose(pipe: Pipeline, profile: Profile, table: str, kitti_root: Path | None, seed: int,
            jobs: int = 1, seeds: int = 1) -> Path:
    """Hand every stage of the experiment to ``pipe`` in order; return the Markdown file of ``table``.

    Every recipe is trained ``seeds`` times (the ``k``-th run named :func:`seed_run_name` (recipe, k), trained with
    seed ``seed + k``; a fine-tuned recipe starts from the ``k``-th run of its source), and every run is predicted,
    filtered and run through SLAM; the untrained layers (sparse, dense, IP-Basic) once."""
    if table not in ("5.2", "5.1"):
        raise DcslamError(f"unknown table {table!r}; expected 5.1 or 5.2 (the beams table: "
                          "dcslam.stages.reproduce_beams.reproduce)")
    if seeds < 1:
        raise DcslamError(f"seeds must be >= 1, got {seeds}")
    ws = pipe.ws
    test, learn = make_drives(pipe, drives=profile.drives, frames=profile.frames, split=profile.split,
                              kitti_root=kitti_root, seed=seed, jobs=jobs)

    recipes = {**RECIPES, **POSE_RECIPES}
    runs = {}  # run name → (its recipe, its training seed), seed by seed in the recipes' order
    trainings = {}  # run name → its stage; those that fine-tune another run (``init``) wait for it
    for k in range(seeds):
        for recipe in recipes:
            config = profile.train_config(recipe, seed, k)
            run_name = config.name
            runs[run_name] = (recipe, seed + k)
            init = [ws.runs / config.init / "model.pt"] if config.init else []
            made = [ws.runs / run_name / "model.pt", ws.runs / run_name / "metrics.jsonl"]
            trainings[run_name] = Stage(f"train-{run_name}", train.run, config, outputs=lambda made=made: made,
                                        inputs=lambda init=init: learn + init, seed=seed + k)
    for names in training_rounds({name: recipes[recipe] for name, (recipe, _) in runs.items()}):
        pipe.run_all([trainings[r] for r in names], jobs)
    if table == "5.1":
        return _tables(pipe, ws, "5.1", inputs=[ws.runs / r / "metrics.jsonl" for r in runs])

    layers = {}  # layer name → (files it is made of, the layer's reference, training seed or None)
    for kind in ("sparse", "dense"):
        layers[kind] = (test, kind, None)
    predictions = []
    for run_name in [*runs, IP_BASIC]:
        made = [ws.predictions / run_name / p.name for p in test]
        config = predict.PredictConfig(run=run_name) if run_name in runs else predict.PredictConfig(model=run_name)
        run_seed = runs[run_name][1] if run_name in runs else None
        predictions.append(Stage(f"predict-{run_name}", predict.run, config, outputs=lambda made=made: made,
                                 inputs=lambda r=run_name: [ws.runs / r / "model.pt", *test] if r in runs else test,
                                 seed=run_seed))
        layers[run_name] = (made, f"predicted/{run_name}", run_seed)
    pipe.run_all(predictions, jobs)
    filters = []  # independent of one another: each reads one run's predictions
    for run_name, (recipe, run_seed) in runs.items():
        if recipe not in RECIPES:  # the thesis's recipes only: filtering the pose runs too would lengthen the profile
            continue
        for fname, specs in profile.filters.items():
            name = f"{run_name}+{fname}"
            made = [ws.filtered / name / p.name for p in test]
            config = filter_stage.FilterConfig(filters=list(specs), depth="predicted", run=run_name, name=name)
            filters.append(Stage(f"filter-{name}", filter_stage.run, config, outputs=lambda made=made: made,
                                 inputs=lambda m=layers[run_name][0]: m, seed=run_seed))
            layers[name] = (made, f"filtered/{name}", run_seed)
    pipe.run_all(filters, jobs)
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


def _slam_stage(ws: Workspace, profile: Profile, layer: str, reference: str, drive: Path, source,
                whole: bool = False, seed: int | None = None) -> Stage:
    """SLAM of ``layer`` (depth ``reference``) over one test drive: its first ``profile.slam_frames`` frames into
    ``slam/<layer>/`` (Table 5.2), or with ``whole`` every frame into ``slam-long/<layer>/`` (its long-drive table)."""
    out = (ws.slam_long if whole else ws.slam) / layer
    config = slam.SlamStageConfig(**{"odometry": "icp", **profile.slam}, depth=reference, drive=[drive.stem],
                                  frames=0 if whole else profile.slam_frames, out=out if whole else None)
    made = [out / f"{drive.stem}{suffix}" for suffix in (".json", ".txt", ".kitti.txt")]
    return Stage(f"{'slam-long' if whole else 'slam'}-{layer}-{drive.stem}", slam.run, config,
                 outputs=lambda: made, inputs=lambda: [drive, source], seed=seed)


def _tables(pipe: Pipeline, ws: Workspace, table: str, inputs: list[Path]) -> Path:
    name = f"table_{table.replace('.', '_')}.md"
    made = [ws.results / name] + ([ws.results / "table_5_2_correlation.md"] if table == "5.2" else [])
    pipe.run(Stage("score-tables", score.run_tables, score.ScoreTablesConfig(), outputs=lambda: made,
                   inputs=lambda: inputs))
    return ws.results / name
