"""Table 5.2 of the thesis over the test drives, with the spread that makes its rows comparable.

For the four trained recipes, sparse and dense depth without a model, and beyond the thesis IP-Basic and each model
after its best filter (the filtered layer of that model with the lowest localisation accuracy): the thesis's
localisation accuracy, MAE / RMSE / iMAE / iRMSE (KITTI devkit, see :data:`dcslam.eval.depth.DEPARTURES_TEXT`),
ATE / RPE (evo) and KITTI drift, each as the mean over the test drives with its spread (:mod:`dcslam.report.spread`),
the median localisation, the failure count and whether the row differs from sparse depth beyond the spread. Every
row carries the settings of the SLAM runs behind it. Every number of ours is computed here from files; a row whose
inputs are missing is kept, with its values empty and a note naming what is missing.
"""
from __future__ import annotations

import functools
import math
import json
from dataclasses import dataclass, field, replace
from pathlib import Path

from dcslam.errors import DcslamError
from dcslam.eval.depth import DepthErrors, mean_errors
from dcslam.eval.surface import SURFACE_METRICS, SurfaceErrors
from dcslam.eval.trajectory import EVO_MAX_TIME_DIFF_S
from dcslam.report.layers import (SURFACE_FRAMES, TrajectoryPair, find_layer, score_layer_depth,
                                  score_layer_surface, score_layer_trajectories, slam_settings, surface_target)
from dcslam.report.seeds import paired, seed_groups
from dcslam.report.spread import TWO_LEVEL_METHOD, seed_spread, spread
from dcslam.report.tables import IP_BASIC, RECIPES, Column, RunSummary, Table
from dcslam.workspace import Workspace

#: A drive's SLAM counts as failed above this thesis localisation error (m + rad) over its frames.
FAILURE_THRESHOLD = 1.0
DEPTH_KEYS = ("mae_mm", "rmse_mm", "imae_per_km", "irmse_per_km")
DRIFT_KEYS = ("kitti_t_rel_percent", "kitti_r_rel_deg_per_100m")
SPREAD_COLUMNS = [Column("localisation", "localisation", "{:.4f}"), Column("mae_mm", "MAE (mm)", "{:.1f}"),
                  Column("rmse_mm", "RMSE (mm)", "{:.1f}"), Column("imae_per_km", "iMAE (1/km)", "{:.2f}"),
                  Column("irmse_per_km", "iRMSE (1/km)", "{:.2f}"), Column("ate_rmse_m", "ATE (m)", "{:.3f}"),
                  Column("rpe_rmse_m", "RPE (m)", "{:.3f}"), Column("rpe_rmse_deg", "RPE (°)", "{:.3f}"),
                  Column("kitti_t_rel_percent", "t_rel (%)", "{:.2f}"),
                  Column("kitti_r_rel_deg_per_100m", "r_rel (°/100 m)", "{:.3f}"),
                  # the surface errors (dcslam.eval.surface) of a sample of each drive's frames (score_layer)
                  Column("normal_mean_deg", "normal mean (°)", "{:.1f}"),
                  Column("normal_median_deg", "normal median (°)", "{:.1f}"),
                  Column("p2p_mean_m", "p2p mean (m)", "{:.3f}"), Column("p2p_rmse_m", "p2p RMSE (m)", "{:.3f}"),
                  Column("flying_share", "flying share", "{:.3f}")]
SPREAD_KEYS = tuple(c.key for c in SPREAD_COLUMNS)
TABLE_5_2_COLUMNS = [
    Column("method", "method"), Column("layer", "layer"), Column("drives", "drives"), Column("failures", "failed"),
    Column("localisation_text", "localisation accuracy"), Column("localisation_median_text", "median"),
    Column("thesis_localisation_text", "thesis"), Column("vs_sparse", "vs sparse"),
    Column("mae_mm_text", "MAE (mm)"), Column("thesis_mae_text", "thesis MAE"),
    Column("rmse_mm_text", "RMSE (mm)"), Column("thesis_rmse_text", "thesis RMSE"),
    Column("imae_per_km_text", "iMAE (1/km)"), Column("irmse_per_km_text", "iRMSE (1/km)"),
    Column("ate_rmse_m_text", "ATE RMSE (m)"), Column("rpe_rmse_m_text", "RPE RMSE (m)"),
    Column("rpe_rmse_deg_text", "RPE RMSE (°)"), Column("kitti_t_rel_percent_text", "t_rel (%)"),
    Column("kitti_r_rel_deg_per_100m_text", "r_rel (°/100 m)"), Column("slam_settings", "SLAM settings"),
    Column("notes", "why —")]


