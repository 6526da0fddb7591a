"""Scoring depth layers and SLAM trajectories of a workspace over drives.

Layers are named as everywhere in dcslam (see :func:`dcslam.workspace.find_layer`, the one resolver). The SLAM
outputs of a layer are ``slam/<layer>/<drive>.txt`` (TUM) and ``<drive>.ply``.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from dcslam.errors import DcslamError
from dcslam.eval.depth import DepthErrors
from dcslam.eval.trajectory import (EVO_MAX_TIME_DIFF_S, Association, TrajectoryScores, associate_timestamps,
                                    score_trajectory)
from dcslam.workspace import LayerRef, Workspace, drive_file, find_layer, resolve_layer, select_drives

if TYPE_CHECKING:  # the surface errors need torch (~2 s to import): scoring trajectories alone does not import it
    from dcslam.eval.surface import SurfaceErrors

__all__ = ["LayerRef", "TrajectoryPair", "drive_file", "find_layer", "load_pair", "resolve_layer",
           "score_layer_depth", "score_layer_surface", "score_layer_trajectories", "select_drives", "slam_outputs",
           "slam_settings", "slam_surface_settings", "slam_trajectory", "surface_frames", "surface_target"]

#: The SLAM settings that make two trajectories comparable (``beams``: the sparse input's beam count, when known;
#: ``confidence`` and ``min_confidence``: how a layer's confidence was used, ``none`` for a layer without one;
#: ``sources`` and ``measured``: the ICP sources as the run used them, ``depth`` or ``measured`` and the measured
#: drive depth kind, None in depth mode).
RUN_SETTINGS = ("frames", "odometry", "mapper", "solver", "association", "voxel_size", "beams", "confidence",
                "min_confidence", "sources", "measured")


def score_layer_depth(ws: Workspace, layer: LayerRef, drives: list[str], interpolate: bool = True,
                      devkit_exact: bool = False, target: str = "dense") -> dict[str, list[DepthErrors | None]]:
    """Per-frame depth errors of a layer against each drive's depth of kind ``target`` (``dense`` or ``exact``):
    ``{drive: [errors per frame]}``."""
    from dcslam.eval.depth import score_drive
    from dcslam.progress import track

    return {drive: score_drive(drive_file(ws, drive), layer.source(drive), interpolate, devkit_exact, target=target)
            for drive in track(drives, f"depth {layer.name}")}


def slam_surface_settings(depth_m: np.ndarray, reference_m: np.ndarray):
    """The :class:`dcslam.eval.surface.SurfaceSettings` under which a depth image and its reference get the points
    and normals a SLAM run of default frame settings gives them (the normal search chosen from each one's fraction
    of in-range pixels, :func:`dcslam.slam.frame.normal_search_for`). Shape: depth_m, reference_m (H, W)."""
    from dcslam.eval.surface import SurfaceSettings
    from dcslam.slam.frame import FrameSettings, normal_search_for

    frame = FrameSettings()

    def search(depth: np.ndarray) -> int:
        return normal_search_for(float(((depth >= frame.min_depth) & (depth <= frame.max_depth)).mean()))

    return SurfaceSettings(search=search(depth_m), reference_search=search(reference_m),
                           max_relative_gap=frame.max_relative_gap, min_depth=frame.min_depth,
                           max_depth=frame.max_depth)


#: Frames of each drive whose surface errors a table scores (:func:`surface_frames`): they cost 0.15-0.3 s of CPU
#: per full-size frame (docs/metrics.md), so a table of many rows scores a fixed sample of each drive, not every frame.
SURFACE_FRAMES = 5


def surface_frames(n: int, count: int = SURFACE_FRAMES) -> list[int]:
    """The frame indices of a drive of ``n`` frames that a table scores the surface of: ``count`` evenly spaced
    ones, the first and the last included (index ``round(k (n - 1) / (count - 1))``, halves up, for k = 0 …
    count - 1); every frame when ``n <= count``. Depends on ``n`` alone, so every row scores the same frames."""
    if count < 1:
        raise DcslamError(f"surface frames must be >= 1, got {count}")
    if n <= count:
        return list(range(n))
    if count == 1:
        return [(n - 1) // 2]
    return [int(np.floor(k * (n - 1) / (count - 1) + 0.5)) for k in range(count)]


def surface_target(ws: Workspace, drives: list[str]) -> str:
    """The reference of a table's surface errors: ``exact`` (the generator's depth) when every one of ``drives``
    holds it, else ``dense`` (the annotated depth)."""
    from dcslam.io.drive import EXACT, DriveFile

    for drive in drives:
        with DriveFile(drive_file(ws, drive)) as d:
            if EXACT not in d.kinds:
                return "dense"
    return EXACT


def score_layer_surface(ws: Workspace, layer: LayerRef, drives: list[str], target: str = "dense",
                        frames: int | None = None) -> dict[str, list[SurfaceErrors | None]]:
    """Per-frame surface errors (:mod:`dcslam.eval.surface`) of a layer against each drive's depth of kind
    ``target`` (``dense`` or ``exact``), with the normals SLAM would take (:func:`slam_surface_settings`):
    ``{drive: [errors per frame]}``, over every frame or, with ``frames``, the :func:`surface_frames` of that
    many."""
    from dcslam.eval.surface import surface_errors
    from dcslam.io.drive import DriveFile, load_depth
    from dcslam.progress import track

    scores = {}
    for drive in track(drives, f"surface {layer.name}"):
        with DriveFile(drive_file(ws, drive)) as d:
            pred, K = load_depth(d, layer.source(drive)), d.K
            chosen = range(len(pred)) if frames is None else surface_frames(len(pred), frames)
            reference = [d.depth(target, i) for i in chosen]
        scores[drive] = [surface_errors(pred[i], r, K, slam_surface_settings(pred[i], r))
                         for i, r in zip(chosen, reference)]
    return scores


@dataclass(frozen=True)
class TrajectoryPair:
    """An estimate and its reference, paired pose by pose: ``T_gt`` and ``T_est`` (N, 4, 4), ``timestamps`` (N,)
    (the estimate's); ``association`` says how they were paired (``None``: by index)."""

    timestamps: np.ndarray
    T_gt: np.ndarray
    T_est: np.ndarray
    association: Association | None = None

    def score(self) -> TrajectoryScores:
        return score_trajectory(self.T_gt, self.T_est)

    def summary(self) -> str:
        if self.association is None:
            return f"{len(self.T_est)} poses paired by index"
        return self.association.summary()

    def left_out(self) -> str | None:
        """One line naming the poses of either side left out of the pairs, or ``None`` when every pose paired."""
        a = self.association
        if a is None or (a.pairs == a.est_poses and a.pairs == a.gt_poses):
            return None
        return (f"{a.est_poses - a.pairs} of {a.est_poses} estimated and {a.gt_poses - a.pairs} of {a.gt_poses} "
                f"reference poses left out (no pose within {1000 * a.max_time_diff_s:g} ms on the other side)")


def _is_kitti_poses(path: Path) -> bool:
    """A KITTI pose file has 12 numbers a line (a TUM file 8); the first non-empty line decides."""
    with open(path) as f:
        for line in f:
            if line.strip() and not line.startswith("#"):
                return len(line.split()) == 12
    return False


def _read_reference(gt_path: Path) -> tuple[np.ndarray | None, np.ndarray]:
    from dcslam.io.kitti_poses import read_kitti_poses
    from dcslam.io.tum import read_tum

    if gt_path.suffix in (".h5", ".hdf5"):
        from dcslam.io.drive import DriveFile

        with DriveFile(gt_path) as drive:
            return drive.timestamps, drive.poses
    if _is_kitti_poses(gt_path):
        return None, read_kitti_poses(gt_path)
    return read_tum(gt_path)


def load_pair(est_path: Path | str, gt_path: Path | str,
              max_time_diff: float = EVO_MAX_TIME_DIFF_S) -> TrajectoryPair:
    """Read an estimated trajectory and its reference, and pair their poses.

    The estimate is a TUM file or a KITTI pose file (12 numbers a line, no timestamps); the reference a drive file,
    a TUM file or a KITTI pose file. Poses with timestamps on both sides are associated as evo does (nearest
    timestamp within ``max_time_diff`` seconds; only the paired poses are scored); a KITTI pose file without
    timestamps is paired by index with a reference of as many poses (it takes the reference's timestamps), and
    refused (:class:`DcslamError`) against one of another length.
    """
    from dcslam.io.kitti_poses import read_kitti_poses
    from dcslam.io.tum import read_tum

    est_path, gt_path = Path(est_path), Path(gt_path)
    for path in (est_path, gt_path):
        if not path.exists():
            raise DcslamError(f"{path} not found")
    if est_path.is_dir():
        raise DcslamError(f"trajectory file {est_path} is a folder; pass a TUM trajectory file or a KITTI pose file")
    if _is_kitti_poses(est_path):
        t_est, T_est = None, read_kitti_poses(est_path)
    else:
        t_est, T_est = read_tum(est_path)
    t_gt, T_gt = _read_reference(gt_path)
    if t_est is None or t_gt is None:
        # by index only when both sides hold the same frames: a shorter or longer side would score other poses
        if len(T_est) != len(T_gt):
            raise DcslamError(
                f"{est_path} has {len(T_est)} poses, its reference {gt_path} {len(T_gt)}: without timestamps on "
                "both sides poses are paired by index, which needs as many on each side; pass a TUM trajectory "
                "(timestamps) and a reference with timestamps (a drive file or TUM), or files of the same frames")
        timestamps = t_gt if t_gt is not None else (t_est if t_est is not None else
                                                    np.arange(len(T_est), dtype=float))
        return TrajectoryPair(timestamps=timestamps, T_gt=T_gt, T_est=T_est)
    try:
        assoc = associate_timestamps(t_est, t_gt, max_time_diff)
    except DcslamError as error:
        raise DcslamError(f"{est_path} against {gt_path}: {error}") from None
    return TrajectoryPair(timestamps=t_est[assoc.est_indices], T_gt=T_gt[assoc.gt_indices],
                          T_est=T_est[assoc.est_indices], association=assoc)


def slam_outputs(ws: Workspace, layer: str, drive: str, root: Path | None = None) -> dict[str, Path]:
    """The committed SLAM outputs of ``<root>/<layer>/<drive>`` (``root``: ``slam/`` unless given), checked to be
    made from the layer as it is now, and the layer from its own inputs as they are now
    (:func:`dcslam.io.slam_summary.committed_outputs`, :func:`dcslam.io.lineage.check_layer_folder`); one
    :class:`DcslamError` line naming what to rerun otherwise."""
    from dcslam.io.lineage import check_layer_folder
    from dcslam.io.slam_summary import committed_outputs

    paths = committed_outputs((ws.slam if root is None else root) / layer, drive,
                              f"dcslam slam --depth {layer} --force")
    found = find_layer(ws, layer) if Path(layer).name == layer else None
    check_layer_folder(found.folder if found is not None else None)
    return paths


def slam_trajectory(ws: Workspace, layer: str, drive: str, root: Path | None = None) -> Path:
    """``<root>/<layer>/<drive>.txt``, ``root`` being ``slam/`` unless given (e.g. ``slam-long/``); only from a
    committed set whose inputs are unchanged (:func:`slam_outputs`)."""
    return slam_outputs(ws, layer, drive, root)["trajectory"]


def slam_settings(ws: Workspace, layer: str, drive: str, root: Path | None = None) -> dict:
    """The settings of the SLAM run behind ``slam/<layer>/<drive>.txt`` (:data:`RUN_SETTINGS`, from the summary
    ``<drive>.json`` beside it; ``frames`` is the number asked for, 0 = all: a drive shorter than that runs fewer,
    which its pose count shows), ``camera``: True where the camera ran beside it (``--camera``, the default; absent
    under ``--no-camera``), plus ``suspect``: the run's verdict (:func:`dcslam.io.slam_summary.run_verdict`: it
    rejected steps, or its health flagged it for degraded steps or its drift bound, or the camera). Empty when the
    summary is missing (a trajectory made elsewhere). ``root``: the folder of the layers' SLAM outputs (default
    ``slam/``)."""
    from dcslam.io.slam_summary import read_summary, run_verdict

    path = (ws.slam if root is None else root) / layer / f"{drive}.json"
    if not path.exists():
        return {}
    slam_outputs(ws, layer, drive, root)
    record = read_summary(path, f"rerun `dcslam slam --depth {layer} --force`")
    settings = {**record.get("settings", {}), **({"beams": record["beams"]} if "beams" in record else {})}
    used = record.get("confidence")
    if isinstance(used, dict) and "mode" in used:    # what was done, not what was asked (a layer may have none)
        settings.update(confidence=used["mode"], min_confidence=used.get("min_confidence", 0.0))
    # what ran, not what was asked (``measured`` defaults to the layer's input); a summary from before the option
    # records none: its run aligned the depth's own points
    sources = record.get("sources") if isinstance(record.get("sources"), dict) else {"mode": "depth"}
    settings.update(sources=sources.get("mode", "depth"), measured=sources.get("kind"))
    out = {k: settings[k] for k in RUN_SETTINGS if k in settings}
    health = record.get("health")
    if isinstance(health, dict) and health.get("camera"):  # the camera ran beside it (`--camera`): say so
        out["camera"] = True
    out["suspect"] = run_verdict(record, str(path)).suspect
    return out


def score_layer_trajectories(ws: Workspace, layer: str, drives: list[str],
                             max_time_diff: float = EVO_MAX_TIME_DIFF_S,
                             root: Path | None = None) -> dict[str, TrajectoryPair]:
    """The SLAM trajectories of a layer (under ``root``, default ``slam/``) paired with the drives' ground truth:
    ``{drive: pair}``."""
    return {drive: load_pair(slam_trajectory(ws, layer, drive, root), drive_file(ws, drive), max_time_diff)
            for drive in drives}
