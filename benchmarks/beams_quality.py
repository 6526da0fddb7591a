"""Do trained completers beat their untrained output and a nearest-neighbour fill at 64, 32, 16, 8 beams?

    python benchmarks/beams_quality.py --workspace WS [--seeds 0 1] [--epochs 3] [--models sparse-conv nconv ...]
        [--input-mix sparse sparse@32 sparse@16 sparse@8 | --train-input sparse] [--l1-weight 1]
        [--lr-schedule cosine] [--fill-holes] [--correct-fill] [--crop 256] [--lr 1e-2] [--profile-recipes] [--tag NAME]

WS must hold drives made by ``dcslam prepare-kitti --beams 32 --beams 16 --beams 8`` (from ``dcslam synth``
drives or real KITTI). Each model is trained once per seed (``--seeds``: the initialisation) through
:func:`dcslam.stages.train.train`, exactly as ``dcslam train`` does with the same options: dense-mask MSE
(plus ``--l1-weight`` × L1), AdamW, ``--epochs`` passes over the training drives at full resolution on the bottom
``--crop`` rows, keeping the best validation checkpoint; its input is ``--train-input`` or, with ``--input-mix``,
each frame's input drawn in turn from those kinds (density augmentation). With ``--profile-recipes`` each model
takes its own recipe (lr, input, input mix, L1 weight, schedule, hole filling) from the beams profile
(:data:`dcslam.stages.experiments.beams.PROFILES`, ``quick``), the epochs, crop and frames staying this script's.
Then, on the test drives and at every beam count (``sparse`` = 64, and each ``sparse@B`` the drives hold), it
prints MAE / RMSE in millimetres over EVERY ground-truth pixel, a hole left at a ground-truth pixel counted as a
prediction of 0 m, for: a nearest-neighbour fill of the input, IP-Basic (fast), and each model untrained and
trained. Rows of models show the mean over the seeds and, after ±, half the range (max − min) / 2; a model is marked
``beats`` at a beam count when EVERY seed's trained model has a lower MAE and a lower RMSE than both the fill and its
own untrained network. Not part of the test suite (minutes of CPU); its output is the tables of RESULTS.md, "Fill
correction".
"""
from __future__ import annotations

import argparse
import json
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


def completer(spec: tuple):
    """A completer ``(sparse, rgb) -> depth`` from its description: ``("fill",)``, ``("ip-basic",)``, or
    ``("network", arch, hparams, seed, model file or None)`` (None: the untrained network of that seed)."""
    if spec[0] == "fill":
        return lambda sparse, rgb: nearest_fill(sparse)
    if spec[0] == "ip-basic":
        from dcslam.depth.models.ip_basic import IPBasic

        return lambda sparse, rgb: IPBasic("fast")(sparse)
    from dcslam.depth.models import build_model, load_model
    from dcslam.depth.predict import NetworkCompleter

    _, arch, hparams, seed, path = spec
    if path is None:
        torch.manual_seed(seed)  # the initialisation train() starts from (it seeds torch the same way)
        model = build_model(arch, **hparams)
    else:
        model = load_model(path)[0]
    network = NetworkCompleter(model.eval(), "cpu", 1.0, model.ARCH)
    return lambda sparse, rgb: network.complete(sparse, rgb if network.guided else None)[0]


def score_task(spec: tuple, drives: list[Path], kind: str) -> tuple[float, float, int]:
    """One cell of one seed (run in a worker process)."""
    return score(completer(spec), drives, kind)


def train_task(run: Path, config, reuse: bool) -> str:
    """Train one run (or check and take the one there with ``reuse``); returns its summary line."""
    from dcslam.stages.train import read_result, recorded_config, settings_record, train

    start = time.perf_counter()
    if reuse and (run / "model.pt").exists():
        # the run's recorded configuration (an option added since it was trained counts as its default there)
        same = settings_record(recorded_config(run), run)
        differ = [k for k, v in settings_record(config, run).items() if k != "device" and same[k] != v]
        if differ:
            raise SystemExit(f"{run} was trained with other options ({', '.join(differ)}); drop --reuse")
        result, how = read_result(run), "reused"
    else:
        result, how = train(run, config, force=True), f"in {(time.perf_counter() - start) / 60:.1f} min"
    best = min((r for r in result_rows(run) if r["kind"] == "val"), key=lambda r: r["mse"])
    return (f"{run.name}: {result.steps} steps ({result.epochs} epochs) {how}; best validation (epoch "
            f"{best['epoch']}) MAE {best['mae_mm']:.0f} mm, RMSE {best['rmse_mm']:.0f} mm")


