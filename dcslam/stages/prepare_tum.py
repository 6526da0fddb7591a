"""``prepare-tum``: TUM RGB-D / ICL-NUIM sequences (real, or from ``dcslam synth --indoor``) → drive files + splits.

Each sequence folder (reading: :mod:`dcslam.io.tum_sequence`) becomes ``<out>/<sequence folder name>.h5``, the same
drive file ``prepare-kitti`` writes (:mod:`dcslam.io.drive`, ``source = "tum"``), so ``slam``, ``train``,
``predict`` and ``score`` run on it unchanged:

- ``rgb``: the colour image; ``depth/dense``: the sensor's depth (value / 5000, metres, 0 = none);
- ``depth/sparse``: a LiDAR-like subsample of that depth, every ``sparse_stride``-th row and column (starting at
  ``sparse_stride // 2``): density ``1 / sparse_stride²`` of the valid pixels (4 % at the default 5, KITTI's
  projected Velodyne covers about 4 %), so the depth-completion recipes also run indoors. It is a regular grid,
  not a scan pattern: scores against it say how a network fills holes, not how it copes with a real LiDAR;
- ``T_world_cam``: the ground-truth pose at each frame (see :func:`dcslam.io.tum_sequence.index_sequence`), re-based
  so that the first stored frame is the identity, as in ``prepare-kitti``;
- ``K``: the given intrinsics, else the folder's ``intrinsics.txt``, else the format's default (ICL-NUIM: fy < 0,
  kept as is);
- ``timestamps``: the depth images' timestamps as written in the sequence (ICL-NUIM: frame numbers);
- ``frame_ids``: each frame's position in the full association, before frames were dropped or skipped.

Root attributes add ``format`` (``tum-rgbd`` or ``icl-nuim``), ``sparse_stride``, ``frame_stride`` and
``sparse_depth`` (a sentence saying what ``depth/sparse`` is). ``<out>/splits.json`` divides the sequences in the
thesis's proportion (:func:`dcslam.stages.prepare.proportional_splits`: one sequence goes to test) unless a splits file
is
given; ``<out>/prepare-tum.json`` records the settings.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.io.drive import DriveFrame, DriveWriter, read_splits
from dcslam.io.tum_rgbd import read_depth_png
from dcslam.io.tum_sequence import Sequence, check_image_size, find_sequences, index_sequence
from dcslam.stages.prepare import SPLIT_NAMES, PreparedDrive, PrepareResult, proportional_splits
from dcslam.progress import track
from dcslam.stages.config import option
from dcslam.io.atomic import write_json_atomic
from dcslam.workspace import Workspace, stage_config

DEFAULT_SPARSE_STRIDE = 5


def sparse_subsample(depth_m: np.ndarray, stride: int) -> np.ndarray:
    """Every ``stride``-th row and column of ``depth_m`` (from ``stride // 2``), zero elsewhere.

    Shape: (H, W) → (H, W), same dtype; the input is not modified."""
    if stride < 1:
        raise DcslamError(f"--sparse-stride is {stride}, expected at least 1")
    out = np.zeros_like(depth_m)
    start = stride // 2
    out[start::stride, start::stride] = depth_m[start::stride, start::stride]
    return out


def _splits(names: list[str], splits_file: Path | str | None, notes: list[str]) -> tuple[dict[str, str], str]:
    if splits_file is None:
        splits, label = proportional_splits(names), "the proportional split"
    else:
        splits, label = read_splits(splits_file), str(splits_file)
    split_of: dict[str, str] = {}
    for split in SPLIT_NAMES:
        for name in splits.get(split, []):
            if name in split_of and split_of[name] != split:
                raise DcslamError(f"{label}: sequence {name} is in both {split_of[name]} and {split}")
            split_of[name] = split
    unsplit = [n for n in names if n not in split_of]
    if unsplit:
        notes.append(f"{len(unsplit)} sequence(s) in no split of {label}, not converted: {', '.join(unsplit)}")
    return {n: split_of[n] for n in names if n in split_of}, label


def _frames(sequence: Sequence, sparse_stride: int):
    T0_inv = np.linalg.inv(sequence.T_world_cam[0])
    for k, (rgb, depth) in enumerate(sequence.frames()):
        yield DriveFrame(rgb=rgb, sparse=sparse_subsample(depth, sparse_stride), dense=depth,
                    T_world_cam=T0_inv @ sequence.T_world_cam[k], timestamp=float(sequence.timestamps[k]),
                    frame_id=int(sequence.frame_ids[k]))


def prepare_tum(src: Path | str, out_dir: Path | str, *, intrinsics: np.ndarray | None = None,
                sparse_stride: int = DEFAULT_SPARSE_STRIDE, max_frames: int | None = None, stride: int = 1,
                splits_file: Path | str | None = None, force: bool = False) -> PrepareResult:
    """Convert TUM RGB-D / ICL-NUIM sequences into drive files and ``splits.json``.

    Args:
        src: a sequence folder, or a folder of sequence folders.
        out_dir: where drive files, ``splits.json`` and ``prepare-tum.json`` are written.
        intrinsics: (3, 3) K for every sequence (fy may be negative); default per sequence (see module docstring).
        sparse_stride: ``depth/sparse`` keeps every ``sparse_stride``-th row and column of the depth.
        max_frames: keep at most this many frames (after ``stride``) per sequence.
        stride: keep every ``stride``-th associated frame.
        splits_file: a ``{"train": [...], "val": [...], "test": [...]}`` file of sequence names.
        force: overwrite drive files and ``splits.json`` that exist.

    Every sequence is indexed and checked (association, files present, ground truth) before anything is written;
    outputs that exist without ``force`` fail before anything is written; each drive file is written atomically.
    Returns a :class:`dcslam.stages.prepare.PrepareResult` with ``source = "tum"``.
    """
    out_dir = Path(out_dir)
    for value, name in ((max_frames, "--max-frames"), (stride, "--stride"), (sparse_stride, "--sparse-stride")):
        if value is not None and value < 1:
            raise DcslamError(f"{name} is {value}, expected at least 1")
    folders = find_sequences(src)
    notes: list[str] = []
    names = [f.name for f in folders]
    if len(set(names)) != len(names):
        raise DcslamError(f"two sequences under {src} share a folder name; drive names must be unique")
    split_of, label = _splits(names, splits_file, notes)
    if not split_of:
        raise DcslamError(f"none of the {len(names)} sequence(s) under {src} is in {label}; nothing to convert")
    chosen = [f for f in folders if f.name in split_of]
    splits_path = out_dir / "splits.json"
    targets = [out_dir / f"{f.name}.h5" for f in chosen]
    if not force:
        for path in (*targets, splits_path):
            if path.exists():
                raise DcslamError(f"{path} exists; pass --force to overwrite it")
    sequences = [_indexed(folder, intrinsics, stride, max_frames, notes) for folder in chosen]
    written = [_write_sequence(sequence, path, split_of[sequence.name], sparse_stride, stride, force)
               for sequence, path in zip(sequences, targets)]

    out_splits = {split: [d.name for d in written if d.split == split] for split in SPLIT_NAMES}
    write_json_atomic(splits_path, out_splits, force=True)
    config_path = write_json_atomic(out_dir / "prepare-tum.json", stage_config("prepare-tum", {
        "src": str(src), "out_dir": str(out_dir), "splits": label, "max_frames": max_frames, "stride": stride,
        "sparse_stride": sparse_stride, "intrinsics": None if intrinsics is None else np.asarray(intrinsics).tolist(),
        "drives": {d.name: {"split": d.split, "frames": d.frames, "format": s.format, "K": s.K.tolist()}
                   for d, s in zip(written, sequences)}}), force=True)
    return PrepareResult("tum", tuple(written), out_splits, splits_path, config_path, tuple(notes))


def _indexed(folder: Path, intrinsics: np.ndarray | None, stride: int, max_frames: int | None,
             notes: list[str]) -> Sequence:
    """The checked sequence of ``folder`` cut to ``stride`` and ``max_frames``; its notes are added to ``notes``."""
    sequence = index_sequence(folder, intrinsics=intrinsics).subsample(stride, max_frames)
    height, width = read_depth_png(sequence.depth_paths[0], sequence.depth_scale).shape
    check_image_size(sequence, width, height, intrinsics is not None)
    notes += [f"{sequence.name}: {note}" for note in sequence.notes]
    return sequence


def _write_sequence(sequence: Sequence, path: Path, split: str, sparse_stride: int, stride: int,
                    force: bool) -> PreparedDrive:
    """Write the drive file of one sequence (atomically, by :class:`dcslam.io.drive.DriveWriter`)."""
    frames = track(_frames(sequence, sparse_stride), sequence.name, total=len(sequence))
    first = next(frames)
    height, width = first.rgb.shape[:2]
    attrs = {"format": sequence.format, "sparse_stride": sparse_stride, "frame_stride": stride,
             "sparse_depth": f"every {sparse_stride}th row and column of depth/dense (LiDAR-like subsample)",
             "sequence": str(sequence.root), "groundtruth": str(sequence.groundtruth)}
    with DriveWriter(path, sequence.K, height, width, source="tum", date="", drive=sequence.name, split=split,
                     force=force, attrs=attrs) as writer:
        writer.append(first)
        for frame in frames:
            writer.append(frame)
    return PreparedDrive(sequence.name, split, path, len(sequence))


HELP = (
    "Convert TUM RGB-D or ICL-NUIM sequences (real, or from `dcslam synth --indoor`) into one HDF5 drive file each "
    "plus splits.json, the format `dcslam slam`, `train` and `score` read.\n\n"
    "A sequence folder holds associations.txt (ICL-NUIM: 't depth/N.png t rgb/N.png') or rgb.txt and depth.txt "
    "(TUM: associated by nearest timestamp, at most 0.02 s apart), 16-bit depth PNGs (5000 = 1 m) and a TUM "
    "trajectory (groundtruth.txt or *.gt.freiburg, also looked for in the parent folder). Poses are interpolated "
    "at each depth timestamp; frames without one are dropped.\n\n"
    "Intrinsics: --intrinsics, else the folder's intrinsics.txt, else TUM's ROS default (525, 525, 319.5, 239.5) or "
    "ICL-NUIM's (481.2, -480, 319.5, 239.5): its negative fy is real (the camera's y axis points up) and is kept.\n\n"
    "depth/dense is the sensor depth; depth/sparse keeps every --sparse-stride-th row and column of it "
    "(LiDAR-like, 4 % of pixels at 5)."
)


@dataclass(frozen=True)
class PrepareTumConfig:
    """Options of ``dcslam prepare-tum``."""

    tum: Path | None = option(None, flags=("--tum",), show_default="<workspace>/tum",
                              help="A sequence folder, or a folder of sequence folders.")
    out: Path | None = option(None, flags=("--out", "-o"), show_default="<workspace>/drives",
                              help="Folder for drive files and splits.json.")
    intrinsics: str | None = option(None, show_default="intrinsics.txt, else the format's default",
                                    help="fx,fy,cx,cy in pixels for every sequence (fy may be negative).")
    sparse_stride: int = option(DEFAULT_SPARSE_STRIDE, min=1, help="depth/sparse keeps every k-th row and column "
                                                                   "of the depth (1/k² of the pixels).")
    max_frames: int | None = option(None, min=1, help="Keep at most this many frames (after --stride) per "
                                                      "sequence.")
    stride: int = option(1, min=1, help="Keep every k-th frame.")
    splits: Path | None = option(None, flags=("--splits",),
                                 show_default="15/4/5 proportion by name; one sequence goes to test",
                                 help='A {"train": [...], "val": [...], "test": [...]} JSON file of sequence names.')

    def __post_init__(self) -> None:
        for name in ("sparse_stride", "stride", "max_frames"):
            if getattr(self, name) is not None and getattr(self, name) < 1:
                raise DcslamError(f"--{name.replace('_', '-')} is {getattr(self, name)}, expected at least 1")
        if self.intrinsics is not None:
            self.K()

    def K(self) -> np.ndarray | None:
        """``intrinsics`` as a (3, 3) matrix, or None."""
        if self.intrinsics is None:
            return None
        from dcslam.io.tum_rgbd import parse_intrinsics

        return parse_intrinsics(self.intrinsics, "--intrinsics")


def run(ws: Workspace, config: PrepareTumConfig, *, force: bool = False) -> PrepareResult:
    """:func:`prepare_tum` with the workspace's default folders (its record: ``<out>/prepare-tum.json``)."""
    return prepare_tum(config.tum or ws.root / "tum", config.out or ws.drives, intrinsics=config.K(),
                       sparse_stride=config.sparse_stride, max_frames=config.max_frames, stride=config.stride,
                       splits_file=config.splits, force=force)


CONFIG = PrepareTumConfig
