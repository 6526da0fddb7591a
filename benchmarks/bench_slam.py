"""dcslam beside KISS-ICP and Open3D in one table (``make bench``): frames per CPU-second, ATE, drift and peak
memory of every SLAM run, on the same generated drives, in one run.

Rows: dcslam with its default settings (``dcslam.run_slam``: the frames streamed from the drive file with the
prefetch thread, glibc's mmap and trim thresholds fixed, as ``dcslam slam`` runs them) on the LiDAR's sparse 64-beam
depth, on the annotated dense depth and on two completions of the sparse depth (IP-Basic fast and planefit, written
by ``dcslam.complete_drive`` before the runs); the same on one thread (``dcslam, one thread``: no prefetch thread,
as the workers of ``dcslam reproduce --jobs N`` run when they fill the cores, and as KISS-ICP's and Open3D's rows
run); Open3D's point-to-plane ICP frame to frame on the same depths; KISS-ICP 1.3.0 on the 360 degree Velodyne scans
(the ``bench`` extra; a line says so when it is missing) on one thread, and as its users run it (``KISS-ICP, its
threads``: its registration on every core, its default), the peer of dcslam's default row. ``--open3d-completed``
chooses which completions Open3D also runs on (default IP-Basic only), and ``--open3d-completed-drives`` over how
many drives (default the first: Open3D takes 3-5 CPU-seconds a frame there).

Each run is a child process of its own with one torch / OpenMP thread (KISS-ICP's registration on one thread too,
but in its own-threads row), so that its peak memory (``VmHWM``, the imports included) is its own; the runs go drive
by drive, dcslam and its peers interleaved, ``--jobs`` at a time (default 2), so that a change of the machine's load
touches every row alike. A run's CPU time is its process time from opening its input to its trajectory: reading and
decoding the frames are counted for every row. Over the drives: frames per CPU-second = all frames / all CPU-seconds
(and each drive's), wall seconds of each drive (the repeat counted: what a second thread buys), ATE (RMSE of the
position errors, no alignment: every run starts at the true first pose) and drift (final position error / distance
travelled) of each drive, peak RSS the largest. ``--json`` writes every run's figures.

Drives: ``--drives DIR`` (prepared drive files, the KITTI root beside them for the Velodyne scans), else
``$DCSLAM_WORKSPACE/drives``, else 2 drives of ``--frames`` frames generated into a temporary folder (seed 2027).
Read the CPU figures as ratios when other processes share the cores; the script prints the load average before and
after. ``--repeat N`` runs every row N times, round by round, and counts each run's fastest repeat (:func:`fastest`).
``--long-memory`` adds the long analytic-street memory runs (:func:`memory`). Usage:
``python benchmarks/bench_slam.py [--drives DIR] [--frames 30] [--max-drives 2] [--repeat 3]``.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

from slam_drives import score  # noqa: E402
from slam_references import kiss_icp_available, run_kiss_icp, run_open3d  # noqa: E402

from dcslam.allocator import SLAM_ARENAS, SLAM_MMAP_THRESHOLD, heap_mb, trim, tuned_environment  # noqa: E402
from dcslam.workers import SHARED_CORES  # noqa: E402

COMPLETERS = {"ip-basic": "ip-basic-fast", "planefit": "planefit"}   # row name -> registered completer
SPARSE_TARGET, COMPLETED_TARGET = 1.5, 8.0   # x KISS-ICP's frames per CPU-second; frames per CPU-second
ONE_THREAD = "dcslam, one thread"                 # the row without the prefetch thread, and its child's name
KISS_THREADS = "KISS-ICP, its threads"            # KISS-ICP's registration on every core (its default)
CHILD = {ONE_THREAD: "dcslam1", KISS_THREADS: "kissicp0"}
DEPTHS = ("sparse", "dense", *COMPLETERS)
#: Which ratio the 1.5 x target is read on: one compute thread against one, as the target was set; the default
#: row's prefetch thread buys wall time with CPU time, at a cost that varies by host (docs/benchmarks.md)
TARGET_MEASURE = (f"the {SPARSE_TARGET:g} x target is read on '{ONE_THREAD} / KISS-ICP' (one compute thread "
                  "against one, drive by drive where KISS-ICP tracks); the default row's prefetch thread trades CPU "
                  "time for wall time")


def _drives(args) -> tuple[list[Path], Path]:
    """Drive files and the KITTI root they came from (generated when none are given or found)."""
    folder = args.drives
    if folder is None:
        workspace = Path(os.environ.get("DCSLAM_WORKSPACE", "workspace"))
        if (workspace / "drives").is_dir() and list((workspace / "drives").glob("*.h5")):
            folder = workspace / "drives"
    if folder is None:
        tmp = Path(tempfile.mkdtemp(prefix="dcslam-bench-"))
        print(f"no drives given: generating 2 drives x {args.frames + 10} frames (seed 2027; prepare-kitti keeps "
              f"{args.frames}) in {tmp}", flush=True)
        env = dict(os.environ, DCSLAM_PROGRESS="0")
        for cmd in (["synth", "--drives", "2", "--frames", str(args.frames + 10), "--seed", "2027"],
                    ["prepare-kitti", "--all-drives"]):
            subprocess.run([sys.executable, "-m", "dcslam", *cmd, "-w", str(tmp)], check=True, env=env,
                           stdout=subprocess.DEVNULL)
        folder = tmp / "drives"
    paths = sorted(folder.glob("*.h5"))[:args.max_drives or None]
    if not paths:
        raise SystemExit(f"{folder} holds no drive files (*.h5)")
    return paths, folder.parent / "kitti"


def _layers(paths: list[Path]) -> dict[tuple[str, str], Path]:
    """(drive stem, completion row) -> its layer file, completed from the sparse depth once (kept beside the drives,
    under ``bench-layers/``, so that a second run reuses them)."""
    import dcslam

    layers = {}
    for path in paths:
        for row, model in COMPLETERS.items():
            out = path.parent.parent / "bench-layers" / f"{path.stem}.{row}.h5"
            if not out.exists():
                out.parent.mkdir(parents=True, exist_ok=True)
                dcslam.complete_drive(path, out, model)
            layers[path.stem, row] = out
    return layers


def _peak_rss_mb() -> float:
    """This process's peak resident memory (Linux ``VmHWM``: unlike ``ru_maxrss``, not inherited from the parent
    that forked it)."""
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _child(system: str, drive: Path, source: str, frames: int, kitti_root: Path) -> dict:
    """One run in this (fresh) process -> its scores, CPU and wall seconds and peak RSS (MB). A 2-frame run first,
    not timed, loads the libraries the run imports lazily (every row alike)."""
    import torch

    torch.set_num_threads(1)
    depth = Path(source) if source.endswith(".h5") else source
    if system in ("dcslam", "dcslam1"):
        import dcslam
        from dcslam.allocator import fix_allocator

        fix_allocator()        # glibc's thresholds as `dcslam slam` and its workers fix them

        def run(n: int):
            wall, cpu = time.perf_counter(), time.process_time()
            out = dcslam.run_slam(drive, depth, frames=n)
            wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
            return score(drive.stem, source, out.T_gt, out.T_world_cam, wall, cpu_seconds=cpu)
    elif system == "open3d":
        def run(n: int):
            return run_open3d(drive, depth, n)
    else:
        def run(n: int):
            return run_kiss_icp(kitti_root, drive, n, threads=0 if system == CHILD[KISS_THREADS] else 1)
    run(2)
    rss_warm = _peak_rss_mb()
    result = run(frames)
    return {"frames": result.frames, "ate_m": result.ate_m, "drift_pct": result.drift_pct,
            "cpu_s": result.frames / result.cpu_fps, "wall_s": result.frames / result.fps,
            "peak_rss_warm_mb": rss_warm, "peak_rss_mb": _peak_rss_mb()}


def _run_child(args, system: str, drive: Path, source: str, kitti_root: Path) -> dict:
    env = dict(os.environ, DCSLAM_PROGRESS="0", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    if system == "dcslam1":
        env[SHARED_CORES] = "1"                    # no prefetch thread: the frame loop alone
    if system.startswith("dcslam"):
        env = tuned_environment(env) or env         # glibc's tunables, as the dcslam command starts itself
    cmd = [sys.executable, __file__, "--child", system, "--child-drive", str(drive), "--child-source", source,
           "--frames", str(args.frames), "--child-kitti", str(kitti_root)]
    done = subprocess.run(cmd, env=env, stdout=subprocess.PIPE, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{system} on {source} of {drive.name} failed (exit {done.returncode})")
    return json.loads(done.stdout.strip().splitlines()[-1])


def _tasks(args, paths: list[Path], layers: dict, kiss: bool) -> list[tuple[str, str, Path, str]]:
    """(system, depth row, drive, source) of every run, drive by drive: dcslam and its peers interleaved in time.
    Open3D runs on the completions over the first ``--open3d-completed-drives`` drives only (3-5 CPU-s a frame)."""
    tasks = []
    for k, drive in enumerate(paths):
        peers = ("sparse", "dense", *(args.open3d_completed if k < args.open3d_completed_drives else ()))
        rows = [(system, d) for system in ("dcslam", ONE_THREAD) for d in DEPTHS] + [("Open3D", d) for d in peers]
        rows += [("KISS-ICP", "velodyne 360"), (KISS_THREADS, "velodyne 360")] if kiss else []
        tasks += [(system, depth, drive, str(layers[drive.stem, depth]) if depth in COMPLETERS else depth)
                  for system, depth in rows]
    return tasks


def fastest(repeats: list[dict], what: str) -> dict:
    """One run's figures from its repeats: those of the repeat that took the least CPU time (the one the machine's
    other work disturbed least: every repeat does the same work), with ``cpu_s_repeats``, every repeat's CPU seconds,
    and the largest peak RSS. A line on stderr when the repeats' ATE differ by more than a micrometre (dcslam and
    KISS-ICP are deterministic; Open3D's threads sum in varying order, a few nanometres apart)."""
    best = min(repeats, key=lambda r: r["cpu_s"])
    ates = [r["ate_m"] for r in repeats]
    if max(ates) - min(ates) > 1e-6:
        print(f"  {what}: the repeats' ATE differ ({', '.join(format(a, '.6f') for a in ates)})",
              file=sys.stderr, flush=True)
    return {**best, "cpu_s_repeats": [r["cpu_s"] for r in repeats],
            "peak_rss_mb": max(r["peak_rss_mb"] for r in repeats)}


