"""Is a SLAM run's memory flat in the drive's length, and its CPU per frame? ``dcslam slam`` over the first 15, 30,
60 and 200 frames of one generated drive, each run a fresh child process: its peak resident memory (``VmHWM``, the
whole command: imports, the run, the map and trajectory files it writes) and, from its process CPU time taken at the
start of every SLAM step (the prefetch thread's reading and preparing included), the CPU per frame of the first
and of the last quarter of its frames, beside their ICP iterations and map points per frame (the work a frame's
content asks for: a stretch of street that needs more iterations costs more without the map growing).

The drive: the analytic street of ``dcslam.slam.scene`` (``StreetScene(seed 0)``, ``street_trajectory``: 1 m per
frame with a gentle weave) at full KITTI size, 1242 x 375, with LiDAR-like sparse depth (every 4th row and column
ray-cast, about 29,000 pixels a frame) written as a drive file (its ``dense`` holds the same sparse depth, its
images are grey): ray casting only the LiDAR's pixels keeps 200 frames to seconds of generation, where ``dcslam
synth`` takes about a CPU-second a frame. ``dcslam slam --depth sparse`` runs with its defaults (a 50-frame local
map, the points leaving it archived for the map file).

Usage: ``python benchmarks/bench_memory.py [--frames 15 30 60 200] [--workdir DIR]``. Exit status 1 when the
longest run's peak RSS exceeds the shortest's by more than 10 %.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HEIGHT, WIDTH = 375, 1242


def write_street_drive(path: Path, frames: int) -> Path:
    """The analytic street's first ``frames`` frames as a drive file (sparse depth, see the module's docstring)."""
    import numpy as np

    from dcslam.io.drive import DriveFrame, DriveWriter
    from dcslam.slam.scene import StreetScene, kitti_K, lidar_mask, street_trajectory

    scene, K = StreetScene(0, length=frames + 60.0), kitti_K(HEIGHT, WIDTH)
    T = street_trajectory(frames, step=1.0)
    mask = lidar_mask(HEIGHT, WIDTH, row_step=4, col_step=4)
    grey = np.full((HEIGHT, WIDTH, 3), 128, np.uint8)
    with DriveWriter(path, K.double().numpy(), HEIGHT, WIDTH, source="synthetic", date="2011_09_26",
                     drive=path.stem, split="test", force=True) as writer:
        for i in range(frames):
            sparse = scene.render(T[i], K, HEIGHT, WIDTH, mask=mask).float().numpy()
            writer.append(DriveFrame(grey, sparse, sparse, T[i].numpy(), 0.1 * i, i))
    return path


def _peak_rss_mb() -> float:
    """This process's peak resident memory, MB (``VmHWM``: its own, not the parent's it was forked from)."""
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    raise SystemExit("no VmHWM in /proc/self/status (Linux only)")


def child(drive: Path, frames: int, out: Path, extra: list[str]) -> dict:
    """``dcslam slam`` in this process over ``frames`` frames -> peak RSS and the CPU seconds of every step but the
    last (the time from one step's start to the next's)."""
    import dcslam.cli
    from dcslam.slam import pipeline

    starts, iterations, points = [], [], []
    step_frame = pipeline.SLAM.step_frame

    def timed(self, *args, **kwargs):
        starts.append(time.process_time())
        report = step_frame(self, *args, **kwargs)
        iterations.append(report.iterations)
        points.append(report.points)
        return report

    pipeline.SLAM.step_frame = timed
    sys.argv = ["dcslam", "slam", "--drive", str(drive), "--depth", "sparse", "--frames", str(frames),
                "--out", str(out), "--workspace", str(out.parent), "--force", *extra]
    cpu = time.process_time()
    try:
        dcslam.cli.main()
    except SystemExit as done:
        if done.code:
            raise
    return {"frames": frames, "peak_rss_mb": _peak_rss_mb(), "cpu_s": time.process_time() - cpu,
            "step_cpu_s": [b - a for a, b in zip(starts, starts[1:])], "iterations": iterations[:-1],
            "points": points[:-1]}


def main() -> int:
    from dcslam.allocator import tuned_environment

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=int, nargs="+", default=[15, 30, 60, 200])
    parser.add_argument("--workdir", type=Path, help="where the drive and outputs go (default: a temporary folder)")
    parser.add_argument("--slam-args", default="", help="more options of dcslam slam, e.g. '--no-keep-global-map'")
    parser.add_argument("--child", type=int, help=argparse.SUPPRESS)
    args, _ = parser.parse_known_args()
    work = args.workdir or Path(tempfile.mkdtemp(prefix="dcslam-memory-"))
    longest = max(args.frames)
    drive = work / "drives" / f"street{longest}" / "2011_09_26_drive_0900_sync.h5"   # one drive per length asked
    if args.child:
        print(json.dumps(child(drive, args.child, work / "slam" / str(args.child), args.slam_args.split())))
        return 0
    if not drive.exists():
        drive.parent.mkdir(parents=True, exist_ok=True)
        cpu = time.process_time()
        write_street_drive(drive, longest)
        print(f"wrote {drive} ({longest} frames, {time.process_time() - cpu:.1f} CPU-s)", flush=True)
    env = dict(os.environ, DCSLAM_PROGRESS="0", OMP_NUM_THREADS="1")
    env = tuned_environment(env) or env   # glibc's tunables, as the dcslam command starts itself (dcslam.launch)
    load = os.getloadavg()[0]
    print(f"dcslam slam --depth sparse over the analytic street at {WIDTH} x {HEIGHT} (LiDAR-like: every 4th row "
          f"and column), defaults{' but ' + args.slam_args if args.slam_args else ''}, each run a fresh process; "
          f"load average {load:.1f} before ({os.cpu_count()} cores)")
    print("| frames | peak RSS MB | CPU-s (whole command) | CPU per frame, first quarter ms | last quarter ms "
          "| ICP iterations per frame, first / last quarter | map points, first / last quarter |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    peaks = {}
    for n in sorted(args.frames):
        done = subprocess.run([sys.executable, __file__, "--workdir", str(work), "--frames", str(longest),
                               f"--slam-args={args.slam_args}", "--child", str(n)], env=env,
                              stdout=subprocess.PIPE, text=True)
        if done.returncode != 0:
            raise SystemExit(f"dcslam slam over {n} frames failed (exit {done.returncode})")
        run = json.loads(done.stdout.strip().splitlines()[-1])
        steps = run["step_cpu_s"][1:]                 # the first frame has no odometry
        quarter = max(1, len(steps) // 4)
        peaks[n] = run["peak_rss_mb"]

        def quarters(values: list, scale: float = 1.0, digits: int = 0) -> tuple[str, str]:
            values = values[1:]
            return (f"{scale * sum(values[:quarter]) / quarter:.{digits}f}",
                    f"{scale * sum(values[-quarter:]) / quarter:.{digits}f}")

        print(f"| {n} | {run['peak_rss_mb']:.0f} | {run['cpu_s']:.1f} | {' | '.join(quarters(steps, 1e3))} | "
              f"{' / '.join(quarters(run['iterations'], digits=1))} | {' / '.join(quarters(run['points']))} |",
              flush=True)
    first, last = peaks[min(peaks)], peaks[max(peaks)]
    flat = last <= 1.1 * first
    print(f"\npeak RSS {min(peaks)} -> {max(peaks)} frames: {first:.0f} -> {last:.0f} MB "
          f"({100 * (last / first - 1):+.1f} %, {'' if flat else 'NOT '}flat within 10 %); load average "
          f"{os.getloadavg()[0]:.1f} after")
    return 0 if flat else 1


if __name__ == "__main__":
    sys.exit(main())
