"""``dcslam reproduce --table surface`` (``make reproduce-surface``): do the completers that keep surfaces (scanline,
planefit, and a network that corrects planefit's scaffold) help SLAM where IP-Basic does not, when the LiDAR has
fewer beams? (docs/slam.md, the surface experiment)

The stages, through the stage engine and the beams experiment's machinery
(:mod:`dcslam.stages.experiments.beams`)::

    synth (unless a KITTI root is given) → prepare-kitti --beams 16,8 (plus depth/exact on generated drives)
    → train SparseConvNet on planefit's scaffold (:data:`SCAFFOLD_RECIPE`), and the same with a learned confidence
      (:data:`SURE`) (``seeds`` times each; only on drives with exact depth, their target)
    → predict IP-Basic, scanline, planefit and each trained run at every beam count
    → slam over every (input, beam count, test drive): sparse, each completion, exact depth, and each completion
      and exact depth again with measured ICP sources (the B-beam pixels against the completed map)
    → score: the surface table (the beams table over these rows, with the robust comparison against sparse), its
      per-drive CSV, the rank correlation of its depth metrics with localisation and a plot of localisation
      against beam count (``dcslam score tables --table surface`` rebuilds them)
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from dcslam.errors import DcslamError
from dcslam.report.seeds import seed_run_name
from dcslam.report.table_beams import (CLASSICAL_RUNS, CONFIDENT_RUN, FULL_BEAMS, SCAFFOLD_RUN, SURFACE_INPUTS,
                                       SURFACE_TRAINED)
from dcslam.stages import prepare, slam, train
from dcslam.stages.experiments.beams import (BeamsTableConfig, have_exact, make_slam_stages, predict_stages,
                                             run_table, train_stage, workspace_beams)
from dcslam.stages.experiments.common import make_drives, train_options
from dcslam.stages.pipeline import Experiment, Pipeline, Stage, profile_options
from dcslam.workspace import Workspace

NAME = "surface"


@dataclass(frozen=True)
class SurfaceProfile:
    """The scale of one surface experiment: drives, beam counts and the SLAM over the test drives."""

    name: str
    drives: int                          # generated drives
    frames: int                          # raw frames per generated drive (depth exists for frames 5 … N−6)
    slam_frames: int                     # frames of each test drive fed to SLAM
    beams: tuple[int, ...] = (64, 16, 8)
    split: tuple[int, int, int] | None = None  # train / val / test drives (None: prepare-kitti's split)
    slam: Mapping = field(default_factory=dict)  # SLAM settings other than the defaults (fields of SlamStageConfig)
    description: str = ""
    # run name (:data:`SURFACE_TRAINED`) → `dcslam train` options (checked against TrainStageConfig's fields);
    # empty: no row is trained
    train: Mapping[str, Mapping] = field(default_factory=dict)
    seeds: int = 1                       # training seeds per trained run (``dcslam reproduce --seeds`` overrides it)

    def __post_init__(self) -> None:
        object.__setattr__(self, "slam", profile_options(f"surface {self.name}", "slam", slam.SlamStageConfig,
                                                         self.slam, frozenset(("depth", "drive", "frames", "out"))))
        object.__setattr__(self, "train", {run: profile_options(f"surface {self.name}", f"train[{run!r}]",
                                                                train.TrainStageConfig, options,
                                                                frozenset(("name", "seed", "init")))
                                           for run, options in self.train.items()})
        unknown = sorted(set(self.train) - set(SURFACE_TRAINED))
        if unknown:
            raise DcslamError(f"surface profile {self.name}: train holds {', '.join(unknown)}, not a run of the "
                              f"surface table ({', '.join(SURFACE_TRAINED)})")
        if self.seeds < 1 or (self.seeds != 1 and not self.train):
            raise DcslamError(f"surface profile {self.name}: seeds must be 1 without a trained row (>= 1 with one), "
                              f"got {self.seeds}")
        if FULL_BEAMS not in self.beams:
            raise DcslamError(f"surface profile {self.name}: beams {self.beams} must include {FULL_BEAMS} (the "
                              "drive's own sparse depth, the reference of the others)")
        for b in self.beams:
            prepare.check_beams(b)
        if self.split is not None and (sum(self.split) != self.drives or min(self.split) < 1):
            raise DcslamError(f"surface profile {self.name}: split {self.split} must be >= 1 drive each and add up "
                              f"to {self.drives} drives")


# SparseConvNet correcting planefit's scaffold in inverse depth (a zero correction keeps its planes; untrained, the
# network is the scaffold), trained against exact depth with the geometry losses at the beams experiment's weights,
# MSE + 30 x L1, lr 1e-3 cosine, on the 64-, 16- and 8-beam inputs in turn (the question is asked at 16 and 8 beams)
SCAFFOLD_RECIPE = {"model": "sparse-conv", "correct_fill": True, "fill": "planefit", "fill_output": "inverse-residual",
                   "target": "exact", "normal_weight": 100.0, "plane_weight": 7.0, "edge_weight": 10.0,
                   "l1_weight": 30.0, "lr": 1e-3, "lr_schedule": "cosine"}
# the same with a learned confidence: its predictions leave empty what the head's gate is not sure it placed (within
# PointFusion's association gate of the exact depth); weighted to the order of the other terms at the start
SURE = {"confidence_weight": 10.0}
_MIX = {"input_mix": ["sparse", "sparse@16", "sparse@8"]}
_QUICK = {"epochs": 2, "max_frames": 31, "scale": 0.5}  # as the beams and Table 5.2 quick profiles


def _networks(options: Mapping) -> dict:
    """The trained rows' options: the network on planefit's scaffold, and the same with a learned confidence."""
    return {SCAFFOLD_RUN: {**SCAFFOLD_RECIPE, **options}, CONFIDENT_RUN: {**SCAFFOLD_RECIPE, **SURE, **options}}


PROFILES = {
    "smoke": SurfaceProfile(
        name="smoke", drives=3, frames=12, beams=(64, 16), slam_frames=2, slam={"iterations": 3, "voxel_size": 0.2},
        train=_networks({"input_mix": ["sparse", "sparse@16"], "epochs": 1, "max_frames": 2, "scale": 0.25}),
        description="a check that every stage runs (3 drives of 12 frames, 64 and 16 beams, tiny training, SLAM "
                    "over 2 frames): numbers mean nothing"),
    "quick": SurfaceProfile(
        name="quick", drives=8, frames=42, split=(3, 1, 4), slam_frames=30,
        train=_networks({**_MIX, **_QUICK}),
        description="8 generated drives of 42 frames (3 train / 1 val / 4 test, the drives of the beams and Table "
                    "5.2 quick profiles), 64/16/8 beams, SparseConvNet on planefit's scaffold trained 2 epochs at "
                    "half resolution (with and without a learned confidence), SLAM on the first 30 frames of each test "
                    "drive, with the depth's own and with the measured ICP sources"),
    "study": SurfaceProfile(
        name="study", drives=14, frames=42, split=(5, 1, 8), slam_frames=30, seeds=3,
        train=_networks({**_MIX, **_QUICK}),
        description="14 generated drives of 42 frames (5 train / 1 val / 8 test, the drives of the beams and Table "
                    "5.2 study profiles), 64/16/8 beams, SparseConvNet on planefit's scaffold (with and without a "
                    "learned confidence) with 3 training seeds (the quick recipe), SLAM on the first 30 frames of "
                    "each test drive; intervals and paired tests over seeds and drives"),
}


def run_surface_table(ws: Workspace, config: BeamsTableConfig, *, force: bool = False):
    """Write the surface table, its per-drive table, correlation and plot (``table_surface*``,
    ``surface_localisation.png``) and the configuration beside them (``table_surface.json``)."""
    return run_table(ws, config, force=force, name=NAME, catalogue=SURFACE_INPUTS)


def compose(pipe: Pipeline, profile: SurfaceProfile, kitti_root: Path | None = None, seed: int = 0,
            jobs: int = 1, seeds: int = 1) -> Path:
    """Hand every stage of the surface experiment to ``pipe`` in order; return the Markdown file of its table. Every
    trained run of the profile is trained ``seeds`` times (the ``k``-th :func:`seed_run_name` (run, k), seed
    ``seed + k``), each predicted and run through SLAM; the classical completers once. Without a trained run
    ``seeds`` does not apply: more than one is noted and every row runs once."""
    if seeds < 1:
        raise DcslamError(f"seeds must be >= 1, got {seeds}")
    if seeds > 1 and not profile.train:
        pipe.log(f"[note] profile {profile.name} trains nothing: --seeds {seeds} does not apply, every row runs once")
        seeds = 1
    ws = pipe.ws
    test, learn = make_drives(pipe, drives=profile.drives, frames=profile.frames, split=profile.split,
                              kitti_root=kitti_root, seed=seed, jobs=jobs,
                              beams=tuple(b for b in profile.beams if b != FULL_BEAMS))
    exact = kitti_root is None if pipe.planning else have_exact(test + learn)
    if not exact and not pipe.planning:
        pipe.log("[note] the drives have no exact depth (real KITTI): the exact rows and the networks trained "
                 "against it are left out")
    runs = list(profile.train) if exact else []
    pipe.run_all([train_stage(ws, (train_options(model="sparse-conv") | profile.train[run]).build(
        name=seed_run_name(run, k), seed=seed + k), learn, seed + k) for k in range(seeds) for run in runs], jobs)
    completers = [(c, None) for c in CLASSICAL_RUNS] + [(seed_run_name(run, k), seed + k) for k in range(seeds)
                                                         for run in runs]
    pipe.run_all(predict_stages(ws, profile.beams, test, completers), jobs)
    inputs = tuple(i for i in SURFACE_INPUTS if i.completer not in SURFACE_TRAINED or i.completer in runs)
    slam_stages = make_slam_stages(ws, profile, test, exact, seed, seeds, inputs=inputs)
    pipe.run_all(slam_stages, jobs)
    slam_outputs = [path for stage in slam_stages for path in stage.outputs()]
    table = BeamsTableConfig(beams=list(profile.beams), drive=[p.stem for p in test], jobs=jobs)
    pipe.run(Stage(f"score-{NAME}", run_surface_table, table,
                   outputs=lambda: [ws.results / f"table_{NAME}.md", ws.results / f"table_{NAME}_correlation.md"],
                   inputs=lambda: slam_outputs, kind="score"))
    return ws.results / f"table_{NAME}.md"


def rebuild_tables(ws: Workspace, config, *, force: bool = False):
    """``dcslam score tables --table surface``: the surface table, its per-drive table, correlation and plot from the
    workspace's SLAM runs (the beam counts of the last scoring stage, else those the drive files hold)."""
    from dcslam.workspace import select_drives

    drives = select_drives(ws, config.drive)
    table = BeamsTableConfig(beams=workspace_beams(ws, drives, f"score-{NAME}"), drive=list(drives),
                             out_dir=config.out_dir, max_time_diff=config.max_time_diff,
                             failure_threshold=config.failure_threshold)
    return run_surface_table(ws, table, force=force)


SURFACE = Experiment(NAME, "the surface experiment: sparse, IP-Basic, scanline, planefit, SparseConvNet on planefit's "
                     "scaffold and exact depth at 64/16/8 LiDAR beams, in depth mode and with measured sources",
                     PROFILES, compose, rebuild_tables)
