"""Workspace layout, atomic writes and stage configuration files.

Every command reads and writes plain files under one folder (default ``./workspace``, or ``--workspace``, or the
``DCSLAM_WORKSPACE`` environment variable)::

    kitti/                 KITTI-format raw + depth folders (real, or from ``dcslam synth``)
    drives/                one HDF5 drive file per drive + splits.json (``dcslam prepare-kitti``)
    runs/<run>/            one training run (``dcslam train``)
    predictions/<run>/     depth layers written by ``dcslam predict``
    filtered/<name>/       depth layers written by ``dcslam filter``
    slam/<layer>/          trajectories, maps and summaries written by ``dcslam slam``
    slam-long/<layer>/     the same over whole test drives (``dcslam reproduce``'s long-drive table)
    results/               tables and plots written by ``dcslam score``

Nothing is overwritten without ``force``; every file is written under a temporary name in its final folder and
renamed when complete, so an interrupted stage leaves no half-written file.
"""
from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from dcslam.version import __version__
from dcslam.errors import DcslamError

ENV_VAR = "DCSLAM_WORKSPACE"


@dataclass(frozen=True)
class Workspace:
    """The default folders of one workspace."""

    root: Path

    @classmethod
    def resolve(cls, root: Path | str | None = None) -> "Workspace":
        """``root`` if given, else ``$DCSLAM_WORKSPACE``, else ``./workspace``; a file there is a DcslamError."""
        if root is None:
            root = os.environ.get(ENV_VAR) or "workspace"
        return cls(output_folder(Path(root), "workspace (-w)"))

    kitti = property(lambda self: self.root / "kitti", doc="KITTI-format raw + depth folders (real or generated).")
    drives = property(lambda self: self.root / "drives", doc="Drive files and splits.json.")
    splits = property(lambda self: self.drives / "splits.json", doc="The train / val / test drive lists.")
    runs = property(lambda self: self.root / "runs", doc="One folder per training run.")
    predictions = property(lambda self: self.root / "predictions", doc="Prediction layers, one folder per run.")
    filtered = property(lambda self: self.root / "filtered", doc="Filtered layers, one folder per filter chain.")
    slam = property(lambda self: self.root / "slam", doc="SLAM outputs, one folder per layer.")
    slam_long = property(lambda self: self.root / "slam-long",
                         doc="SLAM over whole drives (Table 5.2's long-drive table), one folder per layer.")
    results = property(lambda self: self.root / "results", doc="Scores, tables and plots.")


def stage_config(stage: str, settings: dict) -> dict:
    """The record every stage writes beside its outputs: stage name, settings, dcslam version and time."""
    return {"stage": stage, "dcslam_version": __version__,
            "written": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "settings": settings}


def is_up_to_date(outputs: Iterable[Path], inputs: Iterable[Path]) -> bool:
    """True when every output exists and is newer than every input (used to skip finished pipeline stages)."""
    outputs, inputs = list(outputs), list(inputs)
    if not outputs or not all(p.exists() for p in outputs):
        return False
    newest_input = max((p.stat().st_mtime for p in inputs if p.exists()), default=0.0)
    return min(p.stat().st_mtime for p in outputs) >= newest_input


def require(path: Path, made_by: str) -> Path:
    """Return ``path`` if it exists, else fail naming the command that makes it."""
    if not Path(path).exists():
        raise DcslamError(f"{path} not found; run `{made_by}` first")
    return Path(path)


# --- depth layers: the one resolver -------------------------------------------------------------------------------

DRIVE_DEPTH = ("sparse", "dense")
LAYER_KINDS = {"predicted": ("predictions", "dcslam predict"), "filtered": ("filtered", "dcslam filter")}


@dataclass(frozen=True)
class LayerRef:
    """A depth layer over many drives, resolved by :func:`resolve_layer`.

    ``name`` is what its SLAM outputs and scores go by (``slam/<name>/``); ``folder`` holds ``<drive>.h5`` layer
    files, ``file`` is one layer file used for every drive, and neither is set for the drive files' own ``sparse``
    / ``dense`` depth. ``made_by`` names the command that makes the layer.
    """

    name: str
    folder: Path | None = None
    file: Path | None = None
    made_by: str = "dcslam prepare-kitti"

    def source(self, drive: str) -> str | Path:
        """What :func:`dcslam.io.drive.load_depth` takes for one drive."""
        if self.file is not None:
            return self.file
        return self.name if self.folder is None else self.folder / f"{drive}.h5"

    def require(self, drive: str) -> str | Path:
        """Like :meth:`source`, but fails with one line naming the maker when the drive's layer file is missing."""
        source = self.source(drive)
        if isinstance(source, Path) and not source.exists():
            raise DcslamError(f"{source} not found; run `{self.made_by}` first")
        return source


def _latest_layer(root: Path, made_by: str) -> str:
    runs = sorted((p for p in root.glob("*") if p.is_dir() and any(p.glob("*.h5"))),
                  key=lambda p: p.stat().st_mtime) if root.exists() else []
    if not runs:
        raise DcslamError(f"no layers in {root}; run `{made_by}` first")
    return runs[-1].name