@dataclass
class LayerResult:
    """Scores of one depth layer over the test drives (empty where its inputs are missing): ``depth`` maps each
    drive to its mean depth errors, ``surface`` to the mean surface errors of its sampled frames against the
    ``surface_target`` depth (``surface_frames``: how many of them had a reference), ``pairs`` to its trajectory,
    ``settings`` to the settings of its SLAM run (:func:`dcslam.report.layers.slam_settings`)."""

    label: str
    layer: str
    depth: dict[str, DepthErrors] = field(default_factory=dict)
    pairs: dict[str, TrajectoryPair] = field(default_factory=dict)
    settings: dict[str, dict] = field(default_factory=dict)
    surface: dict[str, SurfaceErrors] = field(default_factory=dict)
    surface_frames: dict[str, int] = field(default_factory=dict)
    surface_target: str | None = None
    missing: list[str] = field(default_factory=list)
    failure_threshold: float = FAILURE_THRESHOLD
    seed: int | None = None     # training seed of the run behind the layer (None: no trained model)

    @functools.cached_property
    def scores(self) -> dict:
        """:class:`~dcslam.eval.trajectory.TrajectoryScores` of each drive."""
        return {drive: p.score() for drive, p in self.pairs.items()}

    @property
    def localisation(self) -> float | None:
        if not self.pairs:
            return None
        return sum(s.localisation for s in self.scores.values()) / len(self.scores)

    def failed(self, drive: str) -> bool:
        """A drive's SLAM failed: its run was flagged suspect, or its localisation error is beyond the threshold."""
        return bool(self.settings.get(drive, {}).get("suspect")) or \
            self.scores[drive].localisation > self.failure_threshold

    def run_settings(self) -> dict:
        """The SLAM settings shared by every drive of this row; fails when its drives were run differently."""
        found = {}
        for drive, settings in self.settings.items():
            for key, value in settings.items():
                if key == "suspect":
                    continue
                if key in found and found[key][1] != value:
                    raise DcslamError(f"row {self.label} ({self.layer}) mixes SLAM runs made with {key}="
                                      f"{found[key][1]} ({found[key][0]}) and {key}={value} ({drive}); rerun "
                                      f"`dcslam slam --depth {self.layer} --force` on every test drive")
                found.setdefault(key, (drive, value))
        return {k: v for k, (_, v) in found.items()}

    def localisation_by_seed(self) -> dict[int | None, dict[str, float]]:
        """``{seed: {drive: localisation}}`` (one seed: this layer's); see :func:`dcslam.report.seeds.paired`."""
        return {self.seed: {d: s.localisation for d, s in self.scores.items()}}

    def localisation_spread(self):
        """The :class:`dcslam.report.spread.Spread` of the localisation over the drives."""
        return spread([s.localisation for s in self.scores.values()])

    def with_failure_threshold(self, threshold: float) -> "LayerResult":
        return replace(self, failure_threshold=threshold)

    def per_drive_rows(self) -> list[tuple[int | None, str, dict]]:
        """``(seed, drive, figures)`` of every drive (:meth:`per_drive`)."""
        return [(self.seed, drive, values) for drive, values in self.per_drive().items()]

    def per_drive(self) -> dict[str, dict]:
        """Every figure of each drive: ``{drive: {metric: value}}`` (the per-drive CSV's rows)."""
        rows = {}
        for drive in sorted(set(self.depth) | set(self.pairs)):
            row = {}
            if drive in self.depth:
                row.update({m: getattr(self.depth[drive], m) for m in DEPTH_KEYS})
            if drive in self.surface:  # a metric no sampled frame defines (NaN) is left out
                row.update({m: v for m in SURFACE_METRICS
                            if not math.isnan(v := getattr(self.surface[drive], m))},
                           surface_frames=self.surface_frames.get(drive))
            if drive in self.pairs:
                score = self.scores[drive]
                drift = score.drift.overall if score.drift is not None else None
                row.update(poses=score.poses, localisation=score.localisation,
                           ate_rmse_m=None if score.ate_aligned is None else score.ate_aligned.rmse,
                           rpe_rmse_m=None if score.rpe_trans_m is None else score.rpe_trans_m.rmse,
                           rpe_rmse_deg=None if score.rpe_rot_deg is None else score.rpe_rot_deg.rmse,
                           kitti_t_rel_percent=None if drift is None else drift.t_rel_percent,
                           kitti_r_rel_deg_per_100m=None if drift is None else drift.r_rel_deg_per_100m,
                           path_m=None if score.drift is None else score.drift.path_length_m,
                           failed=self.failed(drive), pairing=self.pairs[drive].summary(),
                           **{k: v for k, v in self.settings.get(drive, {}).items() if k != "suspect"})
            rows[drive] = row
        return rows

    def row(self, reference: "LayerResult | None" = None) -> dict:
        """The row of Table 5.2: for each figure its mean over drives (``<metric>``) and spread (``<metric>_std``,
        ``_ci_low``, ``_ci_high``, ``_median``, and ``<metric>_text``: mean ± 95 % half-width); ``failures``; and
        ``vs_<reference>``: whether its localisation differs from ``reference``'s beyond the spread (paired by
        drive)."""
        row = {"method": self.label, "layer": self.layer, "missing": "; ".join(self.missing) or None}
        per_drive = self.per_drive()
        for key in SPREAD_KEYS:
            values = [r[key] for r in per_drive.values() if r.get(key) is not None]
            if not values:
                continue
            if key in DRIFT_KEYS:
                row[f"{key}_drives"] = len(values)
            elif len(values) != len(per_drive):
                continue  # a figure some drives lack (e.g. aligned ATE of a straight line) is not averaged
            fmt = next(c.fmt for c in SPREAD_COLUMNS if c.key == key)
            if not all(math.isfinite(v) for v in values):  # e.g. the depth errors of a layer left empty
                row.update({key: math.inf, f"{key}_text": f"inf ({sum(not math.isfinite(v) for v in values)} "
                                                          "drive(s) without a finite value)"})
                continue
            sp = spread(values)
            row.update({key: sp.mean, f"{key}_std": sp.std, f"{key}_ci_low": sp.ci_low,
                        f"{key}_ci_high": sp.ci_high, f"{key}_median": sp.median, f"{key}_text": sp.text(fmt)})
        if self.pairs:
            row["drives"] = len(self.pairs)
            row["failures"] = sum(self.failed(d) for d in self.pairs)
            row["localisation_median_text"] = f"{row['localisation_median']:.4f}"
            if reference is self:
                row["vs_sparse"] = "reference"
            elif reference is not None and reference.pairs:
                row["vs_sparse"] = VERDICTS[paired(self, reference)[0]]
        if self.pairs and not any(f"{k}_drives" in row for k in DRIFT_KEYS):
            longest = max(r.get("path_m") or 0.0 for r in per_drive.values())
            row["drift_note"] = f"drives too short (longest {longest:.0f} m < 100 m)"
        return row


