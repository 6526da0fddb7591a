"""The result model of the tables over the test drives: the scores of one depth layer (:class:`LayerResult`: depth
errors, surface errors, trajectories and the SLAM settings behind them, per drive, with the row of a table and its
spread), a row over the layers of several training seeds (:class:`SeedResults`), :func:`score_layer` that fills one
from the workspace's files, the failure threshold, and the columns and notes every table of them shares (Table 5.2,
its long-drive companion, the beams table).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

from dcslam.errors import DcslamError
from dcslam.eval.depth import DepthErrors, mean_errors
from dcslam.eval.trajectory import EVO_MAX_TIME_DIFF_S
from dcslam.report.seeds import paired
from dcslam.report.spread import seed_spread, spread
from dcslam.report.tables import Column
from dcslam.workspace import Workspace

if TYPE_CHECKING:  # the scoring modules import torch: imported where they score, so `dcslam --help` stays fast
    from dcslam.eval.surface import SurfaceErrors
    from dcslam.report.layers import TrajectoryPair

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
                from dcslam.eval.surface import SURFACE_METRICS

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


def depth_per_drive(per_frame: dict[str, list]) -> dict[str, DepthErrors]:
    return {drive: mean_errors(frames) for drive, frames in per_frame.items()}


def score_layer(ws: Workspace, label: str, layer_name: str, drives: list[str], devkit_exact: bool = False,
                max_time_diff: float = EVO_MAX_TIME_DIFF_S, failure_threshold: float = FAILURE_THRESHOLD,
                slam_root: Path | None = None, depth: bool = True,
                surface_frames: int | None = None, slam_name: str | None = None) -> LayerResult:
    """Depth (unless not ``depth``) and trajectory scores of a layer over ``drives``, its SLAM outputs those of
    ``<slam_root>/<slam_name>/`` (default ``slam/<layer_name>/``; another name: SLAM runs of the layer made another
    way, e.g. with measured ICP sources); missing inputs are recorded, bad ones fail. With the depth errors come the
    surface errors of ``surface_frames`` evenly spaced frames of each drive
    (:func:`dcslam.report.layers.surface_frames`; None:
    :data:`dcslam.report.layers.SURFACE_FRAMES`, 0: none) against the exact depth when every drive has it,
    else the annotated one (:func:`dcslam.report.layers.surface_target`)."""
    from dcslam.report.layers import (SURFACE_FRAMES, find_layer, score_layer_depth, score_layer_trajectories,
                                      slam_settings)

    surface_frames = SURFACE_FRAMES if surface_frames is None else surface_frames
    result = LayerResult(label=label, layer=layer_name, failure_threshold=failure_threshold)
    layer = find_layer(ws, layer_name) if depth else None
    if layer is None and depth:
        result.missing.append(f"no layer {layer_name!r} (dcslam predict / filter)")
    elif depth:
        absent = [d for d in drives if layer.folder is not None and not Path(layer.source(d)).exists()]
        if absent:
            result.missing.append(f"depth of {len(absent)} test drive(s) in {layer.folder}")
        else:
            result.depth = depth_per_drive(score_layer_depth(ws, layer, drives, devkit_exact=devkit_exact))
            if surface_frames:
                score_surface(ws, result, layer, drives, surface_frames)
    root = ws.slam if slam_root is None else slam_root
    slam_name = layer_name if slam_name is None else slam_name
    absent = [d for d in drives if not (root / slam_name / f"{d}.txt").exists()]
    if absent:
        result.missing.append(f"{root.name}/{slam_name}/ for {len(absent)} test drive(s) (dcslam slam)")
    else:
        result.pairs = score_layer_trajectories(ws, slam_name, drives, max_time_diff, root)
        result.settings = {d: slam_settings(ws, slam_name, d, root) for d in drives}
    return result


def score_surface(ws: Workspace, result: LayerResult, layer, drives: list[str], frames: int) -> None:
    """Fill ``result.surface`` with the mean surface errors of each drive's sampled frames (a drive none of whose
    sampled frames has a reference is left out)."""
    from dcslam.eval.surface import mean_surface_errors
    from dcslam.report.layers import score_layer_surface, surface_target

    result.surface_target = surface_target(ws, drives)
    for drive, errors in score_layer_surface(ws, layer, drives, result.surface_target, frames).items():
        scored = [e for e in errors if e is not None]
        if scored:
            result.surface[drive] = mean_surface_errors(scored)
            result.surface_frames[drive] = len(scored)


def seed_layer(result, seed) -> str:
    """The layer of ``result``'s run of training seed ``seed`` (a row over seeds has one per seed)."""
    members = getattr(result, "members", None)
    return next(m.layer for m in members if m.seed == seed) if members else result.layer
