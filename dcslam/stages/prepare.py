"""``prepare-kitti``: KITTI raw + depth-completion folders (real or generated) → one drive file per drive + splits.

Every drive of a split becomes ``<out>/<date>_drive_<NNNN>_sync.h5`` (schema in :mod:`dcslam.io.drive`) holding
only the frames that have depth (5 .. n-6 for real KITTI), with ``frame_ids`` giving the KITTI numbers and poses
re-based so that camera 2 at the first STORED frame (the first frame with depth, not raw frame 0) is the identity.
``<out>/splits.json`` lists the drive names of each split; ``<out>/prepare-kitti.json`` records the settings.

Splits. Real KITTI (no ``SYNTHETIC`` marker) uses the thesis's own split by default (:data:`THESIS_SPLITS`):
drives of the split absent from the root are skipped with a note, and drives found in no split are noted and not
converted unless ``include_unsplit``. Generated drives are divided deterministically in the thesis's proportion
(:func:`proportional_splits`). Any split can be given instead (a ``splits.json``-style file).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.io.drive import DriveWriter, read_splits
from dcslam.io.kitti import DriveIndex, RawDrive, find_drives, index_drive, read_drive
from dcslam.progress import track
from dcslam.stages.config import option
from dcslam.io.atomic import AtomicSet, write_json_atomic
from dcslam.workspace import Workspace, stage_config

SPLIT_NAMES = ("train", "val", "test")


def check_beams(beams: int) -> int:
    """``beams`` if it divides the HDL-64E's 64 lasers, else :class:`DcslamError`."""
    from dcslam.geometry.lidar_beams import BEAM_COUNTS, HDL64_LASERS

    if beams < 1 or HDL64_LASERS % beams:
        raise DcslamError(f"--beams is {beams}; expected a divisor of the LiDAR's {HDL64_LASERS} beams "
                          f"(e.g. {', '.join(map(str, BEAM_COUNTS))})")
    return beams


def _names(date: str, numbers: str) -> list[str]:
    return [f"{date}_drive_{n}_sync" for n in numbers.split()]


THESIS_SPLITS: dict[str, list[str]] = {
    "train": _names("2011_09_26", "0011 0027 0057 0096 0101")
    + _names("2011_09_28", "0075 0098 0141 0145 0167 0171 0198 0220")
    + _names("2011_09_30", "0018") + _names("2011_10_03", "0042"),
    "val": _names("2011_09_26", "0029 0051") + _names("2011_09_28", "0095 0168"),
    "test": _names("2011_09_26", "0001 0005 0009 0018 0048") + _names("2011_10_03", "0027"),
}
"""The drive split of the thesis: 15 train, 4 validation and 6 test drives of KITTI raw."""


def proportional_splits(names: list[str]) -> dict[str, list[str]]:
    """Divide drive names deterministically in the thesis's proportion (15 / 4 / 5 of 24).

    Names are sorted; the last ``round(5n/24)`` (at least 1) go to test, the ``round(4n/24)`` before them (at least
    1 when n >= 3) to val, the rest to train.
    """
    names = sorted(set(names))
    n = len(names)
    if n == 0:
        return {split: [] for split in SPLIT_NAMES}
    n_test = max(1, int(n * 5 / 24 + 0.5))
    n_val = max(1 if n >= 3 else 0, int(n * 4 / 24 + 0.5))
    n_val = min(n_val, n - n_test)
    n_train = n - n_test - n_val
    return {"train": names[:n_train], "val": names[n_train:n_train + n_val], "test": names[n_train + n_val:]}


@dataclass(frozen=True)
class PreparedDrive:
    """One written drive file."""

    name: str
    split: str
    path: Path
    frames: int
    exact: bool = False  # holds depth/exact (generated drives)


@dataclass(frozen=True)
class PrepareResult:
    """What :func:`prepare_kitti` wrote and what it noticed (``notes``: drives skipped and why)."""

    source: str
    drives: tuple[PreparedDrive, ...]
    splits: dict[str, list[str]]
    splits_path: Path
    config_path: Path
    notes: tuple[str, ...]