VERDICTS = {None: "one drive", True: "differs", False: "within spread"}


@dataclass
class SeedResults:
    """One row over the runs of a recipe trained with several seeds: ``members`` are the :class:`LayerResult` of
    each seed's layer (their ``seed`` set), scored on the same drives. Every figure of :meth:`row` is the mean over
    seeds × drives with the two-level bootstrap interval (:func:`dcslam.report.spread.seed_spread`), its
    seed-to-seed spread (the std of the per-seed means) and the failed runs among all seeds × drives. ``layer``,
    ``pairs`` and ``depth`` are the first seed's (plots and depth examples show one seed)."""

    label: str
    members: list[LayerResult]

    def __post_init__(self) -> None:
        if len(self.members) < 2:
            raise DcslamError(f"row {self.label}: a row over seeds needs at least 2 runs, got {len(self.members)}")

    layer = property(lambda self: self.members[0].layer)
    layers = property(lambda self: [m.layer for m in self.members])
    seeds = property(lambda self: [m.seed for m in self.members])
    failure_threshold = property(lambda self: self.members[0].failure_threshold)
    surface_target = property(lambda self: self.members[0].surface_target)
    missing = property(lambda self: [f"{m.layer}: {text}" for m in self.members for text in m.missing])

    @property
    def pairs(self) -> dict:
        return self.members[0].pairs if all(m.pairs for m in self.members) else {}

    @property
    def depth(self) -> dict:
        return self.members[0].depth if all(m.depth for m in self.members) else {}

    @property
    def localisation(self) -> float | None:
        if not self.pairs:
            return None
        values = [v for m in self.members for v in m.localisation_by_seed()[m.seed].values()]
        return sum(values) / len(values)

    def localisation_by_seed(self) -> dict[int | None, dict[str, float]]:
        return {m.seed: m.localisation_by_seed()[m.seed] for m in self.members}

    def localisation_spread(self):
        """The :class:`dcslam.report.spread.SeedSpread` of the localisation over seeds × drives."""
        by_seed = self.localisation_by_seed()
        drives = self.drives()
        return seed_spread([[by_seed[s][d] for d in drives] for s in by_seed], self.failures())

    def drives(self) -> list[str]:
        """The drives every seed's run has (those of the first seed, in its order)."""
        first = self.members[0].pairs
        return [d for d in first if all(d in m.pairs for m in self.members)]

    def failures(self) -> int:
        return sum(m.failed(d) for m in self.members for d in m.pairs)

    def with_failure_threshold(self, threshold: float) -> "SeedResults":
        return replace(self, members=[m.with_failure_threshold(threshold) for m in self.members])

    def run_settings(self) -> dict:
        """The SLAM settings shared by every run of every seed; fails when they were run differently."""
        found = {}
        for member in self.members:
            for key, value in member.run_settings().items():
                if key in found and found[key][1] != value:
                    raise DcslamError(f"row {self.label} mixes SLAM runs made with {key}={found[key][1]} "
                                      f"({found[key][0]}) and {key}={value} ({member.layer}); rerun `dcslam slam "
                                      f"--depth {member.layer} --force` on every test drive")
                found.setdefault(key, (member.layer, value))
        return {k: v for k, (_, v) in found.items()}

    def per_drive_rows(self) -> list[tuple[int | None, str, dict]]:
        return [row for m in self.members for row in m.per_drive_rows()]

    def layer_text(self) -> str:
        return f"{self.members[0].layer} (seeds {', '.join(str(s) for s in self.seeds)})"

    def row(self, reference: "LayerResult | SeedResults | None" = None) -> dict:
        """The row of a table: for each figure its mean over seeds × drives (``<metric>``), the two-level interval
        (``_ci_low``, ``_ci_high``), the seed-to-seed spread (``_seed_std``), the median of every run
        (``_median``) and ``<metric>_text`` (``mean [low, high]``); ``seeds``, ``drives``, ``failures`` (failed
        runs of all seeds) and ``vs_sparse`` against ``reference`` (:func:`dcslam.report.seeds.paired`)."""
        row = {"method": self.label, "layer": self.layer_text(), "seeds": len(self.members),
               "missing": "; ".join(self.missing) or None}
        if not self.pairs:
            return row
        drives = self.drives()
        tables = [m.per_drive() for m in self.members]
        for key in SPREAD_KEYS:
            if key in DRIFT_KEYS:
                have = [d for d in drives if all(t[d].get(key) is not None for t in tables)]
                if not have:
                    continue
                row[f"{key}_drives"] = len(have)
            elif any(t[d].get(key) is None for t in tables for d in drives):
                continue  # a figure some run lacks (e.g. aligned ATE of a straight line) is not averaged
            else:
                have = drives
            values = [[t[d][key] for d in have] for t in tables]
            fmt = next(c.fmt for c in SPREAD_COLUMNS if c.key == key)
            flat = [v for seed_values in values for v in seed_values]
            if not all(math.isfinite(v) for v in flat):
                row.update({key: math.inf, f"{key}_text": f"inf ({sum(not math.isfinite(v) for v in flat)} "
                                                          "run(s) without a finite value)"})
                continue
            sp = seed_spread(values)
            row.update({key: sp.mean, f"{key}_ci_low": sp.ci_low, f"{key}_ci_high": sp.ci_high,
                        f"{key}_seed_std": sp.seed_std, f"{key}_median": sp.median, f"{key}_text": sp.text(fmt)})
        row["drives"] = len(drives)
        row["failures"] = self.failures()
        if "localisation_median" in row:
            row["localisation_median_text"] = f"{row['localisation_median']:.4f}"
            row["localisation_seed_std_text"] = f"{row['localisation_seed_std']:.4f}"
        if reference is not None and reference.pairs:
            row["vs_sparse"] = VERDICTS[paired(self, reference)[0]]
        if not any(f"{k}_drives" in row for k in DRIFT_KEYS):
            longest = max(r.get("path_m") or 0.0 for t in tables for r in t.values())
            row["drift_note"] = f"drives too short (longest {longest:.0f} m < 100 m)"
        return row


