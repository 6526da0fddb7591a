"""Scoring depth layers and SLAM trajectories of a workspace over drives.

Layers are named as everywhere in dcslam (see :func:`dcslam.workspace.find_layer`, the one resolver). The SLAM
outputs of a layer are ``slam/<layer>/<drive>.txt`` (TUM) and ``<drive>.ply``.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.eval.depth import DepthErrors
from dcslam.eval.trajectory import TrajectoryScores, pair_by_timestamps, score_trajectory
from dcslam.workspace import LayerRef, Workspace, drive_file, find_layer, resolve_layer, select_drives

__all__ = ["LayerRef", "TrajectoryPair", "drive_file", "find_layer", "load_pair", "resolve_layer",
           "score_layer_depth", "score_layer_trajectories", "select_drives", "slam_trajectory"]

def score_layer_depth(ws: Workspace, layer: LayerRef, drives: list[str], interpolate: bool = True,
                      target: str = "dense") -> dict[str, list[DepthErrors | None]]:
    """Per-frame depth errors of a layer against each drive's depth of kind ``target`` (``dense`` or ``exact``):
    ``{drive: [errors per frame]}``."""
    from dcslam.eval.depth import score_drive
    from dcslam.progress import track

    return {drive: score_drive(drive_file(ws, drive), layer.source(drive), interpolate, target=target)
            for drive in track(drives, f"depth {layer.name}")}


@dataclass(frozen=True)
class TrajectoryPair:
    """An estimate and its reference, paired pose by pose: ``T_gt`` and ``T_est`` (N, 4, 4), ``timestamps`` (N,)."""

    timestamps: np.ndarray
    T_gt: np.ndarray
    T_est: np.ndarray

    def score(self) -> TrajectoryScores:
        return score_trajectory(self.T_gt, self.T_est)


def load_pair(est_path: Path | str, gt_path: Path | str) -> TrajectoryPair:
    """Read an estimated TUM trajectory and its reference: a drive file (the estimate may cover the first frames
    only; it is matched by timestamp) or another TUM file (same timestamps, same length)."""
    from dcslam.io.tum import read_tum

    t_est, T_est = read_tum(est_path)
    gt_path = Path(gt_path)
    if gt_path.suffix in (".h5", ".hdf5"):
        from dcslam.io.drive import DriveFile

        with DriveFile(gt_path) as drive:
            t_gt, T_gt = drive.timestamps, drive.poses
        allow_prefix = True
    else:
        t_gt, T_gt = read_tum(gt_path)
        allow_prefix = False
    try:
        n = pair_by_timestamps(t_est, t_gt, allow_prefix=allow_prefix)
    except DcslamError as error:
        raise DcslamError(f"{est_path} against {gt_path}: {error}") from None
    return TrajectoryPair(timestamps=t_est, T_gt=T_gt[:n], T_est=T_est)


def slam_trajectory(ws: Workspace, layer: str, drive: str) -> Path:
    path = ws.slam / layer / f"{drive}.txt"
    if not path.exists():
        raise DcslamError(f"trajectory {path} not found; run `dcslam slam --depth {layer}` first")
    return path


def score_layer_trajectories(ws: Workspace, layer: str, drives: list[str]) -> dict[str, TrajectoryPair]:
    """The SLAM trajectories of a layer paired with the drives' ground truth: ``{drive: pair}``."""
    return {drive: load_pair(slam_trajectory(ws, layer, drive), drive_file(ws, drive)) for drive in drives}
