"""What ``dcslam reproduce`` will run and what it will cost, printed before it starts (``--dry-run``: only that).

The cost of a stage is its work in the units of its kind (generated frames, drive frames, training frames at full
resolution × epochs, predicted or filtered frames, SLAM frames, SLAM runs scored; :func:`stage_work`) times a unit
cost in seconds. Unit costs are measured, never assumed: every finished stage's stamp in ``<workspace>/.reproduce/``
records its seconds and its configuration, from which :func:`measure` recomputes its work, so the seconds per unit
of each kind are those of a finished reproduction: ``--costs-from DIR``, else the workspace's own finished stages,
else a quick-profile run's as measured on the machine named in ``reproduce_costs.json`` (shipped with dcslam).
Each stage's seconds are the wall time of the one process that ran it, so their sum is CPU time for one-thread
stages and a bound on the wall time at ``--jobs 1``.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from dcslam.errors import DcslamError

SHIPPED_COSTS = Path(__file__).with_name("reproduce_costs.json")
# each kind's unit, as the estimate prints it
UNITS = {"synth": "generated frames", "prepare-kitti": "drive frames",
         "train-mse": "training frames x epochs at full resolution", "train-chamfer": "training frames x epochs "
         "at full resolution", "train-pose": "training frames x epochs at full resolution",
         "predict": "predicted frames", "predict-classical": "predicted frames", "filter": "filtered frames",
         "slam": "SLAM frames", "slam-long": "SLAM frames", "score": "SLAM runs scored"}
CLASSICAL_PREFIX = "ip-basic"
# frames 5 … N−6 of a generated drive of N raw frames have depth, and only those are in its drive file
UNDEPTHED_FRAMES = 10


@dataclass(frozen=True)
class DriveFrames:
    """The drives a reproduction works on: frames in each drive file, and the split."""

    frames: dict[str, int]
    splits: dict[str, list[str]]

    def total(self, names: list[str] | None = None) -> int:
        return sum(self.frames.get(n, 0) for n in (self.frames if names is None else names))


def stage_kind(name: str, config: dict) -> str:
    """The kind of stage ``name`` (its stamp's name) with ``config`` (its options as plain values)."""
    if name == "synth":
        return "synth"
    if name == "prepare-kitti":
        return "prepare-kitti"
    if name.startswith("train-"):
        return f"train-{config.get('loss', 'mse')}"
    if name.startswith("predict-"):
        return "predict-classical" if config.get("model") else "predict"
    if name.startswith("filter-"):
        return "filter"
    if name.startswith("slam-long-"):
        return "slam-long"
    if name.startswith("slam-"):
        return "slam"
    if name.startswith("score-"):
        return "score"
    raise DcslamError(f"stage {name}: not a stage of dcslam reproduce")


def stage_work(name: str, config: dict, drives: DriveFrames, slam_runs: int) -> tuple[str, float]:
    """``(kind, units)`` of stage ``name`` with ``config`` over ``drives`` (``slam_runs``: the SLAM runs a scoring
    stage scores)."""
    kind = stage_kind(name, config)
    test = drives.splits.get("test", [])
    if kind == "synth":
        return kind, float(config["drives"] * config["frames"])
    if kind == "prepare-kitti":
        return kind, float(drives.total())
    if kind.startswith("train-"):
        used = sum(min(config["max_frames"], drives.frames.get(d, 0)) // config["stride"]
                   for d in drives.splits.get("train", []) + drives.splits.get("val", []))
        return kind, float(config["epochs"] * used * config["scale"] ** 2)
    if kind in ("predict", "predict-classical", "filter"):
        return kind, float(drives.total(test))
    if kind in ("slam", "slam-long"):
        frames = [drives.frames.get(Path(d).stem, 0) for d in config["drive"] or test]
        return kind, float(sum(min(n, config["frames"]) if config["frames"] else n for n in frames))
    return kind, float(slam_runs)


def measure(root: Path) -> dict[str, tuple[float, float]]:
    """``{kind: (seconds, units)}`` summed over the finished stages stamped in ``<root>/.reproduce/`` (work from
    each stamp's configuration and the workspace's drive files); empty when it has none."""
    from dcslam.io.drive import DriveFile, read_splits

    root = Path(root)
    stamps = sorted((root / ".reproduce").glob("*.json")) if (root / ".reproduce").is_dir() else []
    records = []
    for path in stamps:
        try:
            record = json.loads(path.read_text())
        except json.JSONDecodeError:
            continue  # a stamp being written, or broken: not a measurement
        if isinstance(record, dict) and record.get("complete") and isinstance(record.get("seconds"), (int, float)) \
                and isinstance(record.get("config"), dict):
            records.append((path.stem, record))
    if not records:
        return {}
    splits_file = root / "drives" / "splits.json"
    splits = read_splits(splits_file) if splits_file.exists() else {}
    frames = {}
    for drive in sorted((root / "drives").glob("*.h5")):
        with DriveFile(drive) as d:
            frames[drive.stem] = len(d)
    drives = DriveFrames(frames, splits)
    slam_runs = sum(name.startswith("slam-") for name, _ in records)
    totals: dict[str, tuple[float, float]] = {}
    for name, record in records:
        try:
            kind, units = stage_work(name, record["config"], drives, slam_runs)
        except (DcslamError, KeyError, TypeError):
            continue  # a stage this estimate does not know, or a stamp of another version's options
        seconds, work = totals.get(kind, (0.0, 0.0))
        totals[kind] = (seconds + float(record["seconds"]), work + units)
    return totals


@dataclass(frozen=True)
class UnitCosts:
    """Seconds per unit of each stage kind, and where they were measured."""

    per_unit: dict[str, float]
    source: str


def shipped_costs(path: Path = SHIPPED_COSTS) -> UnitCosts:
    """The unit costs shipped with dcslam (``reproduce_costs.json``: ``source`` and ``{kind: [seconds, units]}``)."""
    try:
        data = json.loads(Path(path).read_text())
        per_unit = {kind: float(s) / float(u) for kind, (s, u) in data["kinds"].items() if u}
        return UnitCosts(per_unit, str(data["source"]))
    except (OSError, json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
        raise DcslamError(f"{path}: cannot read the unit costs ({exc}); reinstall dcslam or pass --costs-from") \
            from None


def unit_costs(workspace_root: Path, costs_from: Path | None = None) -> UnitCosts:
    """The unit costs of the estimate: measured in ``costs_from`` (a :class:`DcslamError` when it has no finished
    stage), else in ``workspace_root`` when it has finished stages, else :func:`shipped_costs`; kinds the measured
    workspace lacks are taken from the shipped ones (the source says so)."""
    shipped = shipped_costs()
    if costs_from is not None:
        totals = measure(costs_from)
        if not totals:
            raise DcslamError(f"--costs-from {costs_from}: no finished stage stamped in "
                              f"{Path(costs_from) / '.reproduce'}; give the workspace of a finished `dcslam reproduce`")
        where = f"the stage stamps of {costs_from}"
    else:
        totals = measure(workspace_root)
        if not totals:
            return shipped
        where = f"this workspace's stage stamps ({Path(workspace_root) / '.reproduce'})"
    per_unit = {kind: seconds / units for kind, (seconds, units) in totals.items() if units > 0}
    rest = sorted(set(shipped.per_unit) - set(per_unit))
    source = where + (f"; {', '.join(rest)} from {shipped.source}" if rest else "")
    return UnitCosts({**shipped.per_unit, **per_unit}, source)


@dataclass(frozen=True)
class Estimate:
    """Per stage kind: stages, units of work and estimated seconds (None: no unit cost measured)."""

    rows: dict[str, tuple[int, float, float | None]]
    source: str

    @property
    def total_seconds(self) -> float:
        return sum(s for _, _, s in self.rows.values() if s is not None)


def estimate(stages: list, drives: DriveFrames, costs: UnitCosts) -> Estimate:
    """The :class:`Estimate` of ``stages`` (:class:`dcslam.stages.pipeline.Stage`) over ``drives``."""
    from dcslam.stages.config import to_dict

    slam_runs = sum(s.name.startswith("slam-") for s in stages)
    rows: dict[str, list] = {}
    for stage in stages:
        kind, units = stage_work(stage.name, to_dict(stage.config), drives, slam_runs)
        row = rows.setdefault(kind, [0, 0.0])
        row[0] += 1
        row[1] += units
    return Estimate({kind: (n, units, units * costs.per_unit[kind] if kind in costs.per_unit else None)
                     for kind, (n, units) in rows.items()}, costs.source)


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
    costs = unit_costs(ws.root, config.costs_from)
    result = estimate(todo, drives, costs)
    trained = sorted({s.seed for s in stages if s.seed is not None})
    lines = [f"dcslam reproduce --table {config.table} --profile {profile.name}: {len(splits.get('test', []))} test "
             f"drive(s), {seeds} training seed(s) per trained run (seeds {', '.join(map(str, trained)) or '—'}); "
             f"{len(stages)} stages, {len(stages) - len(todo)} up to date, {len(todo)} to run",
             f"estimated cost of the {len(todo)} to run (unit costs measured from {result.source}):",
             f"  {'stage kind':<18}{'stages':>7}{'units':>12}  {'unit':<45}{'s/unit':>9}{'CPU-hours':>11}"]
    for kind, (n, units, seconds) in result.rows.items():
        per = f"{costs.per_unit[kind]:.3g}" if kind in costs.per_unit else "—"
        lines.append(f"  {kind:<18}{n:>7}{units:>12.4g}  {UNITS[kind]:<45}{per:>9}{_hours(seconds):>11}")
    unmeasured = [kind for kind, (_, _, s) in result.rows.items() if s is None]
    lines.append(f"  {'total':<18}{len(todo):>7}{'':>12}  {'':<45}{'':>9}{_hours(result.total_seconds):>11}"
                 + (f" (without {', '.join(unmeasured)}: no unit cost measured)" if unmeasured else ""))
    if any(units == 0 for _, units, _ in result.rows.values()):
        lines.append("  (0 units: the drive files are not prepared yet, so their frames are not known)")
    lines.append("  CPU-hours: each stage's measured single-process wall seconds per unit x its units; with --jobs "
                 "J the training, prediction and SLAM stages run J at a time")
    return "\n".join(lines)


def costs_record(root: Path, source: str) -> dict:
    """What ``reproduce_costs.json`` holds: ``source`` (where and how ``root``'s stages were measured) and
    ``{kind: [seconds, units]}`` of its finished stages (:func:`measure`)."""
    totals = measure(root)
    if not totals:
        raise DcslamError(f"{Path(root) / '.reproduce'}: no finished stage to measure")
    return {"source": source, "kinds": {kind: [round(s, 3), u] for kind, (s, u) in sorted(totals.items())}}
