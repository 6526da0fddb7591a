"""Does a change to the SLAM's hot paths keep its results, and what does it save? Runs the SLAM on three small
generated drives of the analytic street (``dcslam.slam.scene``), records each drive's trajectory and map size per
frame, and measures the process CPU time per frame (one torch thread, so other processes' load does not count).

Drives (30 frames each, at reduced size): LiDAR-like sparse depth with the default settings; dense exact depth
(completed-like) with the default settings; dense depth with ICP-SLAM's map and a 6-frame local window, so that the
frames past the window show whether the CPU per frame stays flat.

Usage: ``python benchmarks/slam_equivalence.py --save base.npz`` on the reference code, then
``python benchmarks/slam_equivalence.py --compare base.npz`` after a change: it prints, per drive, the largest
difference of the trajectories' translations (metres) and rotations (matrix entries), the map sizes that differ, the
CPU per frame and the ATE against the true poses before / after. The CPU figures of both runs depend on the
machine's load: read the ratio, and repeat when it is noisy. Exit status 1 when a trajectory differs by more than
``--tolerance`` (1e-6 m).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

FRAMES = 30


def _drives(frames: int):
    """(name, depth (N, 1, H, W) float32, K (3, 3), settings, true poses (N, 4, 4) relative to the first) of each
    drive."""
    import torch

    from dcslam.slam.config import SlamSettings
    from dcslam.slam.scene import StreetScene, kitti_K, lidar_mask, street_trajectory

    out = []
    H, W = 192, 624
    scene, K = StreetScene(3, length=frames + 80.0), kitti_K(H, W)
    T = street_trajectory(frames, step=0.8)
    mask = lidar_mask(H, W, row_step=4, col_step=2)
    sparse = torch.stack([scene.render(T[i], K, H, W, mask=mask) for i in range(frames)]).float()[:, None]
    truth = torch.linalg.solve(T[0].double(), T.double())
    out.append(("sparse", sparse, K, SlamSettings(), truth))
    H, W = 128, 416
    K = kitti_K(H, W)
    dense = torch.stack([scene.render(T[i], K, H, W) for i in range(frames)]).float()[:, None]
    out.append(("dense", dense, K, SlamSettings(), truth))
    out.append(("dense-icpslam-window", dense, K, SlamSettings(mapper="icpslam", local_map_frames=6), truth))
    return out


def run(frames: int) -> dict:
    """Every drive's trajectory (N, 4, 4) float64, true poses (N, 4, 4), map sizes (N,) and CPU seconds per frame
    (N,)."""
    import torch

    from dcslam.slam.config import build_slam

    torch.set_num_threads(1)
    result = {}
    for name, depth, K, settings, truth in _drives(frames):
        slam = build_slam(settings)
        cpu, sizes = [], []
        for i in range(depth.shape[0]):
            t0 = time.process_time()
            slam.step(depth[i:i + 1], K)
            cpu.append(time.process_time() - t0)
            sizes.append(len(slam.mapper.map))
        result[f"{name}/poses"] = slam.trajectory().detach().double().numpy()
        result[f"{name}/truth"] = truth.numpy()
        result[f"{name}/map_points"] = np.array(sizes)
        result[f"{name}/cpu_s"] = np.array(cpu)
    return result


def _names(result: dict) -> list[str]:
    return sorted({key.split("/")[0] for key in result})


def ate(poses: np.ndarray, truth: np.ndarray) -> float:
    """RMSE of the position errors (metres), no alignment: both start at the same pose."""
    return float(np.sqrt((np.linalg.norm(poses[:, :3, 3] - truth[:, :3, 3], axis=1) ** 2).mean()))


def compare(base: dict, new: dict, tolerance: float) -> bool:
    """Prints each drive's differences; True when every trajectory is within ``tolerance`` metres of the base."""
    ok = True
    for name in _names(base):
        A, B = base[f"{name}/poses"], new[f"{name}/poses"]
        dt = float(np.abs(A[:, :3, 3] - B[:, :3, 3]).max())
        dr = float(np.abs(A[:, :3, :3] - B[:, :3, :3]).max())
        sizes = np.flatnonzero(base[f"{name}/map_points"] != new[f"{name}/map_points"])
        cb, cn = base[f"{name}/cpu_s"][1:], new[f"{name}/cpu_s"][1:]       # the first frame has no odometry
        print(f"{name:<22} max |dt| {dt:.2e} m  max |dR| {dr:.2e}  map sizes differ at {sizes.size} frames  "
              f"CPU/frame {np.median(cb) * 1e3:7.1f} -> {np.median(cn) * 1e3:7.1f} ms "
              f"(x{np.median(cb) / np.median(cn):.2f}"
              f"; last 5 frames {np.median(cb[-5:]) * 1e3:.1f} -> {np.median(cn[-5:]) * 1e3:.1f} ms)"
              f"  ATE {ate(A, new[f'{name}/truth']):.4f} -> {ate(B, new[f'{name}/truth']):.4f} m")
        ok &= dt <= tolerance
    return ok


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--save", type=Path, help="write the results to this .npz")
    parser.add_argument("--compare", type=Path, help="compare with the results in this .npz")
    parser.add_argument("--frames", type=int, default=FRAMES)
    parser.add_argument("--tolerance", type=float, default=1e-6, help="metres")
    args = parser.parse_args()
    result = run(args.frames)
    for name in _names(result):
        cpu = result[f"{name}/cpu_s"][1:]
        print(f"{name:<22} {len(cpu) + 1} frames, final map {result[f'{name}/map_points'][-1]} points, "
              f"CPU/frame median {np.median(cpu) * 1e3:.1f} ms (first 5 {np.median(cpu[:5]) * 1e3:.1f}, "
              f"last 5 {np.median(cpu[-5:]) * 1e3:.1f}; all frames {result[f'{name}/cpu_s'].sum():.2f} s)")
    if args.save:
        np.savez(args.save, **result)
    if args.compare:
        return 0 if compare(dict(np.load(args.compare)), result, args.tolerance) else 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