def _listing(names: list[str], limit: int = 6) -> str:
    shown = ", ".join(names[:limit])
    return shown + (f" and {len(names) - limit} more" if len(names) > limit else "")


def _assign(found: list[RawDrive], splits: dict[str, list[str]], splits_label: str, include_unsplit: bool,
            notes: list[str]) -> list[tuple[RawDrive, str]]:
    split_of: dict[str, str] = {}
    for split in SPLIT_NAMES:
        for name in splits.get(split, []):
            if name in split_of and split_of[name] != split:
                raise DcslamError(f"{splits_label}: drive {name} is in both {split_of[name]} and {split}")
            split_of[name] = split
    found_names = {d.name for d in found}
    absent = sorted(name for name in split_of if name not in found_names)
    if absent:
        notes.append(f"{len(absent)} drive(s) of {splits_label} not found, skipped: {_listing(absent)}")
    chosen, unsplit = [], []
    for drive in found:
        split = split_of.get(drive.name)
        if split is None:
            unsplit.append(drive.name)
            if not include_unsplit:
                continue
            split = ""
        chosen.append((drive, split))
    if unsplit:
        what = "converted with no split" if include_unsplit else "not converted (use --all-drives to convert them)"
        notes.append(f"{len(unsplit)} drive(s) in no split of {splits_label}, {what}: {_listing(unsplit)}")
    return chosen


def prepare_kitti(kitti_root: Path | str, out_dir: Path | str, *, splits_file: Path | str | None = None,
                  max_frames: int | None = None, include_unsplit: bool = False, beams: tuple[int, ...] = (),
                  force: bool = False) -> PrepareResult:
    """Convert the drives of a KITTI root (real or generated) into drive files and ``splits.json``.

    Args:
        kitti_root: folder holding ``raw/`` and ``depth_completion/`` (layout in :mod:`dcslam.io.kitti`).
        out_dir: where drive files, ``splits.json`` and ``prepare-kitti.json`` are written.
        splits_file: a ``{"train": [...], "val": [...], "test": [...]}`` file of drive names; default: the thesis
            split for real KITTI, :func:`proportional_splits` for generated data.
        max_frames: keep at most this many frames (the first ones with depth) per drive.
        include_unsplit: also convert drives found in no split (their ``split`` attribute is empty).
        beams: for each beam count B (a divisor of 64: 32, 16, 8, ...), also write ``depth/sparse_<B>``: the raw
            Velodyne scans cut to B lasers and projected into camera 2 (read as the depth kind ``sparse@<B>``).
        force: overwrite drive files and ``splits.json`` that exist.

    Every drive is checked (:func:`dcslam.io.kitti.index_drive`) before anything is written; outputs that exist
    without ``force`` fail before anything is written. The set is written atomically: drive files are written under
    temporary names and renamed only once every drive has been read, so a failure or an interrupt leaves none of
    them (and no ``splits.json``) and a rerun starts clean.
    """
    kitti_root, out_dir = Path(kitti_root), Path(out_dir)
    _check_arguments(kitti_root, out_dir, max_frames)
    beams = tuple(sorted({int(b) for b in beams}, reverse=True))
    for b in beams:
        check_beams(b)
    notes: list[str] = []
    found = _complete_drives(kitti_root, notes)
    source = found[0].source
    chosen, label = _chosen_drives(kitti_root, found, splits_file, include_unsplit, notes)

    indexes: list[DriveIndex] = [check_increasing(index_drive(drive).head(max_frames)) for drive, _ in chosen]
    from dcslam.locks import output_lock

    with output_lock(out_dir, "drives folder"):  # before anything is checked or written: one writer at a time
        return _write_prepared(kitti_root, out_dir, chosen, indexes, beams, source, label, max_frames,
                               include_unsplit, notes, force)


