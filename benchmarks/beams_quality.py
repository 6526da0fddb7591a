"""Do trained completers beat their untrained output and a nearest-neighbour fill at 64, 32, 16, 8 beams?

    python benchmarks/beams_quality.py --workspace WS [--seeds 0 1] [--epochs 3] [--models sparse-conv nconv ...]
        [--input-mix sparse sparse@32 sparse@16 sparse@8 | --train-input sparse] [--l1-weight 1]
        [--lr-schedule cosine] [--fill-holes] [--crop 256] [--lr 1e-2]

WS must hold drives made by ``dcslam prepare-kitti --beams 32 --beams 16 --beams 8`` (from ``dcslam synth``
drives or real KITTI). Each model is trained once per seed (``--seeds``: the initialisation) through
:func:`dcslam.stages.train.train`, exactly as ``dcslam train`` does with the same options: dense-mask MSE
(plus ``--l1-weight`` × L1), AdamW, ``--epochs`` passes over the training drives at full resolution on the bottom
``--crop`` rows, keeping the best validation checkpoint; its input is ``--train-input`` or, with ``--input-mix``,
each frame's input drawn in turn from those kinds (density augmentation). Then, on the test drives and at every beam
count (``sparse`` = 64, and each ``sparse@B`` the drives hold), it prints MAE / RMSE in millimetres over EVERY
ground-truth pixel, a hole left at a ground-truth pixel counted as a prediction of 0 m, for: a nearest-neighbour fill
of the input, IP-Basic (fast), and each model untrained and trained. Rows of models show the mean over the seeds and,
after ±, half the range (max − min) / 2; a model is marked ``beats`` at a beam count when EVERY seed's trained model
has a lower MAE and a lower RMSE than both the fill and its own untrained network. Not part of the test suite
(minutes of CPU); its output is quoted in the README.
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


def network(model):
    from dcslam.depth.predict import NetworkCompleter

    completer = NetworkCompleter(model.eval(), "cpu", 1.0, model.ARCH)
    return lambda sparse, rgb: completer.complete(sparse, rgb if completer.guided else None)[0]


def cell(values: list[tuple[float, float]]) -> str:
    """``MAE / RMSE`` of one completer (one value per seed: mean ±half-range)."""
    mae, rmse = np.array(values).T
    if len(values) == 1:
        return f"{mae[0]:.0f} / {rmse[0]:.0f}"
    return (f"{mae.mean():.0f}±{np.ptp(mae) / 2:.0f} / {rmse.mean():.0f}±{np.ptp(rmse) / 2:.0f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workspace", type=Path, required=True)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    parser.add_argument("--epochs", type=int, default=3, help="passes over the training drives per model")
    parser.add_argument("--models", nargs="+", default=["sparse-conv", "nconv", "nconv-guided"])
    parser.add_argument("--train-input", default="sparse")
    parser.add_argument("--input-mix", nargs="*", default=[])
    parser.add_argument("--l1-weight", type=float, default=0.0)
    parser.add_argument("--lr-schedule", default="constant")
    parser.add_argument("--fill-holes", action="store_true", help="sparse-conv leaves no hole")
    parser.add_argument("--lr", type=float, default=1e-2)
    parser.add_argument("--crop", type=int, default=256)
    parser.add_argument("--max-frames", type=int, default=200)
    args = parser.parse_args()

    from dcslam.depth.models import build_model, load_model
    from dcslam.depth.models.ip_basic import IPBasic
    from dcslam.depth.train import TrainConfig
    from dcslam.io.drive import DriveFile, input_beams, read_splits
    from dcslam.stages.train import train
    from dcslam.workspace import Workspace

    ws = Workspace.resolve(args.workspace)
    splits = read_splits(ws.splits)
    paths = {k: [ws.drives / f"{name}.h5" for name in v] for k, v in splits.items()}
    with DriveFile(paths["test"][0]) as drive:
        kinds = sorted((k for k in drive.kinds if k.startswith("sparse")), key=lambda k: -input_beams(k))
    torch.set_num_threads(1)
    print(f"recipe: dense-mask MSE + {args.l1_weight} x L1, lr {args.lr} ({args.lr_schedule}), {args.epochs} epochs, "
          f"input {' / '.join(args.input_mix) or args.train_input}, crop {args.crop}"
          + (", sparse-conv fills its holes" if args.fill_holes else ""), flush=True)

    def hparams(arch):
        return {"fill_holes": True} if args.fill_holes and arch == "sparse-conv" else {}

    trained = {}
    for arch in args.models:
        for seed in args.seeds:
            config = TrainConfig(loss="mse", mask="dense", model=arch, model_hparams=hparams(arch), crop=args.crop,
                                 seed=seed, device="cpu", lr=args.lr, lr_schedule=args.lr_schedule,
                                 l1_weight=args.l1_weight, input=args.train_input, input_mix=list(args.input_mix),
                                 max_frames=args.max_frames, epochs=args.epochs, train_drives=paths["train"],
                                 val_drives=paths["val"])
            run = ws.runs / f"beams-{arch}-seed{seed}"
            start = time.perf_counter()
            result = train(run, config, force=True)
            trained[arch, seed] = load_model(run / "model.pt")[0]
            print(f"{arch} seed {seed}: {result.steps} steps ({result.epochs} epochs) in "
                  f"{(time.perf_counter() - start) / 60:.1f} min on {len(paths['train'])} drive(s); best validation "
                  f"(epoch {result.best['epoch']}) MAE {result.best['mae_mm']:.0f} mm, RMSE "
                  f"{result.best['rmse_mm']:.0f} mm", flush=True)

    def untrained(arch, seed):
        torch.manual_seed(seed)  # the initialisation train() starts from (it seeds torch the same way)
        return network(build_model(arch, **hparams(arch)))

    rows = {"nearest-neighbour fill": [lambda s, rgb: nearest_fill(s)],
            "IP-Basic fast": [lambda s, rgb: IPBasic("fast")(s)]}
    for arch in args.models:
        rows[f"{arch} untrained"] = [untrained(arch, seed) for seed in args.seeds]
        rows[f"{arch} trained"] = [network(trained[arch, seed]) for seed in args.seeds]
    print(f"\ntest drives: {', '.join(p.stem for p in paths['test'])}; MAE / RMSE in mm over every ground-truth "
          f"pixel, holes as 0 m; seeds {args.seeds}: mean ±half-range")
    print(f"{'method':<26}" + "".join(f"{kind:>26}" for kind in kinds))
    scores, pixels = {}, 0
    for name, completers in rows.items():
        for kind in kinds:
            results = [score(complete, paths["test"], kind) for complete in completers]
            scores[name, kind], pixels = [r[:2] for r in results], results[0][2]
        print(f"{name:<26}" + "".join(f"{cell(scores[name, kind]):>26}" for kind in kinds), flush=True)
    print(f"({pixels:,} ground-truth pixels per column)")
    fill = {kind: np.array(scores["nearest-neighbour fill", kind][0]) for kind in kinds}
    for arch in args.models:
        verdict = []
        for kind in kinds:
            t, u = np.array(scores[f"{arch} trained", kind]), np.array(scores[f"{arch} untrained", kind])
            verdict.append(f"{kind}: " + ("beats" if (t < fill[kind]).all() and (t < u).all() else "fails"))
        print(f"{arch}: beats fill and untrained on MAE and RMSE at every seed? " + ", ".join(verdict))


if __name__ == "__main__":
    main()