def surface_note(results: list) -> str:
    """The note on the surface columns of a table of ``results`` (the reference and frames they were scored on);
    empty when no row has surface errors."""
    members = [m for r in results for m in getattr(r, "members", [r])]
    targets = sorted({m.surface_target for m in members if m.surface})
    counts = sorted({n for m in members for n in m.surface_frames.values()})
    if not targets:
        return ""
    reference = " / ".join("exact (the generator's)" if t == "exact" else "annotated dense" for t in targets)
    return (f"normal mean / median (°), p2p mean / RMSE (m), flying share (CSV, per-drive CSV): surface errors of "
            f"the layer as SLAM takes it against the {reference} depth, on {'/'.join(map(str, counts))} evenly "
            "spaced frame(s) of each drive, first and last included (docs/metrics.md)")


def seeded(results: list) -> bool:
    """Whether any row of ``results`` is over several training seeds."""
    return any(isinstance(r, SeedResults) for r in results)


SEEDS_NOTE = ("rows over several training seeds (seeds: their number; layer: the first seed's run and the seeds): "
              "every figure is the mean over seeds × test drives with its 95 % interval [low, high] from a "
              f"{TWO_LEVEL_METHOD}; seed-to-seed std: the std of the per-seed mean localisations (the spread from "
              "training alone); failed: failed runs of all seeds × drives; vs sparse: whether the same two-level "
              "interval of the per-run differences from sparse depth (paired by drive) excludes zero. Rows without "
              "seeds: the t-interval over drives")