def frames_per_cpu_s(runs: list[dict]) -> float:
    """All the runs' frames over all their CPU seconds."""
    return sum(r["frames"] for r in runs) / sum(r["cpu_s"] for r in runs)


def sparse_ratios(results: dict[tuple[str, str], list[dict]], system: str, peer: str = "KISS-ICP") -> str:
    """``system``'s frames per CPU-second on sparse depth over the KISS-ICP row ``peer``'s, over all drives and drive
    by drive, each drive's with KISS-ICP's ATE there (over all drives the ratio hides a drive KISS-ICP loses)."""
    ours, peer = results[system, "sparse"], results[peer, "velodyne 360"]
    each = [f"{against(frames_per_cpu_s([a]) / frames_per_cpu_s([b]), SPARSE_TARGET)} on {a['drive']} "
            f"(KISS-ICP ATE {b['ate_m']:.3f} m)" for a, b in zip(ours, peer)]
    return f"{against(frames_per_cpu_s(ours) / frames_per_cpu_s(peer), SPARSE_TARGET)} over all drives; " + \
        ", ".join(each)


def against(value: float, target: float) -> str:
    """``value`` with whether it reaches ``target``: the table says so itself, the script's exit status does not
    (a benchmark reports, it does not gate)."""
    return f"{value:.2f} ({'meets' if value >= target else 'BELOW'} {target:g})"


