"""SLAM accuracy and speed beside the references, and memory on a long drive (``make bench``).

1. On the same generated drives (prepared drive files; ``--drives``, default ``$DCSLAM_WORKSPACE/drives``, else two
   short drives generated into a temporary folder): dcslam with its default settings on sparse and on dense depth
   at full KITTI size, Open3D's point-to-plane ICP on the same depth, and KISS-ICP on the 360 degree Velodyne scans
   (skipped, with a line saying so, when ``kiss-icp`` is not installed: ``pip install -e .[bench]``). For each:
   ATE, RPE, final drift %, frames/s, and dcslam's flagged steps.
2. Peak memory (process RSS, each run in a fresh process) and local-map size at frames 200, 400, ..., 1,000 of a
   long analytic street drive (``dcslam.slam.scene``) with LiDAR-like sparse depth at full size, with the default
   settings (the points leaving the 50-frame local map archived in a temporary file for the map file) and with the
   archive off; they must be flat within 10 %. ``--long-dense`` adds a dense run at ``--dense-scale`` of the size
   (every pixel is ray-cast: about 2 s a frame at full size).

Figures depend on the machine and its load: read them next to the machine line that ``benchmarks/run_all.py``
prints. Run with ``OMP_NUM_THREADS=1`` on a shared machine (the script sets torch to one thread unless
``--threads`` says otherwise). Usage: ``python benchmarks/bench_slam.py [--drives DIR] [--frames 60]
[--long-frames 1000] [--device cuda]``.
"""
from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

from slam_drives import DriveScore, run_dcslam  # noqa: E402
from slam_references import kiss_icp_available, run_kiss_icp, run_open3d  # noqa: E402

from dcslam.allocator import SLAM_MMAP_THRESHOLD, heap_mb, trim  # noqa: E402


def _drives(args) -> tuple[list[Path], Path]:
    """Drive files and the KITTI root they came from (generated when none are given or found)."""
    folder = args.drives
    if folder is None:
        workspace = Path(os.environ.get("DCSLAM_WORKSPACE", "workspace"))
        if (workspace / "drives").is_dir() and list((workspace / "drives").glob("*.h5")):
            folder = workspace / "drives"
    if folder is None:
        tmp = Path(tempfile.mkdtemp(prefix="dcslam-bench-"))
        print(f"no drives given: generating 2 drives x {args.frames + 10} frames (seed 2027) in {tmp}", flush=True)
        env = dict(os.environ, DCSLAM_PROGRESS="0")
        for cmd in (["synth", "--drives", "2", "--frames", str(args.frames + 10), "--seed", "2027"],
                    ["prepare-kitti", "--all-drives"]):
            subprocess.run([sys.executable, "-m", "dcslam", *cmd, "-w", str(tmp)], check=True, env=env,
                           stdout=subprocess.DEVNULL)
        folder = tmp / "drives"
    paths = sorted(folder.glob("*.h5"))[:args.max_drives or None]
    return paths, folder.parent / "kitti"


def _line(label: str, rows: list[DriveScore], flags: bool = True) -> str:
    ate = np.array([r.ate_m for r in rows])
    text = (f"  {label:<28} ATE {ate.mean():6.3f} m (max {ate.max():6.3f})  RPE {np.mean([r.rpe_m for r in rows]):.3f}"
            f" m  drift {np.mean([r.drift_pct for r in rows]):6.2f} %  {np.median([r.fps for r in rows]):6.2f} "
            f"frames/s wall, {np.median([r.cpu_fps for r in rows]):6.2f} per CPU-second")
    if flags:
        text += (f"  flagged steps {sum(r.degraded + r.rejected for r in rows)}, suspect drives "
                 f"{sum(r.suspect for r in rows)}/{len(rows)}")
    return text


def side_by_side(args) -> None:
    from dcslam.slam.config import SlamSettings

    paths, kitti_root = _drives(args)
    print(f"accuracy and speed: {len(paths)} drives x {args.frames} frames, full size, dcslam defaults "
          f"{SlamSettings().to_dict()}", flush=True)
    for depth in ("sparse", "dense"):
        print(_line(f"dcslam {depth}", [run_dcslam(p, depth, SlamSettings(), args.frames, device=args.device)
                                        for p in paths]), flush=True)
        print(_line(f"Open3D point-to-plane {depth}", [run_open3d(p, depth, args.frames) for p in paths],
                    flags=False), flush=True)
    if not kiss_icp_available():
        print("  KISS-ICP: skipped (not installed; pip install kiss-icp, or the dcslam[bench] extra)")
    elif not (kitti_root / "raw").is_dir():
        print(f"  KISS-ICP: skipped ({kitti_root / 'raw'} holds no Velodyne scans)")
    else:
        print(_line("KISS-ICP velodyne 360", [run_kiss_icp(kitti_root, p, args.frames) for p in paths],
                    flags=False), flush=True)


