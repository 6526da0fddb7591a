"""What ``dcslam reproduce`` will run and what it will cost, printed before it starts (``--dry-run``: only that).

The cost of a stage of a kind is ``stage_s + units × unit_s`` CPU seconds: ``units`` its work in the units of its kind
(generated frames, drive frames, training steps (frames × epochs), predicted or filtered frames, SLAM frames, the
SLAM frames of the runs scored; :func:`stage_work`), counted at the profile's settings (image scale, model, loss, map
frames, completer, SLAM settings), so unit costs hold for the profile they were measured at.
Unit costs are measured, never assumed:

- ``--costs-from DIR``: the stamps of a finished reproduction (each records the CPU seconds of its stage):
  seconds per unit of each kind, no per-stage part;
- else the calibration of this workspace for this profile (``dcslam reproduce --calibrate``:
  :mod:`dcslam.stages.reproduce_probe` runs small samples of every stage kind at two sizes and fits ``stage_s`` and
  ``unit_s``; written to ``<workspace>/.reproduce/calibration.json``);
- else the workspace's own finished stages;
- else ``reproduce_costs.json`` (shipped with dcslam: the probe's figures on the machine its ``note`` names; a
  profile it lacks gets quick's, and the source says so).

Seconds are CPU seconds of one torch thread (the probe runs one; a stage that runs more threads spends more CPU for
less wall time), so their sum is about the wall time of ``--jobs 1`` with one thread on a quiet machine.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from dcslam.errors import DcslamError

SHIPPED_COSTS = Path(__file__).with_name("reproduce_costs.json")
CALIBRATION = "calibration.json"  # in <workspace>/.reproduce/: what `dcslam reproduce --calibrate` measured
# each kind's unit, as the estimate prints it
UNITS = {"synth": "generated frames", "prepare-kitti": "drive frames",
         "train-mse": "training steps (frames x epochs)", "train-chamfer": "training steps (frames x epochs)",
         "train-pose": "training steps (frames x epochs)",
         "predict": "predicted frames", "predict-classical": "predicted frames", "filter": "filtered frames",
         "slam-sparse": "SLAM frames", "slam-dense": "SLAM frames", "slam-completed": "SLAM frames",
         "slam-long": "SLAM frames", "score": "SLAM frames scored"}
# IP-Basic's predictions are kind predict-classical; every other classical completer's are a kind of their own,
# predict-<completer> (their costs differ tenfold: planefit against scanline)
CLASSICAL_KIND = ("ip-basic", "ip-basic-fast")
# a network trained on a classical completer's fill (``--correct-fill --fill F``) computes that fill for every frame
# it trains on or predicts: its trainings are kind train-<loss>+<F>, its predictions predict+<F> (priced as plain
# networks, the surface study's took 3.4x and 2.4x their estimate)
FILL_SUFFIX = "+"
# SLAM on a LiDAR-like layer, on annotated depth (a fifth of the pixels) and on full images (completions, filtered
# completions, exact depth, each with its companion run) cost about 1 : 3 : 5 per frame at the quick settings
# (the shipped probe figures): a SLAM stage's kind is its input's (:func:`slam_kind`)
SLAM_KINDS = ("slam-sparse", "slam-dense", "slam-completed")
# frames 5 … N−6 of a generated drive of N raw frames have depth, and only those are in its drive file
UNDEPTHED_FRAMES = 10


@dataclass(frozen=True)
class DriveFrames:
    """The drives a reproduction works on: frames in each drive file, and the split."""

    frames: dict[str, int]
    splits: dict[str, list[str]]

    def total(self, names: list[str] | None = None) -> int:
        return sum(self.frames.get(n, 0) for n in (self.frames if names is None else names))


def stage_kind(name: str, config: dict, fills: dict[str, str] | None = None) -> str:
    """The kind of stage ``name`` (its stamp's name) with ``config`` (its options as plain values); ``fills``: the
    fill each trained run of the plan corrects (:func:`run_fills`), which its predictions compute too."""
    if name == "synth":
        return "synth"
    if name == "prepare-kitti":
        return "prepare-kitti"
    if name.startswith("train-"):
        fill = _fill(config)
        return f"train-{config.get('loss', 'mse')}" + (f"{FILL_SUFFIX}{fill}" if fill else "")
    if name.startswith("predict-"):
        model = config.get("model")
        if not model:
            fill = (fills or {}).get(str(config.get("run")))
            return "predict" + (f"{FILL_SUFFIX}{fill}" if fill else "")
        return "predict-classical" if model in CLASSICAL_KIND else f"predict-{model}"
    if name.startswith("filter-"):
        return "filter"
    if name.startswith("slam-long-"):
        return "slam-long"
    if name.startswith("slam-"):
        return slam_kind(str(config.get("depth", "")))
    if name.startswith("score-"):
        return "score"
    raise DcslamError(f"stage {name}: not a stage of dcslam reproduce")


def _fill(config: dict) -> str | None:
    """The classical fill a training ``config`` corrects (None: the network's own depth)."""
    return str(config["fill"]) if config.get("correct_fill") and config.get("fill") else None


def run_fills(named_configs) -> dict[str, str]:
    """``{run: fill}`` of the trainings among ``named_configs`` (``(stage name, config)`` pairs) that correct a
    classical fill: the predictions by those runs compute it for every frame."""
    return {str(config.get("name", name.removeprefix("train-"))): _fill(config)
            for name, config in named_configs if name.startswith("train-") and _fill(config)}


def slam_kind(depth: str) -> str:
    """The kind of a SLAM stage on the layer ``depth`` (a stage's ``depth`` option): ``slam-sparse`` for the
    LiDAR's own depth (``sparse``, ``sparse@N``), ``slam-dense`` for the annotated ``dense`` depth, ``slam-completed``
    for every other layer (predictions, filtered predictions, ``exact``)."""
    if depth == "sparse" or depth.startswith("sparse@"):
        return "slam-sparse"
    return "slam-dense" if depth == "dense" else "slam-completed"


def stage_work(name: str, config: dict, drives: DriveFrames, slam_frames: float,
               fills: dict[str, str] | None = None) -> tuple[str, float]:
    """``(kind, units)`` of stage ``name`` with ``config`` over ``drives`` (``slam_frames``: the frames of the SLAM
    runs a scoring stage scores, whose trajectories, depths and surfaces it reads; ``fills``: :func:`run_fills`)."""
    kind = stage_kind(name, config, fills)
    test = drives.splits.get("test", [])
    if kind == "synth":
        return kind, float(config["drives"] * config["frames"])
    if kind == "prepare-kitti":
        return kind, float(drives.total())
    if kind.startswith("train-"):
        used = sum(min(config["max_frames"], drives.frames.get(d, 0)) // config["stride"]
                   for d in drives.splits.get("train", []) + drives.splits.get("val", []))
        return kind, float(config["epochs"] * used)  # a step's cost at the profile's scale is its unit cost
    if kind.startswith("predict") or kind == "filter":
        return kind, float(drives.total(test))
    if kind in (*SLAM_KINDS, "slam-long"):
        frames = [drives.frames.get(Path(d).stem, 0) for d in config["drive"] or test]
        return kind, float(sum(min(n, config["frames"]) if config["frames"] else n for n in frames))
    return kind, float(slam_frames)


def _slam_frames(named_configs, drives: DriveFrames) -> float:
    """The SLAM frames of the SLAM stages among ``named_configs``: what a scoring stage of the plan scores."""
    return sum(stage_work(name, config, drives, 0.0)[1] for name, config in named_configs
               if name.startswith("slam-"))


def _stamps(root: Path) -> list[tuple[str, dict]]:
    """``(stage name, stamp)`` of the finished stages stamped in ``<root>/.reproduce/``."""
    state = Path(root) / ".reproduce"
    records = []
    for path in sorted(state.glob("*.json")) if state.is_dir() else []:
        try:
            record = json.loads(path.read_text())
        except json.JSONDecodeError:
            continue  # a stamp being written, or broken: not a measurement
        if isinstance(record, dict) and record.get("complete") and isinstance(record.get("seconds"), (int, float)) \
                and isinstance(record.get("config"), dict):
            records.append((path.stem, record))
    return records


def measure(root: Path) -> dict[str, tuple[float, float, int]]:
    """``{kind: (CPU seconds, units, stages)}`` summed over the finished stages stamped in ``<root>/.reproduce/``
    (work from each stamp's configuration and the workspace's drive files; a stamp without ``cpu_seconds``, from an
    older dcslam, counts its wall seconds); empty when it has none."""
    from dcslam.io.drive import DriveFile, read_splits

    root = Path(root)
    records = _stamps(root)
    if not records:
        return {}
    splits_file = root / "drives" / "splits.json"
    splits = read_splits(splits_file) if splits_file.exists() else {}
    frames = {}
    for drive in sorted((root / "drives").glob("*.h5")):
        with DriveFile(drive) as d:
            frames[drive.stem] = len(d)
    drives = DriveFrames(frames, splits)
    # a stage this estimate does not know, or a stamp of another version's options, is left out
    known = [(name, record) for name, record in records if _known(name, record["config"], drives)]
    configs = [(name, record["config"]) for name, record in known]
    slam_frames, fills = _slam_frames(configs, drives), run_fills(configs)
    totals: dict[str, tuple[float, float, int]] = {}
    for name, record in known:
        kind, units = stage_work(name, record["config"], drives, slam_frames, fills)
        cpu = record.get("cpu_seconds")
        seconds = float(cpu if isinstance(cpu, (int, float)) else record["seconds"])
        total, work, stages = totals.get(kind, (0.0, 0.0, 0))
        totals[kind] = (total + seconds, work + units, stages + 1)
    return totals


def _known(name: str, config: dict, drives: DriveFrames) -> bool:
    """Whether a stamp's stage is one this estimate knows, with the options it reads."""
    try:
        stage_work(name, config, drives, 0.0)
    except (DcslamError, KeyError, TypeError):
        return False
    return True


@dataclass(frozen=True)
class UnitCosts:
    """CPU seconds of each stage kind: ``per_stage`` (each stage's fixed part: imports, model set-up, files) plus
    ``per_unit`` × its units; and where they were measured."""

    per_unit: dict[str, float]
    source: str
    per_stage: dict[str, float] = field(default_factory=dict)

    def seconds(self, kind: str, stages: int, units: float) -> float | None:
        """Estimated CPU seconds of ``stages`` stages of ``kind`` doing ``units`` in all (None: not measured)."""
        if kind not in self.per_unit:
            return None
        return stages * self.per_stage.get(kind, 0.0) + units * self.per_unit[kind]


def read_costs(path: Path, profile: str) -> UnitCosts | None:
    """The unit costs of ``profile`` in a costs file (``reproduce_costs.json``, or a workspace's calibration:
    ``{"profiles": {profile: {"source": ..., "kinds": {kind: {"stage_s": s, "unit_s": s, ...}}}}}``); None when it
    has none for ``profile``; a :class:`DcslamError` when it cannot be read."""
    try:
        entry = json.loads(Path(path).read_text())["profiles"].get(profile)
        if entry is None:
            return None
        kinds = entry["kinds"]
        return UnitCosts({k: float(v["unit_s"]) for k, v in kinds.items()}, str(entry["source"]),
                         {k: float(v["stage_s"]) for k, v in kinds.items()})
    except (OSError, json.JSONDecodeError, KeyError, TypeError, ValueError, AttributeError) as exc:
        raise DcslamError(f"{path}: cannot read the unit costs ({exc}); rerun `dcslam reproduce --calibrate` (or "
                          "reinstall dcslam for its own)") from None


def shipped_costs(profile: str = "quick", path: Path = SHIPPED_COSTS) -> UnitCosts:
    """The unit costs shipped with dcslam for ``profile``; for a profile it has none for, quick's with the same
    camera setting (``quick+no-camera`` for ``study+no-camera``), else quick's, else its first profile's; the source
    then says they were measured at another profile's settings."""
    costs = read_costs(path, profile)
    if costs is not None:
        return costs
    try:
        profiles = list(json.loads(Path(path).read_text())["profiles"])
        suffix = "+no-camera" if profile.endswith("+no-camera") else ""
        other = next((p for p in (f"quick{suffix}", "quick") if p in profiles), profiles[0])
    except (OSError, json.JSONDecodeError, KeyError, TypeError, IndexError) as exc:
        raise DcslamError(f"{path}: cannot read the unit costs ({exc}); reinstall dcslam or pass --costs-from") \
            from None
    costs = read_costs(path, other)
    return UnitCosts(costs.per_unit, f"{costs.source} (at profile {other}'s settings, not {profile}'s: run "
                     "`dcslam reproduce --calibrate` for a better estimate)", costs.per_stage)


def unit_costs(workspace_root: Path, costs_from: Path | None = None, profile: str = "quick") -> UnitCosts:
    """The unit costs of the estimate of ``profile``: measured in ``costs_from``'s stamps (a :class:`DcslamError`
    when it has no finished stage), else this workspace's calibration for ``profile``, else its finished stages,
    else :func:`shipped_costs`; kinds a measurement lacks are taken from the shipped ones (the source says so)."""
    shipped = shipped_costs(profile)
    root = Path(workspace_root)
    if costs_from is None and (root / ".reproduce" / CALIBRATION).exists():
        calibrated = read_costs(root / ".reproduce" / CALIBRATION, profile)
        if calibrated is not None:
            return _with_shipped(calibrated, calibrated.source, shipped)
    if costs_from is not None:
        totals = measure(costs_from)
        if not totals:
            raise DcslamError(f"--costs-from {costs_from}: no finished stage stamped in "
                              f"{Path(costs_from) / '.reproduce'}; give the workspace of a finished `dcslam reproduce`")
        where = f"the stage stamps of {costs_from}"
    else:
        totals = measure(root)
        if not totals:
            return shipped
        where = f"this workspace's stage stamps ({root / '.reproduce'})"
    per_unit = {kind: seconds / units for kind, (seconds, units, _) in totals.items() if units > 0}
    return _with_shipped(UnitCosts(per_unit, where, {kind: 0.0 for kind in per_unit}), where, shipped)


def _with_shipped(costs: UnitCosts, where: str, shipped: UnitCosts) -> UnitCosts:
    rest = sorted(set(shipped.per_unit) - set(costs.per_unit))
    source = where + (f"; {', '.join(rest)} from {shipped.source}" if rest else "")
    return UnitCosts({**shipped.per_unit, **costs.per_unit}, source, {**shipped.per_stage, **costs.per_stage})


@dataclass(frozen=True)
class Estimate:
    """Per stage kind: stages, units of work and estimated CPU seconds (None: no unit cost measured)."""

    rows: dict[str, tuple[int, float, float | None]]
    source: str

    @property
    def total_seconds(self) -> float:
        return sum(s for _, _, s in self.rows.values() if s is not None)


def estimate(stages: list, drives: DriveFrames, costs: UnitCosts, planned: list | None = None) -> Estimate:
    """The :class:`Estimate` of ``stages`` (:class:`dcslam.stages.pipeline.Stage`) over ``drives``; ``planned``: the
    whole plan they are part of (default: ``stages``): a scoring stage scores all its SLAM runs, and its trainings
    say which runs correct a fill."""
    from dcslam.stages.config import to_dict

    named = [(s.name, to_dict(s.config)) for s in stages]
    whole = named if planned is None else [(s.name, to_dict(s.config)) for s in planned]
    slam_frames, fills = _slam_frames(whole, drives), run_fills(whole)  # a scoring stage scores every run
    rows: dict[str, list] = {}
    for name, config in named:
        kind, units = stage_work(name, config, drives, slam_frames, fills)
        row = rows.setdefault(kind, [0, 0.0])
        row[0] += 1
        row[1] += units
    return Estimate({kind: (n, units, costs.seconds(kind, n, units)) for kind, (n, units) in rows.items()},
                    costs.source)


def planned_drives(ws, profile, kitti_root: Path | None, splits: dict[str, list[str]]) -> DriveFrames:
    """The drives of a plan: a generated drive holds the profile's frames less the 10 without depth; drives of a
    KITTI root are counted from the workspace's drive files where they exist (0 frames where not: the estimate then
    says so)."""
    names = [n for part in ("train", "val", "test") for n in splits.get(part, [])]
    if kitti_root is None:
        return DriveFrames({n: max(profile.frames - UNDEPTHED_FRAMES, 0) for n in names}, splits)
    from dcslam.io.drive import DriveFile

    frames = {}
    for name in names:
        path = ws.drives / f"{name}.h5"
        if path.exists():
            with DriveFile(path) as d:
                frames[name] = len(d)
    return DriveFrames(frames, splits)


def unit_of(kind: str) -> str:
    """What a unit of ``kind`` is, as the estimate prints it."""
    base = kind.split(FILL_SUFFIX, 1)[0]
    return UNITS.get(base) or ("predicted frames" if base.startswith("predict") else "?")


def _hours(seconds: float | None) -> str:
    return "unmeasured" if seconds is None else f"{seconds / 3600:.3g}"


def plan_text(ws, config) -> str:
    """What ``dcslam reproduce`` with ``config`` will run in ``ws`` (stages per kind, those up to date, seeds and
    drives) and its estimated cost per stage kind; reads the workspace, writes nothing."""
    from dcslam.stages.pipeline import Pipeline
    from dcslam.stages.reproduce_plan import planned_splits, planned_stages, profile_of, seeds_of

    profile, seeds = profile_of(config), seeds_of(config)
    splits = planned_splits(ws, profile, config.kitti)
    stages = planned_stages(ws, profile, config.table, config.kitti, config.seed, seeds)
    checker = Pipeline(ws)
    todo = [s for s in stages if not checker.up_to_date(s)]
    drives = planned_drives(ws, profile, config.kitti, splits)
    costs = unit_costs(ws.root, config.costs_from, profile.name)
    result = estimate(todo, drives, costs, planned=stages)
    trained = sorted({s.seed for s in stages if s.seed is not None})
    lines = [f"dcslam reproduce --table {config.table} --profile {profile.name}: {len(splits.get('test', []))} test "
             f"drive(s), {seeds} training seed(s) per trained run (seeds {', '.join(map(str, trained)) or '—'}); "
             f"{len(stages)} stages, {len(stages) - len(todo)} up to date, {len(todo)} to run",
             f"estimated cost of the {len(todo)} to run (unit costs measured from {result.source}):",
             f"  {'stage kind':<18}{'stages':>7}{'units':>12}  {'unit':<34}{'s/stage':>9}{'s/unit':>9}"
             f"{'CPU-hours':>11}"]
    for kind, (n, units, seconds) in result.rows.items():
        per = f"{costs.per_unit[kind]:.3g}" if kind in costs.per_unit else "—"
        fixed = f"{costs.per_stage.get(kind, 0.0):.3g}" if kind in costs.per_unit else "—"
        lines.append(f"  {kind:<18}{n:>7}{units:>12.4g}  {unit_of(kind):<34}{fixed:>9}{per:>9}{_hours(seconds):>11}")
    unmeasured = [kind for kind, (_, _, s) in result.rows.items() if s is None]
    lines.append(f"  {'total':<18}{len(todo):>7}{'':>12}  {'':<34}{'':>18}{_hours(result.total_seconds):>11}"
                 + (f" (without {', '.join(unmeasured)}: no unit cost measured)" if unmeasured else ""))
    if any(units == 0 for _, units, _ in result.rows.values()):
        lines.append("  (0 units: the drive files are not prepared yet, so their frames are not known)")
    lines.append("  CPU-hours: stages x s/stage + units x s/unit, CPU seconds of one thread measured at this profile's "
                 "settings; with --jobs J the training, prediction and SLAM stages run J at a time")
    return "\n".join(lines)