def find_layer(ws: Workspace, ref: str) -> LayerRef | None:
    """The layer ``ref`` names, or ``None``. The grammar, everywhere in dcslam:

    ``sparse`` | ``dense`` | ``sparse@<beams>`` | ``exact`` (the drive files' depth) | ``predicted/<run>`` |
    ``filtered/<name>`` | ``predicted`` or ``filtered`` alone (the most recent such layer) | ``<name>`` (looked
    for in predictions/, then filtered/) | a folder of ``<drive>.h5`` layer files | one ``.h5`` layer file.
    """
    from dcslam.io.drive import is_depth_kind

    if ref in DRIVE_DEPTH or is_depth_kind(ref):
        return LayerRef(ref)
    kind, slash, name = ref.partition("/")
    if kind in LAYER_KINDS and (slash or not name):
        folder, made_by = LAYER_KINDS[kind]
        root = ws.root / folder
        name = name or _latest_layer(root, made_by)
        return LayerRef(name, root / name, made_by=made_by) if (root / name).is_dir() else None
    for folder, made_by in LAYER_KINDS.values() if Path(ref).name == ref else ():  # a bare name
        if (ws.root / folder / ref).is_dir():
            return LayerRef(ref, ws.root / folder / ref, made_by=made_by)
    path = Path(ref)
    if path.is_dir():
        return LayerRef(path.name, path, made_by="dcslam predict")
    if path.is_file():
        return LayerRef(path.stem, file=path, made_by="dcslam predict")
    return None


def resolve_layer(ws: Workspace, ref: str) -> LayerRef:
    """Like :func:`find_layer`, but fails with one line naming the commands that make layers."""
    layer = find_layer(ws, ref)
    if layer is None:
        kind, _, name = ref.partition("/")
        if kind in LAYER_KINDS and name:
            folder, made_by = LAYER_KINDS[kind]
            raise DcslamError(f"{ws.root / folder / name} not found; run `{made_by}` first")
        raise DcslamError(f"no depth layer {ref!r}: not sparse, dense, sparse@<beams> or exact, and neither "
                          f"{ws.predictions / ref} nor {ws.filtered / ref} exists; run `dcslam predict` or "
                          f"`dcslam filter` first")
    return layer


def layer_reference(depth: str, run: str | None) -> str:
    """The layer reference of the commands' ``--depth KIND [--run NAME]`` pair (``predicted`` + ``x`` →
    ``predicted/x``; a folder given as ``--run`` is kept as a path)."""
    if depth in LAYER_KINDS and run:
        return run if Path(run).is_dir() else f"{depth}/{run}"
    return depth


def output_folder(path: Path, option: str) -> Path:
    """``path`` unless it exists and is not a folder (a :class:`DcslamError` naming ``option``)."""
    if path.exists() and not path.is_dir():
        raise DcslamError(f"{option} {path} is a file, not a folder; pass a folder (it is made if missing)")
    return path


@contextlib.contextmanager
def new_folder(path: Path):
    """Make ``path`` (and missing parents) for the block; when the block fails, the folders made here that are
    still empty are removed again, so that a failed command leaves nothing behind for its rerun to trip over."""
    path = Path(path)
    made = []
    folder = path
    while not folder.exists():
        made.append(folder)
        folder = folder.parent
    path.mkdir(parents=True, exist_ok=True)
    try:
        yield path
    except BaseException:
        for folder in made:  # the deepest first; one that holds something stays, with its parents
            try:
                folder.rmdir()
            except OSError:
                break
        raise


def plain_name(name: str, what: str = "name") -> str:
    """``name`` if it is a plain file or folder name (no ``/``, ``\\``, not ``.`` or ``..``, not hidden); else a
    :class:`DcslamError`, so that no name given on the command line or read from a file writes outside its folder."""
    name = str(name)
    if not name or name in (".", "..") or "/" in name or "\\" in name or name.startswith(".") or "\0" in name:
        raise DcslamError(f"{what} {name!r} is not a plain name (no '/', '\\', and not starting with '.'); "
                          "pass a name such as mse-dense+range")
    return name


def select_drives(ws: Workspace, drives: list[str] | None = None, split: str = "test") -> list[str]:
    """``drives`` if given, else the drives of ``split`` in ``splits.json``."""
    from dcslam.io.drive import read_splits

    what = "--drive" if drives else f"drive name in {ws.splits}"
    drives = list(drives) if drives else list(read_splits(ws.splits)[split])
    for drive in drives:
        if not str(drive).endswith(".h5"):  # a drive file given by its path is read, never written beside
            plain_name(drive, what)
    if not drives:
        raise DcslamError(f"{ws.splits}: no {split} drives; pass --drive or rerun `dcslam prepare-kitti`")
    return drives


def drive_file(ws: Workspace, drive: str) -> Path:
    """``drives/<drive>.h5`` (or ``drive`` itself when it is a ``.h5`` path), checked to exist."""
    path = Path(drive) if str(drive).endswith(".h5") else ws.drives / f"{drive}.h5"
    if not path.exists():
        raise DcslamError(f"drive file {path} not found; run `dcslam prepare-kitti` first")
    return path
