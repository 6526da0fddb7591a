"""Run SLAM over a drive file and write its outputs: the library side of ``dcslam slam``.

Per drive: ``<out>/<drive>.txt`` (TUM trajectory, readable by evo), ``<out>/<drive>.ply`` (the map with normals
and colours) and ``<out>/<drive>.json`` (frames, points, seconds per frame, rejected steps, drift against the
drive's ground truth, settings).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from dcslam.errors import DcslamError
from dcslam.slam.health import summarise
from dcslam.slam.pipeline import SLAM, StepReport
from dcslam.slam.pointmap import PointMap


@dataclass
class DriveRun:
    """Outputs of one drive. Shape: T_world_cam (N, 4, 4) float64, timestamps (N,), T_gt (N, 4, 4)."""

    name: str
    T_world_cam: np.ndarray
    timestamps: np.ndarray
    T_gt: np.ndarray
    map: PointMap
    reports: list[StepReport]
    seconds: float
    settings: dict = field(default_factory=dict)

    def summary(self) -> dict:
        from dcslam.geometry.se3 import pose_error

        dt, dr = pose_error(torch.from_numpy(self.T_gt), torch.from_numpy(self.T_world_cam))
        n = len(self.reports)
        return {
            "drive": self.name, "frames": n, "points": len(self.map),
            "seconds": round(self.seconds, 3), "seconds_per_frame": round(self.seconds / max(n, 1), 4),
            "map_megabytes": round(self.map.nbytes() / 2 ** 20, 2),
            "rejected_steps": [{"frame": r.index, "reason": r.reason} for r in self.reports if not r.accepted],
            "health": summarise(self.reports),
            "translation_error_m": {"final": float(dt[-1]), "max": float(dt.max()), "mean": float(dt.mean())},
            "rotation_error_deg": {"final": float(dr[-1]) * 180 / np.pi, "max": float(dr.max()) * 180 / np.pi},
            "settings": self.settings,
        }


def run_drive(drive_path: Path, depth_source: str | Path, slam: SLAM, frames: int | None = None,
              device: str = "cpu", description: str | None = None, settings: dict | None = None) -> DriveRun:
    """SLAM over the first ``frames`` frames (all if None) of a drive, with depth from ``sparse``, ``dense`` or a
    layer file."""
    from dcslam.io.drive import DriveFile, load_depth
    from dcslam.progress import Bar

    with DriveFile(drive_path) as drive:
        n = len(drive) if not frames else min(frames, len(drive))
        if n < 1:
            raise DcslamError(f"{drive_path}: no frames")
        depth_all = load_depth(drive, depth_source)[:n]
        K = torch.from_numpy(drive.K).float().to(device)
        T_gt = drive.poses[:n]
        slam.T_world_cam0 = torch.from_numpy(T_gt[0]).float()
        slam.reset()
        start = time.perf_counter()
        with Bar(description or drive.name, total=n) as bar:
            for i in range(n):
                depth = torch.from_numpy(np.ascontiguousarray(depth_all[i])).to(device)[None, None]
                rgb = torch.from_numpy(drive.rgb(i)).to(device).permute(2, 0, 1)[None].float() / 255
                report = slam.step(depth, K, rgb, torch.from_numpy(T_gt[i]).float().to(device))
                bar.advance(status=f"{report.points} points" + ("" if report.accepted else " (step rejected)"))
        seconds = time.perf_counter() - start
        poses = slam.trajectory().detach().cpu().double().numpy()
        global_map = slam.mapper.global_map().detach().to("cpu")
        return DriveRun(drive.name, poses, drive.timestamps[:n].copy(), T_gt.copy(), global_map,
                        list(slam.reports), seconds, dict(settings or {}))


def output_paths(out_dir: Path, name: str) -> dict[str, Path]:
    return {"trajectory": out_dir / f"{name}.txt", "map": out_dir / f"{name}.ply", "summary": out_dir / f"{name}.json"}


def check_outputs(out_dir: Path, name: str, force: bool) -> None:
    """Fail before any work if an output exists and ``force`` is false."""
    for path in output_paths(out_dir, name).values():
        if path.exists() and not force:
            raise DcslamError(f"{path} exists; pass --force to overwrite it")


def write_outputs(run: DriveRun, out_dir: Path, force: bool = False) -> dict[str, Path]:
    from dcslam.io.ply import write_ply
    from dcslam.io.tum import write_tum
    from dcslam.workspace import stage_config, write_json_atomic

    paths = output_paths(out_dir, run.name)
    check_outputs(out_dir, run.name, force)
    timestamps = run.timestamps.astype(np.float64)
    if len(timestamps) > 1 and np.any(np.diff(timestamps) <= 0):
        timestamps = np.arange(len(timestamps), dtype=np.float64) * 0.1
    write_tum(paths["trajectory"], timestamps, run.T_world_cam, force=force)
    pm = run.map
    write_ply(paths["map"], pm.points.numpy(), pm.normals.numpy(), pm.colors.clamp(0, 1).numpy(), force=force)
    record = stage_config("slam", run.settings)
    record.update(run.summary())
    write_json_atomic(paths["summary"], record, force=force)
    return paths