def result_rows(run: Path) -> list[dict]:
    return [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines() if line.strip()]


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
    parser.add_argument("--correct-fill", action="store_true",
                        help="every model outputs a correction of the nearest-neighbour fill of its input")
    parser.add_argument("--lr", type=float, default=1e-2)
    parser.add_argument("--crop", type=int, default=256)
    parser.add_argument("--max-frames", type=int, default=200)
    parser.add_argument("--jobs", type=int, default=2, help="worker processes (training runs and table cells)")
    parser.add_argument("--profile-recipes", action="store_true",
                        help="each model's recipe from the beams profile (make reproduce-beams) instead of the options")
    parser.add_argument("--tag", default="", help="added to the run folders' names (runs/beams-<model>-seed<N><tag>), "
                        "so that runs of different recipes sit side by side")
    parser.add_argument("--train-only", action="store_true", help="train the runs, print no table")
    parser.add_argument("--reuse", action="store_true",
                        help="take a run that is already there (e.g. trained by parallel --train-only processes with "
                             "the same options) instead of training it again")
    args = parser.parse_args()

    from dcslam.depth.train import TrainConfig
    from dcslam.io.drive import DriveFile, input_beams, read_splits
    from dcslam.workers import process_pool
    from dcslam.workspace import Workspace

    ws = Workspace.resolve(args.workspace)
    splits = read_splits(ws.splits)
    paths = {k: [ws.drives / f"{name}.h5" for name in v] for k, v in splits.items()}
    with DriveFile(paths["test"][0]) as drive:
        kinds = sorted((k for k in drive.kinds if k.startswith("sparse")), key=lambda k: -input_beams(k))
    torch.set_num_threads(1)

    def recipe(arch: str) -> dict:
        """The options of ``arch``'s training that differ between recipes."""
        if args.profile_recipes:
            from dcslam.stages.experiments.beams import PROFILES

            given = PROFILES["quick"].train_config(arch, seed=0)  # `dcslam train`'s options, its defaults filled in
            return {"lr": given.lr, "lr_schedule": given.lr_schedule, "l1_weight": given.l1_weight,
                    "input": given.input, "input_mix": list(given.input_mix), "model_hparams": given.model_hparams()}
        return {"lr": args.lr, "lr_schedule": args.lr_schedule, "l1_weight": args.l1_weight,
                "input": args.train_input, "input_mix": list(args.input_mix),
                "model_hparams": {**({"fill_holes": True} if args.fill_holes and arch == "sparse-conv" else {}),
                                  **({"correct_fill": True} if args.correct_fill else {})}}

    def hparams(arch):
        return recipe(arch)["model_hparams"]

    for arch in args.models:
        r = recipe(arch)
        print(f"{arch}: dense-mask MSE + {r['l1_weight']} x L1, lr {r['lr']} ({r['lr_schedule']}), {args.epochs} "
              f"epochs, input {' / '.join(r['input_mix']) or r['input']}, crop {args.crop}"
              + (", holes filled" if r["model_hparams"].get("fill_holes") else "")
              + (", correcting the fill" if r["model_hparams"].get("correct_fill") else ""), flush=True)
    runs = {(arch, seed): ws.runs / f"beams-{arch}-seed{seed}{args.tag}" for arch in args.models for seed in args.seeds}
    configs = {key: TrainConfig(loss="mse", mask="dense", model=key[0], crop=args.crop, seed=key[1], device="cpu",
                                max_frames=args.max_frames, epochs=args.epochs, train_drives=paths["train"],
                                val_drives=paths["val"], **recipe(key[0])) for key in runs}
    start = time.perf_counter()
    with process_pool(args.jobs, args.jobs) as pool:  # spawned, one thread each
        for line in pool.map(train_task, runs.values(), configs.values(), [args.reuse] * len(runs)):
            print(line, flush=True)
        print(f"training: {(time.perf_counter() - start) / 60:.1f} min wall with {args.jobs} processes on "
              f"{len(paths['train'])} training drive(s)", flush=True)
        if args.train_only:
            return
        rows = {"nearest-neighbour fill": [("fill",)], "IP-Basic fast": [("ip-basic",)]}
        for arch in args.models:
            rows[f"{arch} untrained"] = [("network", arch, hparams(arch), seed, None) for seed in args.seeds]
            rows[f"{arch} trained"] = [("network", arch, hparams(arch), seed, runs[arch, seed] / "model.pt")
                                       for seed in args.seeds]
        tasks = [(name, kind, spec) for name, specs in rows.items() for kind in kinds for spec in specs]
        start = time.perf_counter()
        results = list(pool.map(score_task, [t[2] for t in tasks], [paths["test"]] * len(tasks),
                                [t[1] for t in tasks]))
    scores = {}
    for (name, kind, _), result in zip(tasks, results):
        scores.setdefault((name, kind), []).append(result[:2])
    print(f"\ntest drives: {', '.join(p.stem for p in paths['test'])}; MAE / RMSE in mm over every ground-truth "
          f"pixel, holes as 0 m; seeds {args.seeds}: mean ±half-range (scored in "
          f"{(time.perf_counter() - start) / 60:.1f} min)")
    print(f"{'method':<26}" + "".join(f"{kind:>26}" for kind in kinds))
    for name in rows:
        print(f"{name:<26}" + "".join(f"{cell(scores[name, kind]):>26}" for kind in kinds))
    print(f"({results[0][2]:,} ground-truth pixels per column)")
    fill = {kind: np.array(scores["nearest-neighbour fill", kind][0]) for kind in kinds}
    for arch in args.models:
        verdict = []
        for kind in kinds:
            t, u = np.array(scores[f"{arch} trained", kind]), np.array(scores[f"{arch} untrained", kind])
            verdict.append(f"{kind}: " + ("beats" if (t < fill[kind]).all() and (t < u).all() else "fails"))
        print(f"{arch}: beats fill and untrained on MAE and RMSE at every seed? " + ", ".join(verdict))


if __name__ == "__main__":
    main()
