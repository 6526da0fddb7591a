"""Do briefly trained completers beat their untrained output and a nearest-neighbour fill at 64, 32, 16, 8 beams?

    python benchmarks/beams_quality.py --workspace WS [--minutes 2] [--models sparse-conv nconv nconv-guided]
        [--train-input sparse] [--crop 256] [--lr 1e-2]

WS must hold drives made by ``dcslam prepare-kitti --beams 32 --beams 16 --beams 8`` (from ``dcslam synth``
drives or real KITTI). Each model is trained with the dense-mask MSE (AdamW) on the training drives' input
``--train-input`` at full resolution on the bottom ``--crop`` rows, epoch by epoch until ``--minutes`` are up,
keeping the best validation checkpoint. Then, on the test drives and at every beam count (``sparse`` = 64, and each
``sparse@B`` the drives hold), it prints MAE / RMSE in millimetres over EVERY ground-truth pixel, a hole left at a
ground-truth pixel counted as a prediction of 0 m, for: a nearest-neighbour fill of the input, IP-Basic (fast), and
each model untrained and trained. Not part of the test suite (minutes of CPU); its output is quoted in the README.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch

from train_quality import nearest_fill  # the script folder is on sys.path


def score(complete, drives, kind: str) -> tuple[float, float, int]:
    """MAE, RMSE (mm) of ``complete(sparse, rgb)`` against the dense depth, holes as 0 m; pixels scored."""
    from dcslam.eval.depth import MIN_DEPTH_M
    from dcslam.io.drive import DriveFile

    abs_sum, sq_sum, n = 0.0, 0.0, 0
    for path in drives:
        with DriveFile(path) as drive:
            for i in range(len(drive)):
                dense = drive.depth("dense", i)
                pred = np.asarray(complete(drive.depth(kind, i), drive.rgb(i)), np.float32)
                pred = np.where(pred >= MIN_DEPTH_M, pred, 0)
                valid = dense > 0
                err = pred[valid].astype(np.float64) - dense[valid]
                abs_sum, sq_sum, n = abs_sum + np.abs(err).sum(), sq_sum + (err ** 2).sum(), n + int(valid.sum())
    return abs_sum / n * 1e3, np.sqrt(sq_sum / n) * 1e3, n


def network(model, scale: float):
    from dcslam.depth.predict import NetworkCompleter

    completer = NetworkCompleter(model.eval(), "cpu", scale, model.ARCH)
    return lambda sparse, rgb: completer.complete(sparse, rgb if completer.guided else None)[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workspace", type=Path, required=True)
    parser.add_argument("--minutes", type=float, default=2.0, help="training time per model")
    parser.add_argument("--models", nargs="+", default=["sparse-conv", "nconv", "nconv-guided"])
    parser.add_argument("--train-input", default="sparse")
    parser.add_argument("--lr", type=float, default=1e-2)
    parser.add_argument("--crop", type=int, default=256)
    parser.add_argument("--max-frames", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    from dcslam.depth.models import build_model, load_model
    from dcslam.depth.models.ip_basic import IPBasic
    from dcslam.depth.train import TrainConfig
    from dcslam.io.drive import DriveFile, read_splits
    from dcslam.stages.train import train
    from dcslam.workspace import Workspace

    ws = Workspace.resolve(args.workspace)
    splits = read_splits(ws.splits)
    paths = {k: [ws.drives / f"{name}.h5" for name in v] for k, v in splits.items()}
    with DriveFile(paths["test"][0]) as drive:
        kinds = [k for k in drive.kinds if k.startswith("sparse")]
    torch.set_num_threads(1)

    trained = {}
    for arch in args.models:
        config = TrainConfig(loss="mse", mask="dense", model=arch, crop=args.crop, seed=args.seed, device="cpu",
                             lr=args.lr, input=args.train_input, max_frames=args.max_frames,
                             train_drives=paths["train"], val_drives=paths["val"], epochs=1)
        run = ws.runs / f"beams-{arch}"
        start = time.perf_counter()
        result = train(run, config, force=True)
        while time.perf_counter() - start < args.minutes * 60:
            config.epochs += 1
            result = train(run, config, resume=True)
        trained[arch] = load_model(run / "model.pt")[0]
        print(f"{arch}: {result.steps} steps ({result.epochs} epochs) in {(time.perf_counter() - start) / 60:.1f} "
              f"min on {len(paths['train'])} drive(s), input {args.train_input}; best validation "
              f"RMSE {result.best['rmse_mm']:.0f} mm", flush=True)

    rows = [("nearest-neighbour fill", lambda s, rgb: nearest_fill(s)), ("IP-Basic fast", lambda s, rgb: IPBasic(
        "fast")(s))]
    for arch in args.models:
        torch.manual_seed(args.seed)
        rows.append((f"{arch} untrained", network(build_model(arch), 1.0)))
        rows.append((f"{arch} trained", network(trained[arch], 1.0)))
    print(f"\ntest drives: {', '.join(p.stem for p in paths['test'])}; MAE / RMSE in mm over every ground-truth "
          f"pixel, holes as 0 m")
    print(f"{'method':<28}" + "".join(f"{kind:>20}" for kind in kinds))
    for name, complete in rows:
        cells = []
        for kind in kinds:
            mae, rmse, n = score(complete, paths["test"], kind)
            cells.append(f"{mae:>9.0f} /{rmse:>8.0f}")
        print(f"{name:<28}" + "".join(f"{c:>20}" for c in cells), flush=True)
    print(f"({n:,} ground-truth pixels per column)")


if __name__ == "__main__":
    main()
