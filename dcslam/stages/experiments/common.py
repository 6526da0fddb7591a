"""What the experiments share: the drives (synth or a KITTI root, then prepare-kitti, split as the profile says),
the options of ``dcslam train`` and the order trainings can run in."""
from __future__ import annotations

import json
from pathlib import Path

from dcslam.errors import DcslamError
from dcslam.io.atomic import write_json_atomic
from dcslam.stages import prepare, synth, train
from dcslam.stages.config import Options
from dcslam.stages.pipeline import Pipeline, Stage
from dcslam.workspace import Workspace


def train_options(**values) -> Options:
    """Options of ``dcslam train`` (fields of :class:`dcslam.stages.train.TrainStageConfig`), checked when made."""
    return Options(train.TrainStageConfig, values)


def split_by_counts(names: list[str], counts: tuple[int, int, int]) -> dict[str, list[str]]:
    """The profile's split of drive ``names`` (sorted): the first ``counts[0]`` train, then val, then test."""
    n_train, n_val, _ = counts
    names = sorted(names)
    return {"train": names[:n_train], "val": names[n_train:n_train + n_val], "test": names[n_train + n_val:]}


def _split_file(ws: Workspace) -> Path:
    return ws.root / ".reproduce" / "splits.json"


def generated_names(kitti: Path, counts: tuple[int, int, int]) -> list[str] | None:
    """The drive names of a generated root (``dcslam synth``'s ``SYNTHETIC`` marker) holding as many drives as a
    profile splits (``counts``), sorted; None for real KITTI, a missing root or another number of drives (which
    ``prepare-kitti`` then splits in the thesis's proportion)."""
    from dcslam.io.kitti import dataset_source, find_drives

    if not Path(kitti).is_dir() or dataset_source(kitti) != "synthetic":
        return None
    names = sorted({d.name for d in find_drives(kitti)})
    return names if len(names) == sum(counts) else None


def _profile_splits(ws: Workspace, kitti: Path, counts: tuple[int, int, int]) -> Path:
    """Write the profile's split of the generated drives (sorted by name: train, then val, then test)."""
    from dcslam.io.kitti import find_drives

    names = sorted({d.name for d in find_drives(kitti)})
    if len(names) != sum(counts):
        raise DcslamError(f"{kitti}: {len(names)} drives, the profile splits {sum(counts)}; remove {kitti} and rerun")
    path = _split_file(ws)
    splits = split_by_counts(names, counts)
    if not path.exists() or json.loads(path.read_text()) != splits:
        write_json_atomic(path, splits, force=True)
    return path


def training_rounds(runs: dict[str, dict]) -> list[list[str]]:
    """Run names (keys of ``runs``: name → training options) in the order they can be trained, as two rounds of
    independent runs: those from scratch, then those that fine-tune one of them (``init``)."""
    first = [name for name, options in runs.items() if options.get("init") is None]
    return [first, [name for name in runs if name not in first]]


def check_kitti_root(kitti: Path) -> None:
    """A :class:`DcslamError` unless ``kitti`` is a folder."""
    if not Path(kitti).is_dir():
        raise DcslamError(f"KITTI root {kitti} does not exist or is not a folder; pass --kitti DIR")


def make_drives(pipe: Pipeline, *, drives: int, frames: int, split: tuple[int, int, int] | None,
                kitti_root: Path | None = None, seed: int = 0, beams: tuple[int, ...] = (), jobs: int = 1
                ) -> tuple[list[Path], list[Path]]:
    """The synth (unless ``kitti_root``; ``jobs`` drives at once) and prepare-kitti stages (``beams``: the extra
    sparse inputs of ``prepare-kitti --beams``); returns the drive files (test, train + val). A planning pipeline
    (``--print-config``) runs nothing and reads the split it plans with."""
    ws = pipe.ws
    kitti = Path(kitti_root) if kitti_root else ws.kitti
    if kitti_root is None:
        pipe.run(Stage("synth", synth.run, synth.SynthConfig(drives=drives, frames=frames, seed=seed, jobs=jobs),
                       outputs=lambda: [ws.kitti / "SYNTHETIC"]))
    elif not pipe.planning:  # a plan may name a root that is not mounted here
        check_kitti_root(kitti)
    split_file = None
    if kitti_root is None and split:
        split_file = _split_file(ws) if pipe.planning else _profile_splits(ws, kitti, split)
    elif split and not pipe.planning and generated_names(kitti, split) is not None:
        # drives generated before (`dcslam synth`, or another workspace's kitti/) split as the profile splits its own
        split_file = _profile_splits(ws, kitti, split)
    pipe.run(Stage("prepare-kitti", prepare.run, prepare.PrepareConfig(kitti=kitti, splits=split_file,
                                                                       beams=list(beams)),
                   outputs=lambda: [ws.splits, *sorted(ws.drives.glob("*.h5"))],
                   inputs=lambda: [p for p in (kitti / "SYNTHETIC", split_file) if p is not None and p.exists()]))
    from dcslam.io.drive import read_splits

    splits = pipe.splits if pipe.planning else read_splits(ws.splits)
    return ([ws.drives / f"{name}.h5" for name in splits["test"]],
            [ws.drives / f"{name}.h5" for name in splits["train"] + splits["val"]])