def check_increasing(index: DriveIndex) -> DriveIndex:
    """``index`` if its image timestamps strictly increase (what SLAM and evo need), else one :class:`DcslamError`
    line naming the drive and the first frame whose timestamp is not after its predecessor's."""
    steps = np.diff(np.asarray(index.timestamps, float))
    bad = np.flatnonzero(~(steps > 0))
    if len(bad):
        k = int(bad[0]) + 1
        how = "equal to" if steps[k - 1] == 0 else "before"
        raise DcslamError(f"drive {index.drive.name}: the timestamp of frame {int(index.frame_ids[k])} is {how} that "
                          f"of frame {int(index.frame_ids[k - 1])} in image_02/timestamps.txt; timestamps must "
                          "strictly increase (fix or drop the drive)")
    return index


def _write_prepared(kitti_root: Path, out_dir: Path, chosen, indexes, beams, source, label, max_frames,
                    include_unsplit, notes, force) -> PrepareResult:
    """Write the drive files, ``splits.json`` and ``prepare-kitti.json`` (the drives folder's lock held)."""
    splits_path = out_dir / "splits.json"
    targets = [out_dir / f"{drive.name}.h5" for drive, _ in chosen]
    if not force:
        for path in (*targets, splits_path):
            if path.exists():
                raise DcslamError(f"{path} exists; pass --force to overwrite it")
    written = _write_drive_files(chosen, indexes, targets, beams, source)

    out_splits = {split: [d.name for d in written if d.split == split] for split in SPLIT_NAMES}
    write_json_atomic(splits_path, out_splits, force=True)
    config_path = write_json_atomic(out_dir / "prepare-kitti.json", stage_config("prepare-kitti", {
        "kitti_root": str(kitti_root), "out_dir": str(out_dir), "source": source, "splits": label,
        "max_frames": max_frames, "include_unsplit": include_unsplit, "beams": list(beams),
        "drives": {d.name: {"split": d.split, "frames": d.frames, "exact": d.exact} for d in written}}),
        force=True)
    return PrepareResult(source, tuple(written), out_splits, splits_path, config_path, tuple(notes))


def _check_arguments(kitti_root: Path, out_dir: Path, max_frames: int | None) -> None:
    if max_frames is not None and max_frames < 1:
        raise DcslamError(f"--max-frames is {max_frames}, expected at least 1")
    if not kitti_root.is_dir():
        what = "is a file, not a folder" if kitti_root.exists() else "does not exist"
        raise DcslamError(f"KITTI root {kitti_root} {what}; pass --kitti DIR (a folder holding raw/ and "
                          "depth_completion/), or run `dcslam synth` to generate one")
    if out_dir.exists() and not out_dir.is_dir():
        raise DcslamError(f"--out {out_dir} is a file; pass a folder for the drive files")


def _complete_drives(kitti_root: Path, notes: list[str]) -> list:
    """The drives under ``kitti_root`` that have both raw and depth-completion folders (at least one, else a
    DcslamError); the others are named in ``notes``."""
    all_drives = find_drives(kitti_root)
    found = [d for d in all_drives if d.has_raw and d.depth_dir is not None]
    if not found:
        raise DcslamError(f"no KITTI drives under {kitti_root} (looked for raw/<date>/<date>_drive_NNNN_sync with "
                          f"depth_completion/{{train,val}}/<date>_drive_NNNN_sync); run `dcslam synth` to generate a "
                          f"KITTI-format dataset there, or pass --kitti DIR")
    raw_only = [d.name for d in all_drives if d.has_raw and d.depth_dir is None]
    depth_only = [d.name for d in all_drives if not d.has_raw and d.depth_dir is not None]
    if raw_only:
        notes.append(f"{len(raw_only)} raw drive(s) without depth-completion folders, skipped: {_listing(raw_only)}")
    if depth_only:
        notes.append(f"{len(depth_only)} depth-completion drive(s) without raw folders, skipped: "
                     f"{_listing(depth_only)}")
    return found