def with_seed_columns(columns: list[Column], seeds: bool) -> list[Column]:
    """``columns`` with, when ``seeds``, the number of seeds after ``drives`` and the seed-to-seed std of the
    localisation after its median (tables without rows over seeds keep their columns)."""
    if not seeds:
        return list(columns)
    out = []
    for column in columns:
        out.append(column)
        if column.key == "drives":
            out.append(Column("seeds", "seeds"))
        elif column.key == "localisation_median_text":
            out.append(Column("localisation_seed_std_text", "seed-to-seed std"))
    return out


def csv_suffixes(seeds: bool) -> tuple[str, ...]:
    """The CSV columns of each figure: mean, std, interval and median (and with ``seeds`` the seed-to-seed std)."""
    return ("", "_std", "_ci_low", "_ci_high", "_median") + (("_seed_std",) if seeds else ())


def _depth_per_drive(per_frame: dict[str, list]) -> dict[str, DepthErrors]:
    return {drive: mean_errors(frames) for drive, frames in per_frame.items()}


def score_layer(ws: Workspace, label: str, layer_name: str, drives: list[str], devkit_exact: bool = False,
                max_time_diff: float = EVO_MAX_TIME_DIFF_S, failure_threshold: float = FAILURE_THRESHOLD,
                slam_root: Path | None = None, depth: bool = True,
                surface_frames: int = SURFACE_FRAMES, slam_name: str | None = None) -> LayerResult:
    """Depth (unless not ``depth``) and trajectory scores of a layer over ``drives``, its SLAM outputs those of
    ``<slam_root>/<slam_name>/`` (default ``slam/<layer_name>/``; another name: SLAM runs of the layer made another
    way, e.g. with measured ICP sources); missing inputs are recorded, bad ones fail. With the depth errors come the
    surface errors of ``surface_frames`` evenly spaced frames of each drive
    (:func:`dcslam.report.layers.surface_frames`; 0: none) against the exact depth when every drive has it, else
    the annotated one (:func:`dcslam.report.layers.surface_target`)."""
    result = LayerResult(label=label, layer=layer_name, failure_threshold=failure_threshold)
    layer = find_layer(ws, layer_name) if depth else None
    if layer is None and depth:
        result.missing.append(f"no layer {layer_name!r} (dcslam predict / filter)")
    elif depth:
        absent = [d for d in drives if layer.folder is not None and not Path(layer.source(d)).exists()]
        if absent:
            result.missing.append(f"depth of {len(absent)} test drive(s) in {layer.folder}")
        else:
            result.depth = _depth_per_drive(score_layer_depth(ws, layer, drives, devkit_exact=devkit_exact))
            if surface_frames:
                _score_surface(ws, result, layer, drives, surface_frames)
    root = ws.slam if slam_root is None else slam_root
    slam_name = layer_name if slam_name is None else slam_name
    absent = [d for d in drives if not (root / slam_name / f"{d}.txt").exists()]
    if absent:
        result.missing.append(f"{root.name}/{slam_name}/ for {len(absent)} test drive(s) (dcslam slam)")
    else:
        result.pairs = score_layer_trajectories(ws, slam_name, drives, max_time_diff, root)
        result.settings = {d: slam_settings(ws, slam_name, d, root) for d in drives}
    return result


