"""Calibrate the SLAM health verdict (the ``suspect`` flag) at full KITTI size, end to end with the dcslam CLI: generate
drives of one seed, prepare them at 64, 16 and 8 beams, train one SparseConvNet per beam count (the quick profile's
MSE recipe), complete the test drives with it and with IP-Basic, run ``dcslam slam`` (defaults, ``--evidence
auto``) on every input of every test drive, and judge the stored verdicts with ``benchmarks/slam_evidence.py``.

Every step is skipped when its outputs are there, so an interrupted calibration resumes. One process at a time,
one torch thread (set ``OMP_NUM_THREADS=1`` and run under ``nice``).

    OMP_NUM_THREADS=1 nice -n 10 python benchmarks/slam_calibration.py /tmp/calib-ws --drives 12 --seed 9191
    python benchmarks/slam_evidence.py /tmp/calib-ws --flags            # the table, every false flag and miss
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

#: The quick profile's MSE recipe for a SparseConvNet (``dcslam reproduce --table beams --profile quick
#: --print-config``, stage ``train-sparse-conv``), without its density mix: each model sees one beam count.
TRAIN_MSE = ["--model", "sparse-conv", "--loss", "mse", "--mask", "dense", "--target", "dense", "--epochs", "2",
             "--lr", "0.001", "--weight-decay", "0.01", "--max-frames", "31", "--stride", "1", "--scale", "0.5",
             "--crop", "0", "--batch-size", "1", "--seed", "0", "--l1-weight", "30", "--lr-schedule", "cosine",
             "--no-fill-holes", "--correct-fill", "--fill", "nearest", "--fill-output", "depth", "--device", "cpu"]


def kind(beams: int) -> str:
    """The depth kind of a beam count: 64 -> ``sparse``, 16 -> ``sparse@16``."""
    return "sparse" if beams == 64 else f"sparse@{beams}"


def dcslam(ws: Path, *args: str) -> None:
    """One dcslam command in this interpreter's environment, on workspace ``ws``; a command that fails (it has said
    why in its own line) ends the script in one more line, exit 1: a rerun goes on from what is there."""
    command = [sys.executable, "-m", "dcslam", *args, "-w", str(ws)]
    print("$", " ".join(command[2:]), flush=True)
    done = subprocess.run(command, check=False)
    if done.returncode:
        raise SystemExit(f"`dcslam {args[0]}` failed (exit {done.returncode}); run this script again to go on")


def prepare(ws: Path, drives: int, frames: int, seed: int, train: int, val: int, beams: list[int]) -> list[str]:
    """Generate and prepare the drives: the first ``drives - train - val`` (sorted by name) are the test drives, the
    next ``train`` train and the last ``val`` validate. Returns the test drives' names."""
    raw = ws / "kitti" / "raw"
    if not (ws / "kitti" / "SYNTHETIC").exists() and not any(raw.glob("*/*_sync")):
        dcslam(ws, "synth", "--drives", str(drives), "--frames", str(frames), "--seed", str(seed), "--jobs", "1")
    names = sorted(p.name for p in raw.glob("*/*_sync"))
    if len(names) != drives:
        raise SystemExit(f"{raw}: {len(names)} drives, expected {drives}")
    test = names[:drives - train - val]
    splits = {"train": names[len(test):len(test) + train], "val": names[len(test) + train:], "test": test}
    split_file = ws / "calibration-splits.json"
    split_file.write_text(json.dumps(splits, indent=1))
    if not (ws / "drives" / "splits.json").exists():
        dcslam(ws, "prepare-kitti", "--splits", str(split_file), *[a for b in beams if b != 64
                                                                    for a in ("--beams", str(b))])
    return test


def complete(ws: Path, beams: list[int]) -> list[str]:
    """Train one SparseConvNet per beam count and complete the test drives with it and with IP-Basic (fast).
    Returns the prediction layers (``sparse-conv-sparse<beams>``, ``ip-basic-fast-sparse<beams>``)."""
    layers = []
    for b in beams:
        run = f"sparse-conv{b}"
        if not (ws / "runs" / run / "model.pt").exists():   # the trained model (an interrupted run: again)
            dcslam(ws, "train", *TRAIN_MSE, "--input", kind(b), "--name", run, "--force")
        for layer, source in ((f"sparse-conv-sparse{b}", ["--run", run]),
                              (f"ip-basic-fast-sparse{b}", ["--model", "ip-basic-fast"])):
            out = ws / "predictions" / layer
            if not any(out.glob("*.h5")):
                dcslam(ws, "predict", *source, "--split", "test", "--input", kind(b), "--out", str(out),
                       "--device", "cpu")
            layers.append(layer)
    return layers


def slam(ws: Path, inputs: list[str], frames: int, extra: tuple[str, ...] = ()) -> None:
    """``dcslam slam`` at the defaults (``--evidence auto``, and ``extra``: ``--camera`` or ``--no-camera``) over the
    first ``frames`` frames of every test drive for each input, into ``slam/<layer>/``; an input whose summaries are
    all there is skipped."""
    tests = json.loads((ws / "drives" / "splits.json").read_text())["test"]
    for depth in inputs:
        layer = depth.split("/", 1)[-1]
        if all((ws / "slam" / layer / f"{d}.json").exists() for d in tests):
            continue
        dcslam(ws, "slam", "--depth", depth, "--frames", str(frames), "--threads", "1", "--device", "cpu",
               "--evidence", "auto", *extra, "--force")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("workspace", type=Path)
    parser.add_argument("--drives", type=int, default=16, help="drives to generate")
    parser.add_argument("--frames", type=int, default=42, help="raw frames per drive")
    parser.add_argument("--seed", type=int, default=9191)
    parser.add_argument("--test", type=int, default=8, help="test drives (the first by name)")
    parser.add_argument("--val", type=int, default=1, help="validation drives (the last by name)")
    parser.add_argument("--beams", default="64,16,8")
    parser.add_argument("--slam-frames", type=int, default=30)
    parser.add_argument("--no-learned", action="store_true", help="IP-Basic only: no SparseConvNet")
    parser.add_argument("--camera", action="store_true", help="dcslam slam --camera: the camera judges each run "
                        "(without it the runs are made with --no-camera, as the calibrations before the camera were)")
    args = parser.parse_args(argv)
    beams = [int(b) for b in args.beams.split(",")]
    ws = args.workspace
    ws.mkdir(parents=True, exist_ok=True)
    prepare(ws, args.drives, args.frames, args.seed, args.drives - args.test - args.val, args.val, beams)
    layers = complete(ws, beams)
    if args.no_learned:
        layers = [x for x in layers if not x.startswith("sparse-conv")]
    slam(ws, [kind(b) for b in beams] + ["dense", "exact"] + [f"predicted/{x}" for x in layers], args.slam_frames,
         ("--camera",) if args.camera else ("--no-camera",))
    return subprocess.run([sys.executable, str(Path(__file__).with_name("slam_evidence.py")), str(ws), "--flags"],
                          check=False).returncode


if __name__ == "__main__":
    sys.exit(main())
