"""Does training in channels_last keep the numbers? A tiny fixed-seed training (``dcslam.stages.train.train``: 2
epochs over 2 small generated drives, validation on a third, one torch thread) run twice in the default memory
format and twice with the network in ``torch.channels_last``, alternately; prints whether each ``metrics.jsonl``
equals the first default run's (the two default runs are the control: the training is deterministic), the largest
relative difference of any logged number, and each format's smallest CPU time.

Usage: ``python benchmarks/train_channels_last.py [--model sparse-conv] [--height 128] [--width 416]``. Not part of
``make bench``; the finding is in docs/benchmarks.md.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))   # the repository root: tests.fixtures


def _rows(run: Path) -> list[dict]:
    return [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]


def _largest_relative_difference(a: list[dict], b: list[dict]) -> float:
    worst = 0.0
    for row_a, row_b in zip(a, b, strict=True):
        for key, value in row_a.items():
            if isinstance(value, float):
                worst = max(worst, abs(value - row_b[key]) / max(abs(value), 1e-12))
    return worst


def main() -> int:
    import torch

    from dcslam.depth import train as train_module
    from dcslam.depth.train import TrainConfig
    from dcslam.stages.train import train
    from tests.fixtures.depth import write_workspace

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--model", default="sparse-conv")
    parser.add_argument("--height", type=int, default=128)
    parser.add_argument("--width", type=int, default=416)
    parser.add_argument("--epochs", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(1)
    root = Path(tempfile.mkdtemp(prefix="dcslam-channels-last-"))
    drives = write_workspace(root / "ws", height=args.height, width=args.width, n=6) / "drives"
    default_model = train_module.initial_model
    results: dict[str, list] = {"default": [], "channels_last": []}
    for k, fmt in enumerate(["default", "channels_last"] * 2):
        train_module.initial_model = default_model if fmt == "default" else (
            lambda config: default_model(config).to(memory_format=torch.channels_last))
        config = TrainConfig(train_drives=[drives / "drive_a.h5", drives / "drive_b.h5"],
                             val_drives=[drives / "drive_c.h5"], model=args.model, batch_size=2, device="cpu",
                             epochs=args.epochs, seed=0)
        cpu = time.process_time()
        train(root / f"run{k}-{fmt}", config)
        results[fmt].append((_rows(root / f"run{k}-{fmt}"), time.process_time() - cpu))
    train_module.initial_model = default_model
    reference = results["default"][0][0]
    print(f"{args.model} at {args.width} x {args.height}, {args.epochs} epochs, {len(reference)} metrics rows")
    for fmt, runs in results.items():
        for i, (rows, _) in enumerate(runs):
            print(f"  {fmt} run {i + 1}: identical to default run 1: {rows == reference}, largest relative "
                  f"difference {_largest_relative_difference(reference, rows):.2e}")
        print(f"  {fmt}: smallest CPU {min(cpu for _, cpu in runs):.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
