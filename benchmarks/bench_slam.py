"""SLAM speed, side by side (``make bench``):

1. Point-to-plane ICP at full KITTI size (1242 x 375, dense depth), ours (projective association, Gauss-Newton)
   against Open3D's legacy ``registration_icp`` (KD-tree association) on the same frame pair, the same normals,
   the same gate and the same iteration count; prints both times, the ratio and how far the two poses are apart.
2. PointFusion with ICP odometry at full KITTI size: seconds per frame with LiDAR-like sparse and with dense depth,
   and the map size and process memory along a longer drive (they must level off, not grow without bound).

Frames come from the analytic street scene (``dcslam.slam.scene``), so no dataset is needed. Figures depend on the
machine and on its load: read them next to the machine line that ``benchmarks/run_all.py`` prints.
On a shared machine run with ``OMP_NUM_THREADS=1`` (applies to torch and Open3D alike): with two threads on busy
cores torch's small-tensor kernels thrash and every figure becomes several times slower.
Usage: ``python benchmarks/bench_slam.py [--device cuda] [--frames 10] [--memory-frames 100]``.
"""
from __future__ import annotations

import argparse
import resource
import time

import numpy as np
import torch

from dcslam.geometry.se3 import pose_error
from dcslam.slam.association import view_from_frame
from dcslam.slam.frame import prepare_frame
from dcslam.slam.fusion import PointFusion
from dcslam.slam.odometry import ICPOdometry
from dcslam.slam.pipeline import SLAM
from dcslam.slam.scene import StreetScene, kitti_K, lidar_mask, street_trajectory
from dcslam.slam.solvers import GaussNewton

H, W = 375, 1242


def _sync(device: str) -> None:
    if device.startswith("cuda"):
        torch.cuda.synchronize()


def bench_icp(scene: StreetScene, K: torch.Tensor, device: str, iterations: int) -> None:
    import open3d as o3d

    T = street_trajectory(2, step=0.3)
    frames = [prepare_frame(scene.render(T[i], K, H, W).float().to(device), K.to(device)) for i in range(2)]
    target = view_from_frame(frames[0], T[0].float().to(device))
    odometry = ICPOdometry(solver=GaussNewton(tolerance=0.0), iterations=iterations, coarse_to_fine=(1.0,),
                           max_normal_angle_deg=180)
    odometry.estimate(frames[1], target, T[0].float().to(device))           # warm-up
    _sync(device)
    start = time.perf_counter()
    ours = odometry.estimate(frames[1], target, T[0].float().to(device))
    _sync(device)
    t_ours = time.perf_counter() - start

    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(frames[1].vertex[frames[1].valid].double().cpu().numpy()))
    tgt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(target.vertex[target.valid].double().cpu().numpy()))
    tgt.normals = o3d.utility.Vector3dVector(target.normal[target.valid].double().cpu().numpy())
    reg = o3d.pipelines.registration
    start = time.perf_counter()
    result = reg.registration_icp(src, tgt, 0.5, T[0].numpy(), reg.TransformationEstimationPointToPlane(),
                                  reg.ICPConvergenceCriteria(0.0, 0.0, iterations))
    t_o3d = time.perf_counter() - start
    dt, dr = pose_error(ours.T_world_cam.double().cpu(), torch.from_numpy(np.array(result.transformation)))
    et, er = pose_error(ours.T_world_cam.double().cpu(), T[1])
    print(f"ICP point-to-plane, {W} x {H} dense ({len(src.points)} source points), {iterations} iterations, "
          f"device {device}")
    print(f"  ours (projective, Gauss-Newton): {t_ours:7.3f} s   error vs truth {float(et) * 100:.2f} cm")
    print(f"  Open3D registration_icp        : {t_o3d:7.3f} s")
    print(f"  ratio Open3D / ours            : {t_o3d / t_ours:7.1f} x   (poses differ by {float(dt) * 100:.2f} cm, "
          f"{np.degrees(float(dr)):.3f} deg)")


def bench_fusion(scene: StreetScene, K: torch.Tensor, device: str, frames: int, memory_frames: int) -> None:
    mask = lidar_mask(H, W, row_step=4, col_step=4)
    for kind in ("sparse", "dense"):
        n = memory_frames if kind == "sparse" else frames
        T = street_trajectory(n, step=1.0)
        slam = SLAM(ICPOdometry(), PointFusion())
        times, samples = [], []
        for i in range(n):
            depth = scene.render(T[i], K, H, W).float()
            if kind == "sparse":
                depth = depth * mask
            depth = depth.to(device)[None, None]
            _sync(device)
            start = time.perf_counter()
            slam.step(depth, K.to(device))
            _sync(device)
            times.append(time.perf_counter() - start)
            if (i + 1) % max(1, n // 5) == 0 or i == n - 1:
                rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
                samples.append((i + 1, len(slam.map), slam.map.nbytes() / 2 ** 20, rss))
        dt, _ = pose_error(slam.trajectory().double().cpu(), T)
        valid = float((depth > 0).float().mean()) * 100
        print(f"PointFusion + ICP odometry, {W} x {H} {kind} depth ({valid:.1f} % pixels), {n} frames, {device}: "
              f"{np.mean(times[1:]):.3f} s per frame (median {np.median(times[1:]):.3f}), "
              f"final drift {float(dt[-1]):.3f} m over {n - 1} m, rejected {len(slam.rejected)}")
        print("  frame   map points   map MB   peak RSS MB")
        for frame, points, mb, rss in samples:
            print(f"  {frame:5d}   {points:10d}   {mb:6.1f}   {rss:11.0f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    parser.add_argument("--frames", type=int, default=10, help="frames timed with dense depth")
    parser.add_argument("--memory-frames", type=int, default=100, help="frames of the sparse drive (memory curve)")
    parser.add_argument("--iterations", type=int, default=20, help="ICP iterations for both ICPs")
    args = parser.parse_args()
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, device {args.device}")
    scene, K = StreetScene(0, length=max(args.memory_frames, args.frames) + 40.0), kitti_K(H, W)
    bench_icp(scene, K, args.device, args.iterations)
    bench_fusion(scene, K, args.device, args.frames, args.memory_frames)


if __name__ == "__main__":
    main()