def _score_surface(ws: Workspace, result: LayerResult, layer, drives: list[str], frames: int) -> None:
    """Fill ``result.surface`` with the mean surface errors of each drive's sampled frames (a drive none of whose
    sampled frames has a reference is left out)."""
    from dcslam.eval.surface import mean_surface_errors

    result.surface_target = surface_target(ws, drives)
    for drive, errors in score_layer_surface(ws, layer, drives, result.surface_target, frames).items():
        scored = [e for e in errors if e is not None]
        if scored:
            result.surface[drive] = mean_surface_errors(scored)
            result.surface_frames[drive] = len(scored)


def filters_of(ws: Workspace, source_layer: str) -> list[str]:
    """Names of the filtered layers made from ``source_layer`` (by their ``config.json``)."""
    names = []
    if ws.filtered.is_dir():
        for folder in sorted(ws.filtered.iterdir()):
            config = folder / "config.json"
            if config.exists():
                try:
                    settings = json.loads(config.read_text()).get("settings", {})
                except json.JSONDecodeError:
                    raise DcslamError(f"{config}: not valid JSON") from None
                if settings.get("source_layer") == source_layer:
                    names.append(folder.name)
    return names


def imported_layers(ws: Workspace) -> list[str]:
    """Names of the layers ``dcslam import`` brought in (``predictions/<name>/config.json`` of stage ``import``)."""
    names = []
    for config in sorted(ws.predictions.glob("*/config.json")) if ws.predictions.is_dir() else []:
        try:
            stage = json.loads(config.read_text()).get("stage")
        except (json.JSONDecodeError, AttributeError):
            raise DcslamError(f"{config}: not a JSON object") from None
        if stage == "import":
            names.append(config.parent.name)
    return names


def score_runs(ws: Workspace, label: str, runs: list[RunSummary], drives: list[str], suffix: str = "",
               **options) -> "LayerResult | SeedResults":
    """The row of ``runs`` (the seeds of one run, :func:`dcslam.report.seeds.seed_groups`): layer
    ``<run name><suffix>`` of each run scored by :func:`score_layer` (``options``), one :class:`LayerResult` for a
    single run, a :class:`SeedResults` over several."""
    scored = []
    for run in runs:
        result = score_layer(ws, label, f"{run.name}{suffix}", drives, **options)
        result.seed = run.seed
        scored.append(result)
    return scored[0] if len(scored) == 1 else SeedResults(label, scored)


