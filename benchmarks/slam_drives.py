"""Shared by the SLAM benchmarks: run dcslam's SLAM over prepared drive files with given settings and score each
drive (ATE, RPE, final error, health flags, frames/s). Not a benchmark itself (no ``bench_`` prefix)."""
from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass
class DriveScore:
    drive: str
    depth: str
    frames: int
    ate_m: float          # RMSE of position errors, no alignment (both start at the true first pose)
    rpe_m: float          # RMSE of frame-to-frame translation errors
    final_m: float        # position error at the last frame
    drift_pct: float      # final error / distance travelled
    degraded: int
    rejected: int
    suspect: bool
    fps: float            # frames per second of wall-clock time (SLAM steps only)
    cpu_fps: float = float("nan")   # frames per second of this process's CPU time (1 thread: what a quiet core gives)


def score(name: str, depth: str, T_gt: np.ndarray, T_est: np.ndarray, seconds: float, degraded: int = 0,
          rejected: int = 0, suspect: bool = False, cpu_seconds: float = float("nan")) -> DriveScore:
    """Scores of one estimate. Shape: T_gt, T_est (N, 4, 4)."""
    from dcslam.eval.trajectory import ate_errors, rpe_errors

    ate = ate_errors(T_gt, T_est, align=False)
    rpe_t, _ = rpe_errors(T_gt, T_est) if len(T_gt) > 1 else (np.zeros(1), None)
    travelled = float(np.linalg.norm(np.diff(T_gt[:, :3, 3], axis=0), axis=1).sum())
    n = len(T_gt)
    return DriveScore(name, depth, n, float(np.sqrt((ate ** 2).mean())), float(np.sqrt((rpe_t ** 2).mean())),
                      float(ate[-1]), 100 * float(ate[-1]) / max(travelled, 1e-9), degraded, rejected, suspect,
                      n / max(seconds, 1e-9), n / max(cpu_seconds, 1e-9))


def run_dcslam(drive_path: Path, depth: str, settings, frames: int | None = None, device: str = "cpu",
               steps: list | None = None) -> DriveScore:
    """dcslam's SLAM (settings: a SlamSettings) over one drive file -> its scores; per-step evidence is appended to
    ``steps`` when given. ``depth``: a depth kind of the drive (``sparse``, ``sparse@16`` from ``prepare-kitti
    --beams``, ``dense``) or a layer file."""
    import torch

    from dcslam.io.drive import DriveFile, load_depth
    from dcslam.slam.config import build_slam

    slam = build_slam(settings)
    with DriveFile(drive_path) as drive:
        n = len(drive) if not frames else min(frames, len(drive))
        depth_all = load_depth(drive, depth)[:n]
        K = torch.from_numpy(drive.K).float().to(device)
        T_gt = drive.poses[:n]
        slam.T_world_cam0 = torch.from_numpy(T_gt[0]).float().to(device)
        slam.reset()
        frames_t = [torch.from_numpy(np.ascontiguousarray(depth_all[i])).to(device)[None, None] for i in range(n)]
        start, cpu_start = time.perf_counter(), time.process_time()
        for i in range(n):
            slam.step(frames_t[i], K)
        if device.startswith("cuda"):
            torch.cuda.synchronize()
        seconds, cpu_seconds = time.perf_counter() - start, time.process_time() - cpu_start
        health = slam.health_summary()
        T_est = slam.trajectory().detach().cpu().double().numpy()
        if steps is not None:                   # per-step evidence and the error each step added
            for r in slam.reports[1:]:
                X_gt = np.linalg.solve(T_gt[r.index - 1], T_gt[r.index])
                X_est = np.linalg.solve(T_est[r.index - 1], T_est[r.index])
                steps.append({"drive": drive_path.stem, "depth": depth, "frame": r.index, "verdict": r.verdict,
                              "sources": r.sources, "inliers": r.inliers, "conditioning": r.conditioning,
                              "gap_m": r.gap_m, "gap_deg": r.gap_deg, "rmse": r.rmse,
                              "sigma_m": r.sigma_m, "sigma_deg": r.sigma_deg,
                              "step_rot_error_deg": _angle_deg(np.linalg.solve(X_gt, X_est)),
                              "final_error_m": float(np.linalg.norm(T_est[-1, :3, 3] - T_gt[-1, :3, 3])),
                              "step_length_m": float(np.linalg.norm(X_est[:3, 3])),
                              "step_error_m": float(np.linalg.norm(X_est[:3, 3] - X_gt[:3, 3]))})
    return score(drive_path.stem, str(depth), T_gt, T_est, seconds, health["degraded"], health["rejected"],
                 health["suspect"], cpu_seconds)


def _angle_deg(X: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(X[:3, :3]) - 1) / 2, -1.0, 1.0))))


def parse_settings(text: str):
    """``key=value;key=value`` -> SlamSettings (types from the dataclass fields)."""
    from dcslam.slam.config import SlamSettings

    kwargs = {}
    for item in filter(None, text.split(";")):
        key, value = item.split("=")
        kind = SlamSettings.__dataclass_fields__[key].type
        kwargs[key] = {"int": int, "float": float, "str": str, "bool": lambda v: v in ("1", "true", "True")}[kind](
            value)
    return SlamSettings(**kwargs)


def markdown_table(rows: list[DriveScore], title: str) -> str:
    lines = [f"### {title}", "", "| drive | depth | frames | ATE m | RPE m | final m | drift % | degraded | rejected "
             "| suspect | frames/s wall | frames/s CPU |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r.drive[-9:-5]} | {r.depth} | {r.frames} | {r.ate_m:.3f} | {r.rpe_m:.3f} | {r.final_m:.2f} "
                     f"| {r.drift_pct:.2f} | {r.degraded} | {r.rejected} | {'yes' if r.suspect else 'no'} "
                     f"| {r.fps:.2f} | {r.cpu_fps:.2f} |")
    bad = [r for r in rows if r.final_m > 0.5]
    silent = [r for r in bad if not r.suspect]
    lines += ["", f"{len(rows)} drives; {len(bad)} end more than 0.5 m from the truth, {len(silent)} of them "
              f"without a suspect flag; {sum(r.suspect for r in rows if r.final_m <= 0.5)} good drives flagged; median "
              f"frames/s {np.median([r.fps for r in rows]):.2f} wall, {np.median([r.cpu_fps for r in rows]):.2f} CPU "
              f"(load average {os.getloadavg()[0]:.1f} at the end).", ""]
    return "\n".join(lines)
