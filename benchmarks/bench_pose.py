"""Memory and time of one pose-loss training step at full KITTI size (1242 × 375), per cost option.

Run: ``python benchmarks/bench_pose.py [--frames 2] [--model sparse-conv] [--limit-gb 6]``.

A generated drive (``dcslam synth`` + ``prepare-kitti``, full resolution) gives a window of ``--frames`` frames; for
each configuration (back-propagating through every LM iteration or only the last k, ICP source thinning by voxel or
by a random subset), a fresh process runs one training step: network forward, pose loss (differentiable
frame-to-model ICP, 3 gate stages: the last ``--iterations`` LM iterations, the two wide ones as many on sparse
depth and at most 3 on a network's dense depth, which a random subset of its sources no longer is), backward,
optimiser step. Printed per configuration: seconds of the step (and of the loss alone), peak resident memory of the
process (``ru_maxrss``) and its growth over the step, and the pose error. A configuration that passes ``--limit-gb``
of address space is reported as such. Figures depend on the machine and on what else runs on it: read them next to
the machine line."""
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

CONFIGS = {  # name → pose options of TrainConfig
    "all iterations, voxel 0.2 m": {"pose_grad_iterations": 0, "pose_source_voxel": 0.2},
    "last 2 iterations, voxel 0.2 m": {"pose_grad_iterations": 2, "pose_source_voxel": 0.2},
    "last 2, voxel 0.2 m, 2000 sources": {"pose_grad_iterations": 2, "pose_source_voxel": 0.2,
                                          "pose_max_sources": 2000},
    "all iterations, every pixel": {"pose_grad_iterations": 0, "pose_source_voxel": 0.0},
    "last 2 iterations, every pixel": {"pose_grad_iterations": 2, "pose_source_voxel": 0.0},
    "last 2, every pixel, 20000 sources": {"pose_grad_iterations": 2, "pose_source_voxel": 0.0,
                                           "pose_max_sources": 20000},
}


def make_drive(root: Path, frames: int) -> Path:
    from dcslam.stages import prepare, synth
    from dcslam.workspace import Workspace

    ws = Workspace(root)
    synth.run(ws, synth.SynthConfig(drives=1, frames=frames + 10, seed=0))
    prepare.run(ws, prepare.PrepareConfig())
    return sorted(ws.drives.glob("*.h5"))[0]


def one_step(drive: str, frames: int, model: str, iterations: int, options: dict) -> dict:
    """One training step in this process; returns the figures."""
    import torch

    from dcslam.depth.data import DriveFrames
    from dcslam.depth.train import Objective, TrainConfig, initial_model, run_model

    torch.set_num_threads(1)
    torch.manual_seed(0)  # the same untrained network in every configuration
    config = TrainConfig(loss="pose", model=model, train_drives=[Path(drive)], pose_frames=frames,
                         pose_iterations=iterations, **options)
    data = DriveFrames(Path(drive), 200, 1, 1.0, 0, "sparse", "dense")
    batch = data.load(range(frames))
    net = initial_model(config)
    optimizer = torch.optim.AdamW(net.parameters(), lr=1e-3, weight_decay=0.01)
    objective = Objective(config)
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    start = time.perf_counter()
    pred = run_model(net, batch)
    loss = objective(pred, batch)
    loss_s = time.perf_counter() - start
    optimizer.zero_grad()
    loss.backward()
    optimizer.step()
    step_s = time.perf_counter() - start
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return {"shape": list(batch.sparse.shape), "step_s": step_s, "loss_s": loss_s, "peak_gb": peak / 2 ** 20,
            "growth_gb": (peak - rss0) / 2 ** 20, "pose": objective.parts["pose"],
            "translation_m": objective.parts["pose_translation_m"], "rejected": objective.parts["pose_rejected"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=2, help="frames per pose window")
    parser.add_argument("--model", default="sparse-conv")
    parser.add_argument("--iterations", type=int, default=10, help="LM iterations per gate stage")
    parser.add_argument("--limit-gb", type=float, default=6.0, help="address-space limit of each step's process")
    parser.add_argument("--only", default="", help="run only the configurations whose name contains this")
    parser.add_argument("--step", nargs=2, help=argparse.SUPPRESS)  # internal: DRIVE CONFIG-NAME
    args, _ = parser.parse_known_args()   # make bench hands every script the same options
    if args.step:
        limit = int(args.limit_gb * 2 ** 30)
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
        print(json.dumps(one_step(args.step[0], args.frames, args.model, args.iterations, CONFIGS[args.step[1]])))
        return
    from dcslam.slam.odometry import coarse_iterations_for

    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, torch 1 thread; "
          f"{args.model}, window of {args.frames} frames, 3 gate stages, the last of {args.iterations} LM iterations "
          f"(the wide ones: {coarse_iterations_for(1.0, args.iterations)} on dense depth)", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        drive = make_drive(Path(tmp), args.frames)
        print(f"{'configuration':<38}{'step s':>8}{'loss s':>8}{'peak GB':>9}{'+GB':>7}{'pose':>8}{'t (m)':>8}")
        for name in CONFIGS:
            if args.only not in name:
                continue
            cmd = [sys.executable, __file__, "--frames", str(args.frames), "--model", args.model, "--iterations",
                   str(args.iterations), "--limit-gb", str(args.limit_gb), "--step", str(drive), name]
            done = subprocess.run(cmd, capture_output=True, text=True)
            if done.returncode != 0:
                why = "out of memory" if "memory" in done.stderr.lower() or "alloc" in done.stderr.lower() else \
                    (done.stderr.strip().splitlines() or ["failed"])[-1][:60]
                print(f"{name:<38}  over {args.limit_gb:g} GB address space ({why})", flush=True)
                continue
            r = json.loads(done.stdout.strip().splitlines()[-1])
            print(f"{name:<38}{r['step_s']:>8.1f}{r['loss_s']:>8.1f}{r['peak_gb']:>9.2f}{r['growth_gb']:>7.2f}"
                  f"{r['pose']:>8.3f}{r['translation_m']:>8.3f}  input {r['shape']}", flush=True)


if __name__ == "__main__":
    main()
