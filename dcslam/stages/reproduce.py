"""``dcslam reproduce``: one registered experiment end to end in one command (``make reproduce-table-5-2``,
``make reproduce-beams``).

``--table`` names an experiment of :data:`dcslam.stages.experiments.EXPERIMENTS` (Table 5.2, Table 5.1, the beams
experiment); :func:`run` hands its stages to the stage engine (:mod:`dcslam.stages.pipeline`: a stage is skipped when
its outputs are up to date, outputs it did not make are never overwritten without ``--force``), locally (``jobs``
worker processes for the independent stages) or on Slurm (:mod:`dcslam.executor`). Before it starts, :func:`run`
logs the stages and their estimated cost (:mod:`dcslam.stages.reproduce_cost`; ``--dry-run``: only that);
``--print-config`` prints every stage's configuration (:mod:`dcslam.stages.reproduce_plan`). ``--profile`` chooses
the scale and ``--seeds`` the training seeds per trained run (default: the profile's).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from dcslam.errors import DcslamError
from dcslam.stages.config import option
from dcslam.stages.experiments import EXPERIMENTS
from dcslam.stages.experiments import experiment as _experiment
from dcslam.stages.pipeline import Pipeline
from dcslam.workspace import Workspace

# every registered experiment's profile names (each experiment checks that it has the one asked for)
PROFILE_NAMES = tuple(dict.fromkeys(name for table in EXPERIMENTS for name in _experiment(table).profiles))
EXECUTORS = ("local", "slurm")


@dataclass(frozen=True)
class ReproduceConfig:
    """Options of ``dcslam reproduce``."""

    table: str = option("5.2", choices=tuple(EXPERIMENTS), help="Experiment whose table to print: " + "; ".join(
                        f"{name}: {_experiment(name).help}" for name in EXPERIMENTS) + ".")
    profile: str = option("quick", choices=PROFILE_NAMES, help="quick (about 30 min on 2 CPU cores), smoke (a "
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
                         "poll_seconds and [slurm.<kind>] resources (cpus, mem_gb, time_min, gpus, stages_per_job).")
    seeds: int | None = option(None, min=1, help="Train every trained run with N seeds (seed, seed+1, ...; runs "
                               "<run>, <run>-s1, ...), each predicted, filtered and run through SLAM; the tables "
                               "report the spread over seeds and drives. Default: the profile's (1; study: 3).")
    camera: bool = option(True, help="Judge every SLAM run by the camera too (`dcslam slam --camera`, its "
                          "default: each step measured again from the colour images; a run that ends more than "
                          "0.5 m from the camera's trajectory is suspect, one within it is vouched for), so the "
                          "tables' failed counts follow it; one camera pass (2-5 CPU-s per 30 full-size frames) per "
                          "test drive and measured depth judges every input made from it. --no-camera: the depth's "
                          "own evidence alone (the profile is then named <profile>+no-camera, with its own unit "
                          "costs under --calibrate).")
    dry_run: bool = option(False, flags=("--dry-run",), help="Print the stages it would run and their estimated "
                           "cost, then exit without running or writing anything.")
    costs_from: Path | None = option(None, help="Workspace of a finished reproduction whose stage timings give the "
                                     "estimate's unit costs (default: this workspace's --calibrate, else its "
                                     "finished stages, else the probe's figures shipped with dcslam).")
    calibrate: bool = option(False, flags=("--calibrate",), help="First measure the estimate's unit costs on this "
                             "machine: a probe runs small samples of every stage kind at the profile's settings (a "
                             "minute or two of CPU) and writes them to <workspace>/.reproduce/calibration.json.")

    def __post_init__(self) -> None:
        if self.jobs < 1:
            raise DcslamError(f"--jobs must be >= 1, got {self.jobs}")
        if self.seeds is not None and self.seeds < 1:
            raise DcslamError(f"--seeds must be >= 1, got {self.seeds}")
        _experiment(self.table).profile(self.profile)  # an unknown table or profile: one line naming the choices
        if self.executor not in EXECUTORS:
            raise DcslamError(f"unknown executor {self.executor!r}; expected local or slurm")
        from dcslam.executor import SlurmSettings

        SlurmSettings.from_table(self.slurm)  # a mistake in [slurm] fails before anything runs



def run(ws: Workspace, config: ReproduceConfig, *, log: Callable[[str], None] = lambda line: None) -> Path | None:
    """Run the experiment at the profile's scale; return the Markdown file of the requested table. Logs what it will
    run and its estimated cost first (:mod:`dcslam.stages.reproduce_cost`); with ``dry_run`` that is all (None)."""
    from dcslam.stages.experiments.common import check_kitti_root
    from dcslam.stages.reproduce_cost import plan_text
    from dcslam.stages.reproduce_plan import profile_of, seeds_of

    if config.kitti is not None and not config.dry_run:
        check_kitti_root(config.kitti)  # before the plan: a wrong root is one line, not a plan and then an error
    executor = None if config.dry_run else make_executor(ws, config, log)  # a missing submitit/sbatch: one line too
    log(plan_text(ws, config))
    if config.dry_run:
        return None
    return reproduce(ws, profile_of(config), table=config.table, kitti_root=config.kitti, seed=config.seed, log=log,
                     force=config.force, jobs=config.jobs, seeds=seeds_of(config), executor=executor)


def reproduce(workspace: Workspace, profile, table: str = "5.2", kitti_root: Path | None = None, seed: int = 0,
              log: Callable[[str], None] = lambda line: None, force: bool = False, jobs: int = 1, seeds: int = 1,
              executor=None) -> Path:
    """Run experiment ``table`` (a name of :data:`~dcslam.stages.experiments.EXPERIMENTS`) at ``profile``'s scale
    (one of its profiles); return the Markdown file of its table.

    ``force``: overwrite outputs this pipeline did not make (see :meth:`Pipeline.run`); ``jobs``: worker processes
    for the independent stages; ``seeds``: training seeds per trained run (``seed`` … ``seed + seeds − 1``);
    ``executor``: where independent stages run instead (e.g. a :class:`~dcslam.executor.SlurmExecutor`; None:
    ``jobs`` local workers)."""
    from dcslam.locks import output_lock

    # one reproduce per workspace: a second one would replace kitti/ and drives/ under the first (a lock beside the
    # workspace, so that nothing inside it is touched before the lock is held)
    with output_lock(workspace.root, "workspace"):
        from dcslam import interrupt

        interrupt.keep(f"the stages that finished are kept in {workspace.root} (stamped in .reproduce/); rerun the "
                       "same command to go on from there (the stage that was running starts again)", final=True)
        with Pipeline(workspace, log, force=force, executor=executor) as pipe:
            return _experiment(table).compose(pipe, profile, kitti_root, seed, jobs, seeds)


def make_executor(ws: Workspace, config: ReproduceConfig, log: Callable[[str], None] = lambda line: None):
    """The executor ``config`` asks for: None (local workers, ``jobs`` of them) or a
    :class:`~dcslam.executor.SlurmExecutor` whose job folders and logs are ``<workspace>/logs/slurm/``."""
    if config.executor == "local":
        return None
    from dcslam.executor import SlurmExecutor, SlurmSettings

    return SlurmExecutor(ws.root / "logs" / "slurm", SlurmSettings.from_table(config.slurm), log=log)
