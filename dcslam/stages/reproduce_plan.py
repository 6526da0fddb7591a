"""What ``dcslam reproduce`` would run, without running it: the stages in order with their configurations
(``dcslam reproduce --print-config`` prints them as TOML)."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from dcslam.stages.experiments import experiment
from dcslam.stages.experiments.common import generated_names, split_by_counts
from dcslam.stages.pipeline import Pipeline, Stage
from dcslam.workspace import Workspace


def profile_of(config):
    """The profile a :class:`dcslam.stages.reproduce.ReproduceConfig` names, of the experiment it names (without the
    camera's verdict under ``--no-camera``: :func:`camera_profile`)."""
    return camera_profile(experiment(config.table).profile(config.profile), config.camera)


def camera_profile(profile, camera: bool):
    """``profile`` as it is when ``camera`` (the camera judges every SLAM run: ``dcslam slam``'s default), else with
    ``camera`` off in its SLAM settings and named ``<name>+no-camera`` (its unit costs are not the profile's: a run
    without the camera's pass costs less); a profile without SLAM settings as it is."""
    if camera or not hasattr(profile, "slam"):
        return profile
    return replace(profile, name=f"{profile.name}+no-camera", slam={**profile.slam, "camera": False})


def seeds_of(config) -> int:
    """Training seeds per trained run: ``--seeds``, else the profile's."""
    return config.seeds if config.seeds is not None else profile_of(config).seeds


class _Listing(Pipeline):
    """A pipeline that runs nothing and keeps the stages it is given, in order."""

    planning = True

    def __init__(self, workspace: Workspace, splits: dict[str, list[str]]):
        super().__init__(workspace)
        self.splits = splits
        self.stages: list[Stage] = []

    def run(self, stage: Stage):
        self.stages.append(stage)

    def run_all(self, stages: list[Stage], jobs: int = 1) -> None:
        self.stages += stages


def planned_splits(ws: Workspace, profile, kitti_root: Path | None = None) -> dict[str, list[str]]:
    """The split ``prepare-kitti`` will write: for generated drives (made here, or a generated root given as the
    KITTI root) their names split as the profile says (or in the thesis's proportion); for a real KITTI root the
    workspace's ``splits.json`` if there is one, else the thesis's. ``profile``: any experiment's (its ``drives``
    and ``split``)."""
    from dcslam.io.drive import read_splits
    from dcslam.stages.prepare import THESIS_SPLITS, proportional_splits
    from dcslam.synth.street.generate import drive_name

    if kitti_root is not None:
        if ws.splits.exists():
            return read_splits(ws.splits)
        names = generated_names(Path(kitti_root), profile.split) if profile.split else None
        return THESIS_SPLITS if names is None else split_by_counts(names, profile.split)
    names = sorted(drive_name(i) for i in range(profile.drives))
    return proportional_splits(names) if profile.split is None else split_by_counts(names, profile.split)


def planned_stages(workspace: Workspace, profile, table: str = "5.2", kitti_root: Path | None = None,
                   seed: int = 0, seeds: int = 1) -> list[Stage]:
    """The stages experiment ``table`` (:data:`~dcslam.stages.experiments.EXPERIMENTS`) would run at ``profile``
    (one of its profiles), in order, with their configurations (test drives from :func:`planned_splits`; ``seeds``
    training seeds per trained run, each stage's ``seed`` that of the run it trains or uses); nothing is run or
    written."""
    pipe = _Listing(workspace, planned_splits(workspace, profile, kitti_root))
    experiment(table).compose(pipe, profile, kitti_root, seed, 1, seeds)
    return pipe.stages


def stage_configs_toml(workspace: Workspace, config) -> str:
    """Every stage's configuration as TOML tables ``[stages."<stage>"]``, in the order they run, each line commented
    out (``#>`` + the TOML line), so that what ``--print-config`` prints stays a ``--config`` file of ``dcslam
    reproduce`` (``config``: its :class:`~dcslam.stages.reproduce.ReproduceConfig`); :func:`read_stage_configs`
    reads them back."""
    from dcslam.stages.config import to_toml

    stages = planned_stages(workspace, profile_of(config), config.table, config.kitti, config.seed, seeds_of(config))
    lines = [f"# the {len(stages)} stages this runs, in order, with their configurations (informative: a stage is "
             "skipped when its outputs are up to date; each line below is TOML after '#> ')"]
    for stage in stages:
        body = to_toml(stage.config, f"{stage.run.__module__}.{stage.run.__name__}")
        lines += [f"{STAGE_PREFIX}", f'{STAGE_PREFIX}[stages."{stage.name}"]']
        lines += [f"{STAGE_PREFIX}{line}" for line in body.splitlines()]
    return "\n".join(lines) + "\n"


STAGE_PREFIX = "#> "


def read_stage_configs(text: str) -> dict[str, dict]:
    """The stage configurations in what ``--print-config`` printed: ``{stage name: {option: value}}``."""
    import tomllib

    body = "\n".join(line[len(STAGE_PREFIX):] for line in text.splitlines() if line.startswith(STAGE_PREFIX.rstrip()))
    return tomllib.loads(body).get("stages", {})
