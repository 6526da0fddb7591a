"""Depth-completion speed, side by side (run: ``python benchmarks/bench_depth.py [--quick] [--device cuda]``).

1. IP-Basic (fast, multiscale) frames per second at 1242 x 375 on the real KITTI frame (the paper: 90 Hz, one core).
2. SparseConvNet forward and forward+backward seconds per full-size frame, and the share of the peak FLOP rate
   measured in the same run with a large matmul.
3. Chamfer forward+backward (dcslam.depth.chamfer) for 1e5 and 1e6 points per cloud against SciPy cKDTree
   (default build) querying both directions on the same clouds, in the same run. The clouds are two depth images
   back-projected (a slightly perturbed copy), as the maps of the chamfer loss are.
"""
from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np
import torch

SAMPLE = Path("/work/shared/kitti-sample/depth_completion/train/2011_09_26_drive_0001_sync/proj_depth")
LOCAL = Path(__file__).parents[1] / "tests" / "data" / "kitti-sample" / "depth_completion" / "train" / \
    "2011_09_26_drive_0001_sync" / "proj_depth"


def timed(fn, repeat: int, sync=lambda: None) -> float:
    fn()
    sync()
    start = time.perf_counter()
    for _ in range(repeat):
        fn()
    sync()
    return (time.perf_counter() - start) / repeat


def kitti_sparse() -> tuple[np.ndarray, np.ndarray]:
    from dcslam.io.kitti import read_depth_png

    root = SAMPLE if SAMPLE.exists() else LOCAL
    return (read_depth_png(root / "velodyne_raw/image_02/0000000005.png"),
            read_depth_png(root / "groundtruth/image_02/0000000005.png"))


def bench_ip_basic(sparse, gt, repeat):
    from dcslam.depth.models.ip_basic import IPBasic

    print("\nIP-Basic on the KITTI frame (1242 x 375)")
    print(f"{'variant':<24}{'Hz':>8}{'ms/frame':>10}{'MAE mm':>9}{'RMSE mm':>9}"
          "   paper: 90 Hz (1 core), 302.6 / 1288.5 mm")
    valid = gt > 0
    for variant, blur in (("fast", "bilateral"), ("fast", "gaussian"), ("multiscale", "gaussian")):
        f = IPBasic(variant, blur=blur)
        dt = timed(lambda: f(sparse), repeat)
        err = f(sparse)[valid] - gt[valid]
        print(f"{variant + ' / ' + blur:<24}{1 / dt:>8.1f}{dt * 1e3:>10.2f}{np.abs(err).mean() * 1e3:>9.1f}"
              f"{np.sqrt((err ** 2).mean()) * 1e3:>9.1f}")


def sparse_conv_flops(net, h, w) -> float:
    """Multiply-adds x 2 of the forward pass: per layer two convolutions (x*m with W, m with ones) + pooling."""
    total = 0
    for layer in net.layers:
        k2 = layer.kernel_size ** 2
        total += 2 * h * w * layer.in_channels * layer.out_channels * k2 + 2 * h * w * k2
    return float(total)


def bench_sparse_conv(sparse, device, repeat):
    from dcslam.depth.models.sparse_conv import SparseConvNet

    sync = torch.cuda.synchronize if device.type == "cuda" else (lambda: None)
    n = 4096 if device.type == "cpu" else 8192
    a = torch.randn(n, n, device=device)
    b = torch.randn(n, n, device=device)
    dt = timed(lambda: a @ b, 3, sync)
    peak = 2 * n ** 3 / dt
    net = SparseConvNet().to(device)
    x = torch.from_numpy(sparse)[None, None].to(device)
    m = (x > 0).float()
    fwd = timed(lambda: net(x, m), repeat, sync)

    def fwd_bwd():
        net.zero_grad()
        net(x, m).mean().backward()

    fb = timed(fwd_bwd, repeat, sync)
    flops = sparse_conv_flops(net, *sparse.shape)
    print(f"\nSparseConvNet, one 1242 x 375 frame on {device} ({torch.get_num_threads()} threads)")
    print(f"peak (fp32 {n}x{n} matmul): {peak / 1e9:.1f} GFLOP/s; forward {flops / 1e9:.1f} GFLOP, "
          f"forward+backward ~{3 * flops / 1e9:.1f} GFLOP")
    print(f"{'pass':<20}{'s/frame':>10}{'GFLOP/s':>10}{'% of peak':>11}")
    for name, t, f in (("forward", fwd, flops), ("forward+backward", fb, 3 * flops)):
        print(f"{name:<20}{t:>10.3f}{f / t / 1e9:>10.1f}{100 * f / t / peak:>10.1f}%")


def depth_cloud(n_points: int, seed: int) -> np.ndarray:
    """Back-projected depth image (a street-like ramp with boxes) of about n_points pixels, image order."""
    rng = np.random.default_rng(seed)
    w = int(np.sqrt(n_points * 3.3))
    h = n_points // w
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    f = 0.8 * w
    depth = 5 + 60 * (1 - v / h) ** 2 + 3 * np.sin(u / 37.0)
    depth[h // 3: h // 2, w // 5: w // 3] = 12.0
    depth += rng.normal(0, 0.02, depth.shape)
    z = depth.ravel()
    return np.stack([(u.ravel() - w / 2) / f * z, (v.ravel() - h / 2) / f * z, z], 1)


def bench_chamfer(sizes, device, repeat):
    from scipy.spatial import cKDTree

    from dcslam.depth.chamfer import chamfer_distance

    print(f"\nChamfer distance forward+backward vs SciPy cKDTree (default build) querying both directions "
          f"({os.cpu_count()} cores)")
    print(f"{'points/cloud':>13}{'cKDTree s':>11}{'ours f+b s':>12}{'ratio':>8}   (ratio < 1: ours faster)")
    for n in sizes:
        a_np = depth_cloud(n, 0)
        b_np = a_np + np.random.default_rng(1).normal(0, 0.05, a_np.shape)

        def reference():
            cKDTree(b_np).query(a_np, workers=-1)
            cKDTree(a_np).query(b_np, workers=-1)

        a = torch.tensor(a_np, dtype=torch.float32, device=device, requires_grad=True)
        b = torch.tensor(b_np, dtype=torch.float32, device=device)

        def ours():
            a.grad = None
            chamfer_distance(a, b).backward()

        sync = torch.cuda.synchronize if device.type == "cuda" else (lambda: None)
        t_ref = timed(reference, repeat)
        t_ours = timed(ours, repeat, sync)
        print(f"{len(a_np):>13,}{t_ref:>11.3f}{t_ours:>12.3f}{t_ours / t_ref:>8.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats, no 1e6-point chamfer")
    parser.add_argument("--device", default="auto")
    args, _ = parser.parse_known_args()   # make bench hands every script the same options
    device = torch.device("cuda" if args.device == "auto" and torch.cuda.is_available() else
                          ("cpu" if args.device == "auto" else args.device))
    repeat = 2 if args.quick else 5
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, torch {torch.__version__}, "
          f"device {device}")
    sparse, gt = kitti_sparse()
    bench_ip_basic(sparse, gt, 10 if args.quick else 50)
    bench_sparse_conv(sparse, device, repeat)
    bench_chamfer([100_000] if args.quick else [100_000, 1_000_000], device, 1 if args.quick else 3)


if __name__ == "__main__":
    main()