def _rss_mb() -> float:
    """Resident memory of this process now (Linux /proc)."""
    try:
        return int(open("/proc/self/statm").read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2 ** 20
    except OSError:
        return float("nan")


def memory(args) -> None:
    """Each memory run in a fresh child process, so that its peak is the SLAM's own and not the accuracy runs'."""
    runs = [("sparse", True), ("sparse", False)] + ([("dense", False)] if args.long_dense else [])
    for kind, keep in runs:
        cmd = [sys.executable, __file__, "--memory-child", kind, "--long-frames", str(args.long_frames),
               "--threads", str(args.threads), "--device", args.device, "--dense-scale", str(args.dense_scale),
               "--malloc-trim-every", str(args.malloc_trim_every), "--mmap-threshold-mb", str(args.mmap_threshold_mb)
               ] + (["--probe-trim"] if args.probe_trim else [])
        if subprocess.call(cmd + (["--keep-global-map"] if keep else [])) != 0:
            raise SystemExit(f"memory run ({kind}, keep_global_map={keep}) failed")


def memory_child(args) -> None:
    """One long drive in this process: RSS now and the peak so far (ru_maxrss) at frames 200, 400, ... ."""
    from dcslam.allocator import fix_mmap_threshold
    from dcslam.slam.config import SlamSettings, build_slam
    from dcslam.slam.scene import StreetScene, kitti_K, lidar_mask, street_trajectory

    kind, n = args.memory_child, args.long_frames
    fixed = fix_mmap_threshold(round(args.mmap_threshold_mb * 2 ** 20))   # as `dcslam slam` does
    H, W = 375, 1242
    if kind == "dense":                                    # every pixel ray-cast: reduced size to stay affordable
        H, W = round(H * args.dense_scale), round(W * args.dense_scale)
    scene, K = StreetScene(0, length=n + 60.0), kitti_K(H, W)
    T = street_trajectory(n, step=1.0)
    mask = lidar_mask(H, W, row_step=4, col_step=4) if kind == "sparse" else None
    settings = SlamSettings(keep_global_map=args.keep_global_map)
    slam = build_slam(settings)
    marks = sorted({min(200, n), n} | set(range(200, n, 200)))
    print(f"memory: analytic street drive (dcslam.slam.scene), {n} frames of 1 m, {W} x {H} {kind} depth"
          + (" (LiDAR-like: every 4th row and column)" if kind == "sparse" else "")
          + f", dcslam defaults but keep_global_map={settings.keep_global_map} (local map "
          f"{settings.local_map_frames} frames), {args.threads} thread(s), fresh process", flush=True)
    print(f"  glibc mmap threshold: {f'fixed at {args.mmap_threshold_mb:g} MB' if fixed else 'not fixed by dcslam'}"
          + (f" (MALLOC_MMAP_THRESHOLD_={os.environ['MALLOC_MMAP_THRESHOLD_']})"
             if 'MALLOC_MMAP_THRESHOLD_' in os.environ else ""), flush=True)
    if args.malloc_trim_every:
        print(f"  malloc_trim(0) after every {args.malloc_trim_every} frames", flush=True)
    print("  frame   local map points   map MB   archived points   archive file MB   RSS MB   peak RSS MB   "
          "malloc arena MB (in use)   mmapped MB   RSS after malloc_trim MB   s/frame (SLAM, last 50)", flush=True)
    times, peaks = [], {}
    for i in range(n):
        depth = scene.render(T[i], K, H, W, mask=mask).float().to(args.device)[None, None]
        start = time.perf_counter()
        slam.step(depth, K.to(args.device))
        times.append(time.perf_counter() - start)
        if args.malloc_trim_every and (i + 1) % args.malloc_trim_every == 0:
            trim()
        if i + 1 in marks:
            archived, archive_mb = len(slam.mapper.archived), slam.mapper.archived.nbytes / 2 ** 20
            peaks[i + 1] = peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
            rss, heap = _rss_mb(), heap_mb()
            arena = f"{heap[0]:8.0f} ({heap[1]:5.0f})   {heap[2]:10.0f}" if heap else f"{'n/a':>15}   {'n/a':>10}"
            trimmed = f"{_rss_mb():24.0f}" if args.probe_trim and trim() else f"{'-':>24}"
            print(f"  {i + 1:5d}   {len(slam.map):16d}   {slam.map.nbytes() / 2 ** 20:6.1f}   {archived:15d}   "
                  f"{archive_mb:15.1f}   {rss:6.0f}   {peak:11.0f}   {arena}   {trimmed}   "
                  f"{np.mean(times[-50:]):.3f}", flush=True)
    first, last = peaks[marks[0]], peaks[marks[-1]]
    print(f"  peak RSS frame {marks[0]} -> {marks[-1]}: {first:.0f} -> {last:.0f} MB "
          f"({100 * (last / first - 1):+.1f} %, {'' if last <= 1.1 * first else 'NOT '}flat within 10 %)", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--drives", type=Path, help="folder of prepared drive files")
    parser.add_argument("--frames", type=int, default=60, help="frames per drive")
    parser.add_argument("--max-drives", type=int, default=4)
    parser.add_argument("--long-frames", type=int, default=1000, help="frames of the memory drive")
    parser.add_argument("--keep-global-map", action="store_true",
                        help="memory run keeps the archive for the map file (grows with the street seen)")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--long-dense", action="store_true", help="also a dense memory run (slow: every pixel cast)")
    parser.add_argument("--dense-scale", type=float, default=1 / 3, help="image scale of the dense memory run")
    parser.add_argument("--malloc-trim-every", type=int, default=0,
                        help="memory run: call glibc's malloc_trim(0) after every N frames (0 = never)")
    parser.add_argument("--mmap-threshold-mb", type=float, default=SLAM_MMAP_THRESHOLD / 2 ** 20,
                        help="memory run: glibc mmap threshold fixed as `dcslam slam` fixes it (0 = glibc's own)")
    parser.add_argument("--probe-trim", action="store_true",
                        help="memory run: at each mark, also the RSS after malloc_trim(0) (how much malloc held free)")
    parser.add_argument("--memory-child", choices=("sparse", "dense"), help=argparse.SUPPRESS)
    parser.add_argument("--skip", choices=("accuracy", "memory"), action="append", default=[])
    args, _ = parser.parse_known_args()
    import torch

    torch.set_num_threads(args.threads)
    if args.memory_child:
        return memory_child(args)
    if "accuracy" not in args.skip:
        side_by_side(args)
    if "memory" not in args.skip:
        memory(args)


if __name__ == "__main__":
    main()
