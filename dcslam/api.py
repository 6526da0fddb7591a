"""The front door: the few calls a researcher starts from, re-exported by ``import dcslam``.

::

    import dcslam

    completed = dcslam.complete(sparse_m, "planefit")                 # one (H, W) depth map, metres, 0 = none
    run = dcslam.run_slam("workspace/drives/2011_09_26_drive_0001_sync.h5", depth="sparse", frames=30)
    print(dcslam.score_trajectory(run.T_gt, run.T_world_cam).localisation)

Each call wraps the library pieces the commands use (the same completers, SLAM and scores), so a result here equals
the command's on the same input and settings. Everything below is importable on its own for finer control
(:mod:`dcslam.slam`, :mod:`dcslam.depth`, :mod:`dcslam.eval`); ``docs/architecture.md`` says where each thing lives.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.eval.trajectory import TrajectoryScores, score_trajectory
from dcslam.slam.config import SlamSettings

__all__ = ["SlamSettings", "TrainedRun", "TrajectoryScores", "complete", "complete_drive", "load_completer",
           "load_run", "run_slam", "score_trajectory", "slam_arrays"]


def load_completer(model: str | Path = "ip-basic-fast", device: str = "cpu"):
    """A completer with its provenance (:class:`dcslam.depth.predict.Predictor`): ``model`` is a registered
    classical completer (``ip-basic-fast``, ``scanline``, ``planefit``, ...; ``dcslam predict --help`` lists them) or
    the folder of a training run (``workspace/runs/<run>``, its best ``model.pt``)."""
    from dcslam.depth.models import classical_name
    from dcslam.depth.predict import classical_predictor

    if isinstance(model, str) and classical_name(model):
        return classical_predictor(model)
    if not Path(model).is_dir():
        raise DcslamError(f"{model} is neither a registered completer nor a training run folder")
    from dcslam.stages.predict import run_predictor

    return run_predictor(model, device)


def complete(sparse_m: np.ndarray, model: str | Path = "ip-basic-fast", rgb: np.ndarray | None = None,
             device: str = "cpu") -> np.ndarray:
    """One sparse depth map completed by ``model`` (as :func:`load_completer` takes it).

    Shape:
        sparse_m: (H, W) metres, 0 = none; rgb: (H, W, 3) uint8, for networks guided by the image
        → (H, W) float32 metres, 0 where the completer leaves a pixel empty
    """
    completer = load_completer(model, device).completer
    if getattr(completer, "guided", False):
        if rgb is None:
            raise DcslamError(f"{model} is guided by the colour image; pass rgb=")
        return completer.complete(np.asarray(sparse_m, np.float32), rgb)[0]
    return completer(np.asarray(sparse_m, np.float32))


def complete_drive(drive: str | Path, out: str | Path, model: str | Path = "ip-basic-fast", input: str = "sparse",
                   force: bool = False, device: str = "cpu") -> Path:
    """Every frame of a drive file (``drives/<drive>.h5``) completed by ``model`` from its depth of kind ``input``
    (``sparse``, ``sparse@16``, ...), written as the layer file ``out`` (what ``dcslam predict`` writes); returns
    ``out``."""
    from dcslam.stages.predict import predict_drive

    return predict_drive(load_completer(model, device), drive, out, force=force, input=input)


def run_slam(drive: str | Path, depth: str | Path = "sparse", frames: int | None = None,
             settings: SlamSettings | None = None, device: str = "cpu"):
    """SLAM over the first ``frames`` frames (all if None) of a drive file, with depth from ``depth``: a depth kind
    of the drive (``sparse``, ``dense``, ``exact``, ``sparse@16``) or a layer file (a prediction, a filtered layer).
    ``settings``: :class:`SlamSettings` (the defaults of ``dcslam slam``). The frames are read as they are used.

    Returns:
        a :class:`dcslam.slam.drive.DriveRun`: ``T_world_cam`` and ``T_gt`` (N, 4, 4), ``timestamps`` (N,), the
        fused ``map``, per-frame ``reports`` and the ``summary()`` that ``dcslam slam`` writes (without its companion
        check, which needs the drive's measured pixels: ``dcslam slam`` runs it).
    """
    from dcslam.slam.config import build_slam
    from dcslam.stages.slam import run_drive_file

    settings = settings or SlamSettings()
    return run_drive_file(Path(drive), depth, build_slam(settings), frames, device, settings=settings.to_dict())


def slam_arrays(depth_m: np.ndarray, K: np.ndarray, T_world_cam0: np.ndarray | None = None,
                settings: SlamSettings | None = None) -> np.ndarray:
    """SLAM over depth maps held in memory (no files): the trajectory it estimates.

    Shape:
        depth_m: (N, H, W) metres, 0 = none; K: (3, 3) pinhole intrinsics; T_world_cam0: (4, 4), the first pose
        (identity if None) → T_world_cam (N, 4, 4) float64
    """
    import torch

    from dcslam.slam.config import build_slam

    depth_m = np.asarray(depth_m, np.float32)
    if depth_m.ndim != 3:
        raise DcslamError(f"depth has shape {depth_m.shape}, expected (N, H, W)")
    settings = settings or SlamSettings()
    if settings.odometry == "gt":
        raise DcslamError("odometry 'gt' needs ground-truth poses; slam_arrays has none (use run_slam on a drive)")
    slam = build_slam(settings)
    if T_world_cam0 is not None:
        slam.T_world_cam0 = torch.from_numpy(np.asarray(T_world_cam0, np.float64)).float()
    slam.reset()
    with torch.no_grad():
        poses = slam.run(torch.from_numpy(depth_m)[:, None], torch.from_numpy(np.asarray(K, np.float32)))
    return poses.detach().cpu().double().numpy()


@dataclass
class TrainedRun:
    """A training run read back: its ``name``, the settings it was trained with, its logged ``metrics`` (one dict
    per line of ``metrics.jsonl``) and ``predictor``, its best model as a completer."""

    name: str
    path: Path
    settings: dict
    metrics: list
    predictor: object

    def complete(self, sparse_m: np.ndarray, rgb: np.ndarray | None = None) -> np.ndarray:
        """(H, W) metres → (H, W) float32 metres, as :func:`complete`."""
        completer = self.predictor.completer
        return completer.complete(sparse_m, rgb)[0] if completer.guided else completer(sparse_m)


def load_run(run_dir: str | Path, device: str = "cpu") -> TrainedRun:
    """A training run folder (``workspace/runs/<run>``, what ``dcslam train`` writes) read back."""
    run_dir = Path(run_dir)
    if not (run_dir / "model.pt").exists():
        raise DcslamError(f"{run_dir} holds no model.pt; is it a run folder of `dcslam train`?")
    config = run_dir / "config.json"
    settings = json.loads(config.read_text(encoding="utf-8")).get("settings", {}) if config.exists() else {}
    metrics_path = run_dir / "metrics.jsonl"
    metrics = [json.loads(line) for line in metrics_path.read_text(encoding="utf-8").splitlines() if line.strip()] \
        if metrics_path.exists() else []
    from dcslam.stages.predict import run_predictor

    return TrainedRun(run_dir.name, run_dir, settings, metrics, run_predictor(run_dir, device))
