"""``dcslam score``: depth errors, trajectory errors, map chamfer of layers, and the tables of every experiment of
``dcslam reproduce`` (Tables 5.1 / 5.2, the beams table; ``score tables --table NAME``).

Four stages, one per ``dcslam score`` subcommand; each returns the table(s) it wrote (a CSV file, or the report).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from dcslam.errors import DcslamError
from dcslam.eval.depth import DEPARTURES_TEXT
from dcslam.eval.trajectory import EVO_MAX_TIME_DIFF_S
from dcslam.report.results import FAILURE_THRESHOLD
from dcslam.stages.config import option
from dcslam.stages.experiments import EXPERIMENTS
from dcslam.workspace import Workspace

DRIVE_HELP = "Drive name (repeatable); default: the test split of splits.json."
MAX_TIME_DIFF_HELP = ("Largest timestamp difference (seconds) at which an estimated pose is paired with a reference "
                      "pose, as evo's --t_max_diff (default evo's 0.01); only the paired poses are scored.")
FAILURE_HELP = ("A drive counts as a SLAM failure when its run was flagged suspect (rejected steps, too many degraded "
                "steps, or a drift bound; see `dcslam slam --help`) or its thesis localisation error exceeds this "
                "(m + rad).")
OUT_HELP = "CSV file to write (default under results/)."


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-_+." else "_" for c in text)


@dataclass
class ScoreResult:
    """A scored table and the CSV it was written to (its configuration beside it: the same name, ``.json``);
    ``shown`` is the part worth printing."""

    table: object
    out: Path
    shown: object = None


def _write(stage: str, config, table, out: Path, shown=None) -> ScoreResult:
    from dcslam.report.scores import write_table_csv
    from dcslam.stages.config import to_dict
    from dcslam.io.atomic import write_json_atomic
    from dcslam.workspace import stage_config

    write_table_csv(table, out, force=True)
    write_json_atomic(out.with_suffix(".json"), stage_config(stage, to_dict(config)), force=True)
    return ScoreResult(table, out, table if shown is None else shown)


def _file_or_layer_output(ws: Workspace, kind: str, path: Path | None, gt: Path | None, layer: str | None,
                          out: Path | None, force: bool, usage: str) -> tuple[str, Path]:
    """The preamble of the stages that score either ``--<file> FILE --gt REFERENCE`` or ``--layer NAME``.

    Fails with ``usage`` unless exactly one of the two forms is given; returns the name the scores go by (the
    layer's, or the file's stem) and the CSV to write (``out``, or ``results/<kind>_<name>.csv``), checked not to
    exist unless ``force``.
    """
    from dcslam.report.scores import check_outputs

    if (path is None) == (layer is None) or (path is not None and gt is None):
        raise DcslamError(usage)
    name = _slug(layer) if layer else _slug(path.stem)
    out = out or ws.results / f"{kind}_{name}.csv"
    check_outputs([out], force)
    return name, out


@dataclass(frozen=True)
class ScoreDepthConfig:
    """Options of ``dcslam score depth``."""

    layer: str | None = option(None, help="sparse, dense, sparse@<beams>, exact, a run or filter name (or "
                                          "predicted/<run>, filtered/<name>), or a folder of layer files. Required.")
    drive: list[str] = option(default_factory=list, help=DRIVE_HELP)
    out: Path | None = option(None, help=OUT_HELP)
    target: str = option("dense", choices=("dense", "exact"),
                         help="Reference depth: dense (annotated) or exact (noise-free; generated drives only).")
    raw: bool = option(False, flags=("--raw",), help="No devkit interpolation: score only the pixels where the "
                                                     "layer has depth.")
    devkit_exact: bool = option(False, flags=("--devkit-exact",), help=DEPARTURES_TEXT)

    def __post_init__(self) -> None:
        if not self.layer:
            raise DcslamError("give --layer NAME (sparse, dense, a run or filter name, or a folder of layer files)")
        if self.raw and self.devkit_exact:
            raise DcslamError("--raw and --devkit-exact cannot be combined: the devkit always interpolates")


def run_depth(ws: Workspace, config: ScoreDepthConfig, *, force: bool = False) -> ScoreResult:
    from dcslam.report.scores import check_outputs, depth_table
    from dcslam.workspace import select_drives

    suffix = "" if config.target == "dense" else f"_vs_{config.target}"
    out = config.out or ws.results / f"depth_{_slug(Path(config.layer).name)}{suffix}.csv"
    check_outputs([out], force)
    table = depth_table(ws, config.layer, select_drives(ws, config.drive), interpolate=not config.raw,
                        devkit_exact=config.devkit_exact, target=config.target)
    return _write("score-depth", config, table, out)


@dataclass(frozen=True)
class ScoreTrajectoryConfig:
    """Options of ``dcslam score trajectory``."""

    est: Path | None = option(None, help="Estimated trajectory: TUM, or a KITTI pose file (paired by index).")
    gt: Path | None = option(None, help="Reference: a drive file (.h5), a TUM file or a KITTI pose file.")
    layer: str | None = option(None, help="Score slam/<layer>/<drive>.txt against the drive files.")
    drive: list[str] = option(default_factory=list, help=DRIVE_HELP)
    out: Path | None = option(None, help=OUT_HELP)
    max_time_diff: float = option(EVO_MAX_TIME_DIFF_S, min=0.0, help=MAX_TIME_DIFF_HELP)


def run_trajectory(ws: Workspace, config: ScoreTrajectoryConfig, *, force: bool = False) -> ScoreResult:
    from dcslam.report.layers import load_pair, score_layer_trajectories
    from dcslam.report.scores import TRAJECTORY_SHOWN, trajectory_table
    from dcslam.report.tables import Table
    from dcslam.workspace import select_drives

    name, out = _file_or_layer_output(ws, "trajectory", config.est, config.gt, config.layer, config.out, force,
                                      "give either --est X.txt --gt REFERENCE, or --layer NAME")
    if config.layer:
        pairs = score_layer_trajectories(ws, config.layer, select_drives(ws, config.drive), config.max_time_diff)
    else:
        pairs = {config.est.stem: load_pair(config.est, config.gt, config.max_time_diff)}
    table = trajectory_table(pairs, f"trajectory errors of {name}")
    brief = Table(table.title, [c for c in table.columns if c.key in ("trajectory", *TRAJECTORY_SHOWN)],
                  table.rows, table.notes)
    return _write("score-trajectory", config, table, out, brief)


@dataclass(frozen=True)
class ScoreMapConfig:
    """Options of ``dcslam score map``."""

    map_path: Path | None = option(None, flags=("--map",), help="Map (PLY).")
    gt: Path | None = option(None, help="Ground-truth map (PLY).")
    layer: str | None = option(None, help="Score slam/<layer>/<drive>.ply.")
    gt_layer: str = option("dense", help="Layer whose slam maps are the ground truth.")
    drive: list[str] = option(default_factory=list, help=DRIVE_HELP)
    out: Path | None = option(None, help=OUT_HELP)


def run_map(ws: Workspace, config: ScoreMapConfig, *, force: bool = False) -> ScoreResult:
    from dcslam.eval.maps import score_map
    from dcslam.report.scores import map_table
    from dcslam.workspace import select_drives

    name, out = _file_or_layer_output(ws, "map", config.map_path, config.gt, config.layer, config.out, force,
                                      "give either --map X.ply --gt Y.ply, or --layer NAME")
    if config.layer:
        from dcslam.report.layers import slam_outputs

        scores = {d: score_map(slam_outputs(ws, config.layer, d)["map"], slam_outputs(ws, config.gt_layer, d)["map"])
                  for d in select_drives(ws, config.drive)}
    else:
        scores = {config.map_path.stem: score_map(config.map_path, config.gt)}
    table = map_table(scores, f"map of {name} against {config.gt_layer if config.layer else config.gt.name}")
    return _write("score-map", config, table, out)


@dataclass(frozen=True)
class ScoreTablesConfig:
    """Options of ``dcslam score tables``."""

    drive: list[str] = option(default_factory=list, help=DRIVE_HELP)
    out_dir: Path | None = option(None, flags=("--out",), aliases=("--out-dir",),
                                  help="Output folder (default: <workspace>/results).")
    devkit_exact: bool = option(False, flags=("--devkit-exact",), help=DEPARTURES_TEXT)
    max_time_diff: float = option(EVO_MAX_TIME_DIFF_S, min=0.0, help=MAX_TIME_DIFF_HELP)
    failure_threshold: float = option(FAILURE_THRESHOLD, min=0.0, help=FAILURE_HELP)
    table: str = option("5.2", choices=tuple(EXPERIMENTS), help="Experiment whose tables to build from the "
                        "workspace's outputs (those of `dcslam reproduce --table NAME`): 5.2 and 5.1 build both "
                        "Tables 5.1 and 5.2; beams the beams table, its per-drive table, correlation and plot.")

    def __post_init__(self) -> None:
        if self.table not in EXPERIMENTS:
            raise DcslamError(f"unknown table {self.table!r}; expected one of {', '.join(EXPERIMENTS)}")


def run_tables(ws: Workspace, config: ScoreTablesConfig, *, force: bool = False):
    """The tables of experiment ``config.table`` from the workspace's outputs: its own table builder
    (:attr:`dcslam.stages.pipeline.Experiment.tables`) for every experiment but Tables 5.1 / 5.2, which are
    :func:`run_thesis_tables`."""
    from dcslam.stages.experiments import experiment

    return experiment(config.table).tables(ws, config, force=force)


def run_thesis_tables(ws: Workspace, config: ScoreTablesConfig, *, force: bool = False):
    """Tables 5.1 and 5.2 with their plots; returns the :class:`dcslam.report.scores.Report` and writes the
    configuration beside them (``score-tables.json``)."""
    from dcslam.report.scores import build_report
    from dcslam.stages.config import to_dict
    from dcslam.io.atomic import write_json_atomic
    from dcslam.workspace import select_drives, stage_config

    report = build_report(ws, select_drives(ws, config.drive), out_dir=config.out_dir, force=force,
                          devkit_exact=config.devkit_exact, max_time_diff=config.max_time_diff,
                          failure_threshold=config.failure_threshold)
    report.written.append(write_json_atomic(report.written[0].parent / "score-tables.json",
                                            stage_config("score-tables", to_dict(config)), force=True))
    return report


@dataclass(frozen=True)
class ScorePageConfig:
    """Options of ``dcslam score page``."""

    page: Path = option(Path("RESULTS.md"), argument=True,
                        help="Markdown page whose <!-- table: FILE ... --> ... <!-- /table --> regions are rewritten "
                             "from their results files (paths relative to the page).")
    check: bool = option(False, flags=("--check",),
                         help="Write nothing; exit 1 naming the first region that differs from its file.")


@dataclass
class PageResult:
    """The page, its regions and those that changed (``written``: whether the page was rewritten)."""

    page: Path
    regions: int
    changed: tuple
    written: bool


def run_page(ws: Workspace, config: ScorePageConfig) -> PageResult:
    """Splice the page's marked regions from their results files (:mod:`dcslam.report.splice`); with ``check``,
    fail on the first region that differs instead of writing."""
    from dcslam.io.atomic import write_text_atomic
    from dcslam.report.splice import splice_page

    result = splice_page(config.page)
    if config.check:
        if result.changed:
            first = result.changed[0]
            raise DcslamError(f"{config.page}:{first.line}: the table from {first.source} differs from its file "
                              f"({len(result.changed)} region(s) differ); run `dcslam score page {config.page}`")
        return PageResult(config.page, len(result.regions), (), False)
    if result.changed:
        write_text_atomic(config.page, result.text, force=True)
    return PageResult(config.page, len(result.regions), result.changed, bool(result.changed))


@dataclass(frozen=True)
class ScoreCollectConfig:
    """Options of ``dcslam score collect``."""

    name: str | None = option(None, help="Folder name under --dest, e.g. table_5_2. Required.")
    source: Path | None = option(None, help="Results folder to copy (default: <workspace>/results).")
    dest: Path = option(Path("results"), help="Folder of committed results (the repository's results/).")
    profile: str | None = option(None, help="Profile the results were made with (recorded in provenance.json).")
    command: str | None = option(None, help="Command that made them, e.g. 'make reproduce-table-5-2'.")
    machine: str | None = option(None, help="Machine they were made on (default: CPU cores, architecture, system).")
    commit: str | None = option(None, help="Commit of the code that made them (default: the checkout's HEAD).")
    include: list[str] = option(default_factory=list, metavar="GLOB",
                                help="File patterns to copy (repeatable; default *.md and *.csv).")

    def __post_init__(self) -> None:
        from dcslam.workspace import plain_name

        if not self.name:
            raise DcslamError("give --name NAME: the folder under results/ to copy the results into")
        plain_name(self.name, "--name")


def run_collect(ws: Workspace, config: ScoreCollectConfig, *, force: bool = False):
    """Copy a workspace's results into ``<dest>/<name>/`` with their provenance
    (:func:`dcslam.report.provenance.collect_results`)."""
    from dcslam.report.provenance import DEFAULT_PATTERNS, collect_results

    return collect_results(config.source or ws.results, config.dest / config.name, profile=config.profile,
                           command=config.command, machine=config.machine, commit=config.commit,
                           patterns=tuple(config.include) or DEFAULT_PATTERNS, force=force)
