"""Finding depth layers, trajectories and maps in a workspace, and scoring them over drives.

A *layer name* is ``sparse`` or ``dense`` (depth stored in the drive files), the name of a run
(``predictions/<run>/``), of a filter output (``filtered/<name>/``), or a folder of ``<drive>.h5`` layer files.
The SLAM outputs of a layer are ``slam/<layer>/<drive>.txt`` (TUM) and ``<drive>.ply``.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.eval.depth import DepthErrors
from dcslam.eval.trajectory import TrajectoryScores, pair_by_timestamps, score_trajectory
from dcslam.workspace import Workspace

DRIVE_DEPTH = ("sparse", "dense")


@dataclass(frozen=True)
class LayerRef:
    """A depth layer over many drives: ``folder`` holds ``<drive>.h5`` files (``None``: the drive files' own
    ``sparse`` / ``dense`` depth)."""

    name: str
    folder: Path | None

    def source(self, drive: str) -> str | Path:
        """What :func:`dcslam.io.drive.load_depth` takes for one drive."""
        return self.name if self.folder is None else self.folder / f"{drive}.h5"


def find_layer(ws: Workspace, name: str) -> LayerRef | None:
    """The layer called ``name`` (see the module docstring), or ``None`` if there is none."""
    if name in DRIVE_DEPTH:
        return LayerRef(name, None)
    for folder in (ws.predictions / name, ws.filtered / name, Path(name)):
        if folder.is_dir():
            return LayerRef(folder.name, folder)
    return None


def resolve_layer(ws: Workspace, name: str) -> LayerRef:
    """Like :func:`find_layer`, but fails with a message naming the commands that make layers."""
    layer = find_layer(ws, name)
    if layer is None:
        raise DcslamError(f"no depth layer {name!r}: not sparse or dense, and neither {ws.predictions / name} nor "
                          f"{ws.filtered / name} exists; run `dcslam predict` or `dcslam filter` first")
    return layer


def select_drives(ws: Workspace, drives: list[str] | None = None, split: str = "test") -> list[str]:
    """``drives`` if given, else the drives of ``split`` in ``splits.json``."""
    from dcslam.io.drive import read_splits

    drives = list(drives) if drives else list(read_splits(ws.splits)[split])
    if not drives:
        raise DcslamError(f"{ws.splits}: no {split} drives; pass --drive or rerun `dcslam prepare-kitti`")
    return drives


def drive_file(ws: Workspace, drive: str) -> Path:
    path = ws.drives / f"{drive}.h5"
    if not path.exists():
        raise DcslamError(f"drive file {path} not found; run `dcslam prepare-kitti` first")
    return path


def score_layer_depth(ws: Workspace, layer: LayerRef, drives: list[str],
                      interpolate: bool = True) -> dict[str, list[DepthErrors | None]]:
    """Per-frame depth errors of a layer against each drive's dense depth: ``{drive: [errors per frame]}``."""
    from dcslam.eval.depth import score_drive
    from dcslam.progress import track

    return {drive: score_drive(drive_file(ws, drive), layer.source(drive), interpolate)
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
