"""``dcslam import``: another method's predictions, saved as KITTI devkit PNGs (:mod:`dcslam.io.devkit`), → a layer
``predictions/<name>/<drive>.h5`` that ``slam``, ``score``, ``filter`` and ``score tables`` take like any other.

Every file is checked against its drive before anything is written: the frames of each drive all there and no
other, each file's size (after the crop is put back), 16 bits, depths within the sensor's range. The layers appear
together or not at all, and each records where it came from (``config["imported"]``: source folder, layout, kind,
list, crop)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.io.devkit import LAYOUTS
from dcslam.io.drive import check_input_kind
from dcslam.stages.config import option
from dcslam.workspace import Workspace


def parse_crop(text: str) -> tuple[int, int]:
    """``"ROWS,COLUMNS"`` → (rows, columns), both >= 0; else a :class:`DcslamError`."""
    rows, comma, columns = str(text).partition(",")
    if not comma or not rows.strip().isdigit() or not columns.strip().isdigit():
        raise DcslamError(f"--crop {text!r}: expected ROWS,COLUMNS (what the crop removed above and left of the "
                          "saved pixels, e.g. 100,0)")
    return int(rows), int(columns)


@dataclass(frozen=True)
class ImportConfig:
    """Options of ``dcslam import``."""

    src: Path | None = option(None, metavar="FOLDER", help="Folder of the method's devkit PNGs (uint16, metres × "
                                                           "256, 0 = no depth).")
    name: str | None = option(None, help="Layer name: writes predictions/<name>/ (default: the folder's name).")
    layout: str = option("drive", choices=LAYOUTS,
                         help="drive: <src>/<drive>/proj_depth/<kind>/image_02/<frame:010d>.png; index: "
                              "<src>/<i:010d>.png in the order of --list.")
    kind: str | None = option(None, show_default="the one folder under proj_depth/",
                              help="The folder under <drive>/proj_depth/ (drive layout).")
    list_file: Path | None = option(None, flags=("--list",), metavar="FILE",
                               help="The ordered frames of the index layout: '<drive> <frame>' or a path through "
                                    "<drive>/.../<frame:010d>.png a line, as the method's test list.")
    crop: str | None = option(None, metavar="ROWS,COLUMNS", validate=parse_crop,
                              help="Where the saved pixels sit in the drive's frame (what the method's crop removed "
                                   "above and left of them, e.g. 100,0); the cropped-away pixels get no depth.")
    drive: list[str] = option(default_factory=list,
                              help="Drive name (repeatable; drive layout); default: the test split.")
    input: str = option("sparse", validate=lambda kind: check_input_kind(kind), metavar="KIND",
                        help="The drives' depth the method completed (recorded for `slam --sources measured`).")
    max_depth: float = option(120.0, min=1.0, help="Farthest depth accepted, in metres (KITTI's HDL-64E: 120 m).")

    def __post_init__(self) -> None:
        if self.src is None:
            raise DcslamError("give --src FOLDER: the method's devkit PNGs")
        if self.layout not in LAYOUTS:
            raise DcslamError(f"unknown --layout {self.layout!r}; expected {' or '.join(LAYOUTS)}")
        if self.layout == "index" and self.list_file is None:
            raise DcslamError("--layout index needs --list FILE: the ordered (drive, frame) of the PNGs")
        if self.layout == "index" and self.drive:
            raise DcslamError("--layout index takes its drives from --list; leave out --drive")
        if self.layout == "drive" and self.list_file is not None:
            raise DcslamError("--list is for --layout index; the drive layout names its frames by file")
        if self.crop is not None:
            parse_crop(self.crop)
        check_input_kind(self.input)
        from dcslam.workspace import plain_name

        if self.name is not None:
            plain_name(self.name, "--name")
        if self.kind is not None:
            plain_name(self.kind, "--kind")

    @property
    def offset(self) -> tuple[int, int]:
        return parse_crop(self.crop) if self.crop is not None else (0, 0)


@dataclass
class ImportResult:
    name: str
    out_dir: Path
    layers: list[Path]
    frames: int


def _drive_files(src: Path, drive: str, kind: str | None, frame_ids: np.ndarray) -> tuple[list[Path], str]:
    """The per-drive layout's PNG of every frame of a drive, in the drive's order, and the folder under
    ``proj_depth/`` they are in; a missing or extra file is a :class:`DcslamError` naming it."""
    from dcslam.io.devkit import drive_folder, drive_png

    if not (src / drive).is_dir():
        raise DcslamError(f"{src / drive} not found: no predictions of drive {drive} in --src (or pass --drive)")
    if kind is None:
        kinds = sorted(p.name for p in (src / drive / "proj_depth").glob("*") if p.is_dir())
        if len(kinds) != 1:
            raise DcslamError(f"{src / drive / 'proj_depth'}: {'folders ' + ', '.join(kinds) if kinds else 'no folder'}"
                              "; pass --kind NAME to say which holds the predictions")
        kind = kinds[0]
    files = [drive_png(src, drive, kind, int(f)) for f in frame_ids]
    missing = [f for f in files if not f.is_file()]
    if missing:
        raise DcslamError(f"{missing[0]} not found: {len(missing)} of the drive's {len(files)} frames are missing")
    extra = sorted(set(drive_folder(src, drive, kind).glob("*.png")) - set(files))
    if extra:
        raise DcslamError(f"{extra[0]}: not a frame of drive {drive} ({len(extra)} such file(s)); remove it or "
                          "import against the drive it belongs to")
    return files, kind


def _index_files(src: Path, entries: list[tuple[str, int]], frames: dict[str, np.ndarray],
                 list_path: Path) -> dict[str, list[Path]]:
    """The index layout's PNG of every frame of each listed drive, in the drive's order; a drive the list covers
    only in part, a missing PNG or one beyond the list is a :class:`DcslamError`."""
    from dcslam.io.devkit import index_png

    where = {entry: i for i, entry in enumerate(entries)}
    files = {}
    for drive, frame_ids in frames.items():
        listed = {f for d, f in entries if d == drive}
        unknown = sorted(listed - {int(f) for f in frame_ids})
        if unknown:
            raise DcslamError(f"{list_path}: frame {unknown[0]} of {drive} is not in its drive file")
        absent = [int(f) for f in frame_ids if int(f) not in listed]
        if absent:
            raise DcslamError(f"{list_path}: lists {len(listed)} of the {len(frame_ids)} frames of {drive} (frame "
                              f"{absent[0]} missing); a layer covers every frame of its drive")
        files[drive] = [index_png(src, where[(drive, int(f))]) for f in frame_ids]
    expected = {index_png(src, i) for i in range(len(entries))}
    missing = sorted(f for f in expected if not f.is_file())
    if missing:
        raise DcslamError(f"{missing[0]} not found: {len(missing)} of the list's {len(entries)} frames are missing")
    extra = sorted(set(src.glob("*.png")) - expected)
    if extra:
        raise DcslamError(f"{extra[0]}: beyond the {len(entries)} frames of {list_path} ({len(extra)} such file(s))")
    return files


def _drives_of(ws: Workspace, config: ImportConfig, src: Path) -> tuple[list | None, list[str]]:
    """(the list's (drive, frame) entries or None, the drives imported): those of the list (index layout), else the
    drives selected, refusing a drive folder in ``src`` that is not among them (drive layout)."""
    from dcslam.io.devkit import read_list
    from dcslam.io.drive import list_drives
    from dcslam.workspace import select_drives

    if config.layout == "index":
        entries = read_list(config.list_file, [p.stem for p in list_drives(ws.drives)])
        return entries, list(dict.fromkeys(drive for drive, _ in entries))
    drives = select_drives(ws, config.drive)
    others = sorted(p.name for p in src.iterdir() if p.is_dir() and not p.name.startswith(".") and p.name not in drives)
    if others:
        raise DcslamError(f"{src / others[0]}: predictions of a drive not imported (drives: {', '.join(drives)})"
                          f"; pass --drive {others[0]} too, or remove the folder")
    return None, drives


def run(ws: Workspace, config: ImportConfig, *, force: bool = False) -> ImportResult:
    """Read and check every PNG, then write ``<out>/<drive>.h5`` for each drive and ``<out>/config.json``."""
    from dcslam.workspace import output_folder, plain_name

    src = Path(config.src)
    if not src.is_dir():
        raise DcslamError(f"--src {src} is not a folder of devkit PNGs")
    name = plain_name(config.name or src.resolve().name, "--name")
    out_dir = output_folder(ws.predictions / name, "predictions/<name>")
    entries, drives = _drives_of(ws, config, src)
    outputs = {drive: out_dir / f"{drive}.h5" for drive in drives}
    from dcslam.locks import output_lock

    with output_lock(out_dir, "layer"):  # before anything is checked or written: one writer at a time
        files = _import_drives(ws, config, src, name, out_dir, entries, drives, outputs, force)
    return ImportResult(name, out_dir, list(outputs.values()), sum(len(f) for f in files.values()))


def _import_drives(ws: Workspace, config: ImportConfig, src: Path, name: str, out_dir: Path, entries, drives,
                   outputs: dict, force: bool) -> dict:
    """Read, check and write every drive's layer and ``config.json`` (the layer folder's lock held); returns the
    PNG files read per drive."""
    from dcslam.io.atomic import AtomicSet, write_json_atomic
    from dcslam.io.devkit import read_prediction
    from dcslam.io.drive import DriveFile, Layer, input_beams, write_layer
    from dcslam.progress import track
    from dcslam.stages.config import to_dict
    from dcslam.workspace import drive_file, new_folder, stage_config

    kinds = None
    existing = [p for p in [*outputs.values(), out_dir / "config.json"] if p.exists()]
    if existing and not force:
        raise DcslamError(f"{existing[0]} exists; pass --force to overwrite it")

    frames, shapes = {}, {}
    for drive in drives:
        with DriveFile(drive_file(ws, drive)) as opened:
            frames[drive], shapes[drive] = opened.frame_ids.copy(), opened.shape[1:]
    if entries is not None:
        files = _index_files(src, entries, frames, Path(config.list_file))
    else:
        found = {drive: _drive_files(src, drive, config.kind, frames[drive]) for drive in drives}
        files = {drive: paths for drive, (paths, _) in found.items()}
        kinds = sorted({kind for _, kind in found.values()})

    list_file = str(Path(config.list_file).resolve()) if config.list_file else None
    kind = kinds[0] if kinds and len(kinds) == 1 else kinds  # the folder under proj_depth/ (drive layout)
    imported = {"source": str(src.resolve()), "layout": config.layout, "kind": kind, "list": list_file,
                "crop": list(config.offset)}
    # each drive's layer is staged as soon as its files are read and checked (one drive in memory at a time); the
    # layers appear together when every drive passed, and a refused file leaves none
    with new_folder(out_dir), AtomicSet() as staged:
        for drive in drives:
            h, w = shapes[drive]
            depth = np.stack([read_prediction(path, h, w, config.offset, config.max_depth)
                              for path in track(files[drive], f"import {drive}")])
            layer = Layer(depth=depth, drive=f"{drive}.h5", made_by=name, frame_ids=frames[drive],
                          config={"imported": imported, "drive_file": str(drive_file(ws, drive)),
                                  "input": config.input, "input_beams": input_beams(config.input)})
            write_layer(staged.stage(outputs[drive]), layer, force=True)
    write_json_atomic(out_dir / "config.json",
                      stage_config("import", {**to_dict(config), "name": name, "drives": drives,
                                              "imported": imported}), force=True)
    return files
