"""``dcslam export``: any depth layer (sparse, dense, a prediction, a filtered layer) → KITTI devkit PNGs
(:mod:`dcslam.io.devkit`) in the benchmark's per-drive layout, or named by index with their ordered list.

The files appear together or not at all: each is written under a temporary name and renamed when every drive's
layer was read and encoded; a refused layer leaves no file and no folder behind."""
from __future__ import annotations

import contextlib
from dataclasses import dataclass
from pathlib import Path

from dcslam.errors import DcslamError
from dcslam.io.devkit import LAYOUTS
from dcslam.stages.config import option
from dcslam.workspace import Workspace

#: The benchmark's folder names of the drive files' own depth; every other layer goes under ``prediction``.
KIND_OF = {"sparse": "velodyne_raw", "dense": "groundtruth"}
LIST_NAME = "list.txt"


@dataclass(frozen=True)
class ExportConfig:
    """Options of ``dcslam export``."""

    depth: str = option("predicted", help="The layer: sparse, dense, sparse@<beams>, exact, predicted/<run>, "
                                          "filtered/<name>, a bare layer name, or a layer folder or file.")
    out_dir: Path | None = option(None, flags=("--out",), metavar="FOLDER",
                                  help="Folder to write the PNGs to (made; must be empty unless --force).")
    layout: str = option("drive", choices=LAYOUTS,
                         help="drive: <out>/<drive>/proj_depth/<kind>/image_02/<frame:010d>.png; index: "
                              f"<out>/<i:010d>.png with <out>/{LIST_NAME} ('<drive> <frame>' a line).")
    kind: str | None = option(None, show_default="velodyne_raw for sparse, groundtruth for dense, else prediction",
                              help="The folder under <drive>/proj_depth/ (drive layout).")
    drive: list[str] = option(default_factory=list, help="Drive name (repeatable); default: the test split.")

    def __post_init__(self) -> None:
        if self.out_dir is None:
            raise DcslamError("give --out FOLDER: where the devkit PNGs go")
        if self.layout not in LAYOUTS:
            raise DcslamError(f"unknown --layout {self.layout!r}; expected {' or '.join(LAYOUTS)}")
        if not self.depth:
            raise DcslamError("--depth is empty; name a depth layer, e.g. sparse or predicted/<run>")
        if self.kind is not None:
            from dcslam.workspace import plain_name

            plain_name(self.kind, "--kind")


@dataclass
class ExportResult:
    layer: str
    out_dir: Path
    files: list[Path]
    list_file: Path | None


@contextlib.contextmanager
def _made_folders():
    """Yield ``make(folder)``, which makes a folder and its missing parents; when the block fails, those made here
    and still empty are removed again, the deepest first."""
    made: list[Path] = []

    def make(folder: Path) -> Path:
        missing = []
        for parent in (folder, *folder.parents):
            if parent.exists():
                break
            missing.append(parent)
        folder.mkdir(parents=True, exist_ok=True)
        made.extend(reversed(missing))
        return folder

    try:
        yield make
    except BaseException:
        for folder in reversed(made):
            with contextlib.suppress(OSError):
                folder.rmdir()
        raise


def run(ws: Workspace, config: ExportConfig, *, force: bool = False) -> ExportResult:
    """Write one PNG per frame of every selected drive (and the list of the index layout)."""
    from dcslam.io.atomic import AtomicSet
    from dcslam.io.devkit import drive_png, encode_prediction, index_png, list_text
    from dcslam.io.drive import DriveFile, load_depth
    from dcslam.progress import track
    from dcslam.workspace import drive_file, output_folder, resolve_layer, select_drives

    layer = resolve_layer(ws, config.depth)
    drives = select_drives(ws, config.drive)
    out = output_folder(Path(config.out_dir), "--out")
    if out.is_dir() and any(out.iterdir()) and not force:
        raise DcslamError(f"--out {out} is not empty; pass --force to write into it")
    kind = config.kind or KIND_OF.get(config.depth, "prediction")
    sources = {drive: layer.require(drive) for drive in drives}  # every layer file there before any work
    paths = {drive: drive_file(ws, drive) for drive in drives}
    files, entries = [], []
    with _made_folders() as make, AtomicSet() as staged:
        for drive in drives:
            with DriveFile(paths[drive]) as opened:
                depth = load_depth(opened, sources[drive])
                frame_ids = opened.frame_ids
            for i in track(range(len(depth)), f"export {drive}"):
                if config.layout == "index":
                    path = index_png(out, len(entries))
                    entries.append((drive, int(frame_ids[i])))
                else:
                    path = drive_png(out, drive, kind, int(frame_ids[i]))
                make(path.parent)
                staged.stage(path).write_bytes(encode_prediction(depth[i]))
                files.append(path)
        list_file = None
        if config.layout == "index":
            list_file = out / LIST_NAME
            make(out)
            staged.stage(list_file).write_text(list_text(entries))
    return ExportResult(layer.name, out, files, list_file)