def _chosen_drives(kitti_root: Path, found: list, splits_file: Path | str | None, include_unsplit: bool,
                   notes: list[str]) -> tuple[list, str]:
    """((drive, split) to convert, the split's label): by ``splits_file``, else the thesis split for real KITTI and
    :func:`proportional_splits` for generated data. None chosen, or a split file whose test drives are all absent,
    is a DcslamError."""
    if splits_file is not None:
        splits, label = read_splits(splits_file), str(splits_file)
    elif found[0].source == "kitti":
        splits, label = THESIS_SPLITS, "the thesis split"
    else:
        splits, label = proportional_splits([d.name for d in found]), "the proportional split"
    chosen = _assign(found, splits, label, include_unsplit, notes)
    if not chosen:
        raise DcslamError(f"none of the {len(found)} drive(s) under {kitti_root} is in {label}; nothing to convert")
    wanted = list(splits.get("test", [])) if splits_file is not None else []
    if wanted and not any(split == "test" for _, split in chosen):
        # a split file that names test drives none of which is here (a typo) would make an empty test split,
        # and every later stage (slam, score) runs on the test drives
        raise DcslamError(f"--splits {splits_file}: none of its test drive(s) ({_listing(wanted)}) is under "
                          f"{kitti_root}, so the test split would be empty; fix the names (drives found: "
                          f"{_listing(sorted(d.name for d in found))})")
    return chosen, label


def _write_drive_files(chosen: list, indexes: list[DriveIndex], targets: list[Path], beams: tuple[int, ...],
                       source: str) -> list[PreparedDrive]:
    """Write one drive file per chosen drive, all of them or (on any failure) none."""
    written = []
    with AtomicSet() as files:  # every drive read cleanly, or none of them appears
        for (drive, split), index, path in zip(chosen, indexes, targets):
            frames = track(read_drive(index, beams), drive.name, total=len(index))
            first = next(frames)  # its image gives the frame size
            height, width = first.rgb.shape[:2]
            extra = (*(f"sparse@{b}" for b in beams), *(("exact",) if drive.has_exact else ()))
            with DriveWriter(files.stage(path), index.K, height, width, source=source, date=drive.date,
                             drive=drive.name, split=split, force=True, extra=extra) as writer:
                writer.append(first)
                for frame in frames:
                    writer.append(frame)
            written.append(PreparedDrive(drive.name, split, path, len(index), drive.has_exact))
    return written


HELP = ("Convert KITTI raw + depth-completion drives (real, or from `dcslam synth`) into one HDF5 drive file each, "
        "with only the frames that have depth, camera-2 poses from OXTS, and splits.json.")


@dataclass(frozen=True)
class PrepareConfig:
    """Options of ``dcslam prepare-kitti``."""

    kitti: Path | None = option(None, flags=("--kitti",), show_default="<workspace>/kitti",
                                help="KITTI root holding raw/ and depth_completion/.")
    out: Path | None = option(None, flags=("--out", "-o"), show_default="<workspace>/drives",
                              help="Folder for drive files and splits.json.")
    splits: Path | None = option(None, flags=("--splits",),
                                 show_default="thesis split (real KITTI) or 15/4/5 proportion (generated)",
                                 help='A {"train": [...], "val": [...], "test": [...]} JSON file of drive names.')
    max_frames: int | None = option(None, min=1, help="Keep at most this many frames (the first with depth) per "
                                                      "drive.")
    all_drives: bool = option(False, flags=("--all-drives",), help="Also convert drives that are in no split.")
    beams: list[int] = option(default_factory=list, validate=lambda b: check_beams(b), metavar="BEAMS",
                              help="Also write the sparse depth of this many of the 64 LiDAR beams (repeatable: "
                                   "--beams 32 --beams 16 --beams 8), read as sparse@<BEAMS> by train, predict, "
                                   "slam and score.")

    def __post_init__(self) -> None:
        if self.max_frames is not None and self.max_frames < 1:
            raise DcslamError(f"--max-frames is {self.max_frames}, expected at least 1")


def run(ws: Workspace, config: PrepareConfig, *, force: bool = False) -> PrepareResult:
    """:func:`prepare_kitti` with the workspace's default folders (its record: ``<out>/prepare-kitti.json``)."""
    return prepare_kitti(config.kitti or ws.kitti, config.out or ws.drives, splits_file=config.splits,
                         max_frames=config.max_frames, include_unsplit=config.all_drives,
                         beams=tuple(config.beams), force=force)


CONFIG = PrepareConfig
