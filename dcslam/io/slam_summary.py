"""The verdict of a SLAM run, read from the summary ``<drive>.json`` that ``dcslam slam`` writes beside its
trajectory: the one reader that every table uses to decide whether a run failed.

The summary holds ``rejected_steps`` (a list, one entry per step the odometry refused) and ``health``
(:func:`dcslam.slam.health.summarise`: ``suspect``, ``reasons``, counts of accepted / degraded / rejected steps).
A run is flagged when its health says suspect (rejected or degraded steps, the drift bound) or when it rejected a
step, unless the camera vouched for it (``health.camera``, ``dcslam slam --camera``: its trajectory measured from
the images ends within 0.5 m of the run's, which no rejected step changes). A summary without ``health`` (written
before the verdicts existed) is judged by its rejected steps alone.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from dcslam.errors import DcslamError


@dataclass(frozen=True)
class RunVerdict:
    """Whether a SLAM run is flagged (``suspect``), why (``reasons``, the health's own words), and its counts of
    ``rejected`` and ``degraded`` steps."""

    suspect: bool
    reasons: tuple[str, ...] = ()
    rejected: int = 0
    degraded: int = 0


def read_summary(path: Path | str, fix: str = "rerun `dcslam slam --force`") -> dict:
    """The JSON object of a SLAM summary; a :class:`DcslamError` naming the file (and ``fix``) when it is not one."""
    path = Path(path)
    try:
        record = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError):
        raise DcslamError(f"{path}: not valid JSON; {fix}") from None
    except OSError as exc:
        raise DcslamError(f"{path}: cannot be read ({exc.strerror or exc}); {fix}") from None
    if not isinstance(record, dict):
        raise DcslamError(f"{path}: not a SLAM summary (a JSON object); {fix}")
    return record


def run_verdict(record: dict, where: str = "SLAM summary") -> RunVerdict:
    """The verdict of the run a summary ``record`` describes (``where``: its file, for the error message)."""
    rejected_steps = record.get("rejected_steps", [])
    if not isinstance(rejected_steps, list):
        raise DcslamError(f"{where}: 'rejected_steps' is not a list; rerun `dcslam slam --force`")
    health = record.get("health")
    if health is None:
        n = len(rejected_steps)
        return RunVerdict(suspect=n > 0, reasons=(f"{n} steps rejected",) if n else (), rejected=n)
    if not isinstance(health, dict) or not isinstance(health.get("suspect"), bool):
        raise DcslamError(f"{where}: 'health' has no true/false 'suspect'; rerun `dcslam slam --force`")
    reasons = tuple(str(r) for r in health.get("reasons", []))
    rejected = max(int(health.get("rejected", 0)), len(rejected_steps))
    vouched = isinstance(health.get("camera"), dict) and health["camera"].get("verdict") == "agrees"
    if rejected and not health["suspect"] and not vouched:
        reasons += (f"{rejected} steps rejected",)
    return RunVerdict(suspect=health["suspect"] or (rejected > 0 and not vouched), reasons=reasons, rejected=rejected,
                      degraded=int(health.get("degraded", 0)))


def read_verdict(path: Path | str) -> RunVerdict:
    """:func:`run_verdict` of the summary file at ``path``."""
    return run_verdict(read_summary(path), str(path))


def committed_outputs(out_dir: Path | str, drive: str, rerun: str = "dcslam slam --force") -> dict[str, Path]:
    """A drive's SLAM outputs in ``out_dir`` (``trajectory``, ``kitti_poses``, ``map``, ``summary``), accepted only
    as the complete set that ``<drive>.done`` commits and only while the inputs its summary records
    (:mod:`dcslam.io.lineage`) are unchanged; otherwise one :class:`DcslamError` line saying to run ``rerun``.

    Outputs without a marker (a run that failed while writing them, or one made before markers existed) are refused
    rather than scored."""
    from dcslam.io.atomic import committed_files
    from dcslam.io.lineage import check_made_from

    out_dir = Path(out_dir)
    marker = out_dir / f"{drive}.done"
    paths = {"trajectory": out_dir / f"{drive}.txt", "kitti_poses": out_dir / f"{drive}.kitti.txt",
             "map": out_dir / f"{drive}.ply", "summary": out_dir / f"{drive}.json"}
    if not marker.exists():
        if not any(p.exists() for p in paths.values()):
            raise DcslamError(f"trajectory {paths['trajectory']} not found; run `{rerun.replace(' --force', '')}` "
                              "first")
        raise DcslamError(f"the SLAM outputs of {drive} in {out_dir} are not committed (no {marker.name}: the run "
                          f"failed while writing them, or an older dcslam wrote them); rerun `{rerun}`")
    try:
        committed_files(marker)
    except DcslamError as error:
        raise DcslamError(f"{error}".replace("rerun the command that makes it with --force", f"rerun `{rerun}`"))
    if paths["summary"].exists():  # a set made elsewhere may hold a trajectory alone
        check_made_from(read_summary(paths["summary"], f"rerun `{rerun}`"), out_dir, paths["summary"], rerun)
    return paths