def _each(runs: list[dict], key: str, spec: str) -> str:
    """The drives' values of ``key`` (``fps``: frames per CPU-second) formatted by ``spec``, comma separated."""
    return ", ".join(format(frames_per_cpu_s([r]) if key == "fps" else r[key], spec) for r in runs)


def side_by_side(args) -> None:
    from concurrent.futures import ThreadPoolExecutor

    from dcslam.slam.config import SlamSettings

    paths, kitti_root = _drives(args)
    load_before = os.getloadavg()
    layers = _layers(paths)
    kiss = kiss_icp_available() and (kitti_root / "raw").is_dir()
    print(f"side by side: {len(paths)} drives x {args.frames} frames at full size ({', '.join(p.stem for p in paths)})"
          f"; dcslam defaults {SlamSettings().to_dict()}; one compute thread per run (dcslam's prefetch thread and "
          f"KISS-ICP's own-threads row aside), each in its own process, "
          f"{args.jobs} at a time"
          + (f", every run {args.repeat} times round by round, its fastest counted" if args.repeat > 1 else "")
          + f"; load average {load_before[0]:.1f} before", flush=True)
    if not kiss:
        print("  KISS-ICP: skipped (" + ("not installed; pip install -e .[bench]" if not kiss_icp_available()
                                        else f"{kitti_root / 'raw'} holds no Velodyne scans") + ")", flush=True)
    tasks = _tasks(args, paths, layers, kiss)
    with ThreadPoolExecutor(args.jobs) as pool:       # each thread waits on its child process; round by round
        runs = list(pool.map(lambda t: _run_child(args, CHILD.get(t[0], t[0].lower().replace("-", "")), t[2], t[3],
                                                  kitti_root), tasks * args.repeat))
    done = [fastest(runs[i::len(tasks)], f"{t[0]} on {t[1]} of {t[2].stem}") for i, t in enumerate(tasks)]
    results: dict[tuple[str, str], list[dict]] = {}
    for (system, depth, drive, _), run in zip(tasks, done):
        results.setdefault((system, depth), []).append({**run, "drive": drive.stem})
    if args.json:
        args.json.write_text(json.dumps({f"{s} {d}": runs for (s, d), runs in results.items()}, indent=1))
    print("\n| system | depth | frames per CPU-s: all (per drive) | wall s per drive | ATE m per drive "
          "| drift % per drive | peak RSS MB | frames |", flush=True)
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    fps = {}
    for (system, depth), runs in sorted(results.items(), key=lambda item: "dOK".index(item[0][0][0])):
        frames = sum(r["frames"] for r in runs)
        fps[system, depth] = frames_per_cpu_s(runs)
        label = {"ip-basic": "IP-Basic of sparse", "planefit": "planefit of sparse"}.get(depth, depth)
        print(f"| {system} | {label} | {fps[system, depth]:.2f} ({_each(runs, 'fps', '.1f')}) | "
              f"{_each(runs, 'wall_s', '.2f')} | {_each(runs, 'ate_m', '.3f')} | {_each(runs, 'drift_pct', '.2f')} | "
              f"{max(r['peak_rss_mb'] for r in runs):.0f} | {frames} |", flush=True)
    load_after = os.getloadavg()
    print(f"\nload average {load_before[0]:.1f} before, {load_after[0]:.1f} after ({os.cpu_count()} cores, "
          f"{platform.processor() or platform.machine()})")
    for system, peer in (("dcslam", KISS_THREADS), ("dcslam", "KISS-ICP"), (ONE_THREAD, "KISS-ICP")):
        if kiss:
            print(f"{system} sparse / {peer} frames per CPU-s: {sparse_ratios(results, system, peer)} (a KISS-ICP "
                  f"that diverges iterates to its cap and runs slower: read each drive's ratio beside KISS-ICP's ATE "
                  f"on it)")
    if kiss:
        print(TARGET_MEASURE, flush=True)
    for system in ("dcslam", ONE_THREAD):
        print(f"{system} frames per CPU-s on IP-Basic's completion: "
              f"{against(fps[system, 'ip-basic'], COMPLETED_TARGET)}, on planefit's "
              f"{against(fps[system, 'planefit'], COMPLETED_TARGET)}", flush=True)


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
    from dcslam.allocator import fix_allocator
    from dcslam.slam.config import SlamSettings, build_slam
    from dcslam.slam.scene import StreetScene, kitti_K, lidar_mask, street_trajectory

    kind, n = args.memory_child, args.long_frames
    nbytes = round(args.mmap_threshold_mb * 2 ** 20)
    fixed = fix_allocator(nbytes, arenas=SLAM_ARENAS if nbytes > 0 else 0)   # as `dcslam slam` does
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
    parser.add_argument("--frames", type=int, default=30, help="frames per drive")
    parser.add_argument("--max-drives", type=int, default=2)
    parser.add_argument("--open3d-completed", nargs="*", choices=tuple(COMPLETERS), default=["ip-basic"],
                        help="the completions Open3D runs on besides sparse and dense")
    parser.add_argument("--open3d-completed-drives", type=int, default=1,
                        help="Open3D runs on the completions over this many of the drives (the first)")
    parser.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1), help="runs at a time")
    parser.add_argument("--repeat", type=int, default=1,
                        help="runs of every row on every drive, round by round; the fastest counts (read the CPU "
                             "figures of noisy machines from 3 or more)")
    parser.add_argument("--json", type=Path, help="also write every run's figures to this JSON file")
    parser.add_argument("--long-memory", action="store_true",
                        help="also the long analytic-street memory runs (minutes: --long-frames frames at full size)")
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
                        help="memory run: glibc mmap threshold fixed as `dcslam slam` fixes it, with its trim "
                             "threshold and one arena (0 = glibc's own settings, all three)")
    parser.add_argument("--probe-trim", action="store_true",
                        help="memory run: at each mark, also the RSS after malloc_trim(0) (how much malloc held free)")
    parser.add_argument("--memory-child", choices=("sparse", "dense"), help=argparse.SUPPRESS)
    parser.add_argument("--child", choices=("dcslam", "open3d", "kissicp", *CHILD.values()), help=argparse.SUPPRESS)
    parser.add_argument("--child-drive", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--child-source", help=argparse.SUPPRESS)
    parser.add_argument("--child-kitti", type=Path, help=argparse.SUPPRESS)
    args, _ = parser.parse_known_args()
    if args.repeat < 1:
        parser.error(f"--repeat must be at least 1, got {args.repeat}")
    if args.child:
        print(json.dumps(_child(args.child, args.child_drive, args.child_source, args.frames, args.child_kitti)))
        return
    import torch

    torch.set_num_threads(args.threads)
    if args.memory_child:
        return memory_child(args)
    side_by_side(args)
    if args.long_memory:
        memory(args)


if __name__ == "__main__":
    main()