def table_5_2_results(ws: Workspace, runs: list[RunSummary], drives: list[str], devkit_exact: bool = False,
                      max_time_diff: float = EVO_MAX_TIME_DIFF_S,
                      failure_threshold: float = FAILURE_THRESHOLD) -> list:
    """Every row of Table 5.2 as a :class:`LayerResult` (models, no model, IP-Basic, models after best filter); the
    runs of one recipe trained with several seeds (:func:`dcslam.report.seeds.seed_groups`) as one
    :class:`SeedResults`."""
    options = dict(devkit_exact=devkit_exact, max_time_diff=max_time_diff, failure_threshold=failure_threshold)

    def score(label, name):
        return score_layer(ws, label, name, drives, devkit_exact, max_time_diff, failure_threshold)

    groups = seed_groups(runs)
    results = []
    for recipe in RECIPES:
        ours = [g for g in groups if g[0].recipe == recipe]
        if not ours:
            results.append(LayerResult(label=recipe, layer="—", missing=[f"no run trained as {recipe}"]))
        results += [score_runs(ws, recipe, group, drives, **options) for group in ours]
    results += [score_runs(ws, g[0].recipe, g, drives, **options)  # e.g. the pose loss
                for g in groups if g[0].recipe not in RECIPES]
    results.append(score("sparse depth", "sparse"))
    results.append(score("dense depth", "dense"))
    found = [name for name in IP_BASIC if find_layer(ws, name) is not None]
    results += [score("IP-Basic", name) for name in found] or [
        LayerResult(label="IP-Basic", layer="—", missing=[f"no layer {' or '.join(IP_BASIC)} (dcslam predict)"])]
    results += [score(f"{name} (imported)", name) for name in imported_layers(ws)]  # other methods' predictions
    for group in groups:
        run, label = group[0], f"{group[0].recipe} + best filter"
        names = filters_of(ws, run.name)
        if len(group) == 1:
            candidates = [score(label, name) for name in names]
            for candidate in candidates:
                candidate.seed = run.seed
        else:  # a filter every seed's run went through, named after the run (<run><suffix>)
            suffixes = [name[len(run.name):] for name in names if name.startswith(run.name)]
            suffixes = [x for x in suffixes if all(f"{r.name}{x}" in filters_of(ws, r.name) for r in group[1:])]
            candidates = [score_runs(ws, label, group, drives, suffix, **options) for suffix in suffixes]
        if not candidates and run.recipe not in RECIPES:
            continue  # recipes beyond the thesis's (the pose loss) are not filtered by the reproduction
        scored = [c for c in candidates if c.localisation is not None and c.depth]
        if scored:
            results.append(min(scored, key=lambda c: c.localisation))
        else:
            what = "filtered layers with slam results" if candidates else "filtered layer"
            results.append(LayerResult(label=label, layer="—",
                                       missing=[f"no {what} of {run.name} (dcslam filter, dcslam slam)"]))
    return results


def most_common_settings(rows: list[dict]) -> dict:
    """For each setting, the value most rows were made with (the first row's on a tie)."""
    common = {}
    for key in sorted(set().union(*rows)) if rows else []:
        values = [repr(r.get(key)) for r in rows]
        best = max(values, key=values.count)
        common[key] = next(r.get(key) for r in rows if repr(r.get(key)) == best)
    return {k: v for k, v in common.items() if v is not None}


def settings_text(settings: dict) -> str:
    return ", ".join(f"{k}={settings[k]}" for k in sorted(settings))


def annotate(row: dict, result: LayerResult, settings: dict | None, common: dict) -> dict:
    """Complete a table row of ``result``: ``slam_settings`` (how its SLAM ``settings`` differ from the ``common``
    ones; absent without settings) and ``notes`` (what is missing, why there is no drift or aligned ATE)."""
    if settings is not None:
        own = {k: settings.get(k) for k in set(common) | set(settings) if common.get(k) != settings.get(k)}
        row["slam_settings"] = "as the others" if not own else "differs: " + settings_text(own)
    notes = [n for n in (row.get("missing"), row.get("drift_note")) if n]
    if result.pairs and row.get("ate_rmse_m") is None:
        notes.append("aligned ATE undefined on some drive (degenerate positions)")
    row["notes"] = "; ".join(notes) or None
    return row


def table_5_2(results: list[LayerResult], thesis: dict, drives: list[str], devkit_exact: bool = False) -> Table:
    """Table 5.2: one row per result, each figure as mean ± the 95 % t-interval's half-width over the test drives,
    with the median localisation, the failure count and whether the row differs from sparse depth beyond the
    spread; the CSV holds every mean, std, interval and median. Rows whose SLAM runs were made with other settings
    than the others show the difference in ``SLAM settings``; a row whose drives were run differently fails."""
    figures = thesis.get("table_5_2", {}).get("rows", {})
    table = Table(f"Table 5.2 — {len(drives)} test drive(s) ({', '.join(drives)})",
                  with_seed_columns(TABLE_5_2_COLUMNS, seeded(results)))
    table.csv_columns = [Column(k, k) for k in ("method", "layer", "drives", *(("seeds",) if seeded(results) else ()),
                                                "failures", "vs_sparse")] + [
        Column(f"{c.key}{suffix}", "") for c in SPREAD_COLUMNS for suffix in csv_suffixes(seeded(results))] + [
        Column(f"{k}_drives", "") for k in DRIFT_KEYS] + [
        Column(f"thesis_{k}", "") for k in ("localisation", "mae", "rmse")] + [
        Column("slam_settings", ""), Column("missing", ""), Column("notes", "")]
    reference = next((r for r in results if r.layer == "sparse"), None)
    settings = {id(r): r.run_settings() for r in results if r.pairs}
    common = most_common_settings(list(settings.values()))
    for result in results:
        theirs = figures.get(result.label, {})
        row = {**result.row(reference), **{f"thesis_{k}": v for k, v in theirs.items()}}
        for k in ("localisation", "mae", "rmse"):
            row.setdefault(f"thesis_{k}_text", "x" if k in theirs and theirs[k] is None else
                           (None if theirs.get(k) is None else f"{theirs[k]:g}"))
        table.rows.append(annotate(row, result, settings.get(id(result)), common))
    threshold = results[0].failure_threshold if results else FAILURE_THRESHOLD
    single_runs = all(sum(r.label == recipe for r in results) <= 1 for recipe in RECIPES)
    table.notes += [  # short on purpose: how each column is computed is in docs/metrics.md
        "localisation accuracy: the thesis's metric (m + rad, lower is better); every figure: mean over the test "
        "drives ± the half-width of its 95 % t-interval (std, interval and median in the CSV)",
        f"failed: drives flagged suspect by the SLAM (its step verdicts, its drift bound, or for completed depth a "
        f"companion run on the measured LiDAR pixels it departs from) or with a localisation error above "
        f"{threshold:g}; vs sparse: "
        "paired 95 % t-interval of the per-drive differences",
        "MAE, RMSE, iMAE, iRMSE: " + ("exactly as the KITTI devkit" if devkit_exact else
                                     "KITTI devkit with two departures (--devkit-exact removes them)"),
        "ATE, RPE: as evo computes them; t_rel / r_rel: KITTI odometry devkit over 100-800 m segments",
        (SEEDS_NOTE if seeded(results) else
         "trained rows: one training run per recipe, so their spread is across test drives only" if single_runs
         else "trained rows: each training run of a recipe is its own row"),
        "thesis columns: the thesis's figures (dcslam/report/thesis_tables.json); x: not computed there; —: no "
        "such row",
        surface_note(results),
        "how each column is computed, and where dcslam departs from the thesis and the devkits: docs/metrics.md",
        f"SLAM settings of the rows (those of most rows; a row made otherwise says how in SLAM settings): "
        f"{settings_text(common) or 'none recorded'}"]
    table.notes = [n for n in table.notes if n]
    return table
