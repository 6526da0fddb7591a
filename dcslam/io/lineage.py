"""What an output was made from: each input file's identity (the SHA-256 of its bytes, and its size), recorded in
the output's record under ``made_from`` and checked by the stages that read the output, so that an output made
from an input that changed after it (a SLAM run of an older prediction, a prediction of an older model) is refused
instead of being scored beside the new one.

A record is ``{"made_from": {role: {"path": <relative to the record's folder>, "sha256": hex, "bytes": n}}}``;
paths are relative so that a workspace can be moved or copied. A hash of the bytes is exact; a 30-frame full-size
layer (56 MB) hashes in about 0.1 s, and each file is hashed once per process while its size and mtime stay.
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

from dcslam.errors import DcslamError

#: The key of an output's record under which its inputs' identities are kept.
MADE_FROM = "made_from"
_CHUNK = 1 << 20
# (path, size, mtime_ns, inode) → sha256: a file is hashed once per process while it stays as it was
_hashes: dict[tuple, str] = {}


def file_hash(path: Path | str) -> str:
    """The SHA-256 of the file's bytes (hex), read in 1 MiB chunks."""
    path = Path(path)
    try:
        stat = path.stat()
        key = (str(path.absolute()), stat.st_size, stat.st_mtime_ns, stat.st_ino)
        if key in _hashes:
            return _hashes[key]
        digest = hashlib.sha256()
        with open(path, "rb") as f:
            while chunk := f.read(_CHUNK):
                digest.update(chunk)
    except OSError as exc:
        raise DcslamError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    _hashes[key] = digest.hexdigest()
    return _hashes[key]


def identity(path: Path | str, base: Path | str) -> dict:
    """The identity of input file ``path`` as a record in folder ``base`` keeps it: its path relative to ``base``,
    its SHA-256 and its size."""
    path = Path(path)
    return {"path": os.path.relpath(path.absolute(), Path(base).absolute()), "sha256": file_hash(path),
            "bytes": path.stat().st_size}


def made_from(inputs: dict[str, Path | str | None], base: Path | str) -> dict:
    """``{role: identity}`` of the input files (``None`` entries, inputs that are no file, are left out)."""
    return {role: identity(path, base) for role, path in inputs.items() if path is not None}


def changed_inputs(record: dict, base: Path | str) -> list[tuple[str, Path, str]]:
    """The inputs of a record (in folder ``base``) that are no longer what it was made from: ``(role, path, how)``
    with ``how`` "missing" or "changed after it was made". A record without ``made_from`` has none to check."""
    entries = record.get(MADE_FROM) if isinstance(record, dict) else None
    changed = []
    for role, entry in (entries or {}).items() if isinstance(entries, dict) else ():
        if not isinstance(entry, dict) or "path" not in entry:
            continue
        path = Path(os.path.normpath(Path(base) / entry["path"]))
        if not path.is_file():
            changed.append((role, path, "missing"))
        elif path.stat().st_size != entry.get("bytes") or file_hash(path) != entry.get("sha256"):
            changed.append((role, path, "changed after it was made"))
    return changed


def check_made_from(record: dict, base: Path | str, output: Path | str, rerun: str) -> None:
    """Refuse (one :class:`DcslamError` line) an ``output`` whose record says it was made from an input that has
    changed or gone since: "<output> was made from <input>, which changed after it was made; rerun `<rerun>`"."""
    changed = changed_inputs(record, base)
    if changed:
        _, path, how = changed[0]
        what = "which is missing now" if how == "missing" else "which changed after it was made"
        raise DcslamError(f"{output} is stale: it was made from {path}, {what}; rerun `{rerun}`")


def rerun_command(record: dict) -> str:
    """The command that remakes the output a stage record (``stage_config``) describes, with ``--force``."""
    stage = record.get("stage", "") if isinstance(record, dict) else ""
    settings = record.get("settings", {}) if isinstance(record, dict) else {}
    settings = settings if isinstance(settings, dict) else {}
    if stage == "predict":
        name = settings.get("run") or settings.get("model")
        return f"dcslam predict {'--run' if settings.get('run') else '--model'} {name} --force"
    if stage == "filter":
        return f"dcslam filter --name {settings.get('name')} (its filters) --force"
    return f"dcslam {stage or 'predict'} --force"


def check_layer_folder(folder: Path | str | None) -> None:
    """Refuse a layer folder (``predictions/<run>/``, ``filtered/<name>/``) whose ``config.json`` records inputs
    that changed after its layers were made (the run's model retrained, the source layer remade); a folder without
    that record (the drive files' own depth, a layer made elsewhere or before records existed) passes."""
    import json

    if folder is None:
        return
    path = Path(folder) / "config.json"
    try:
        record = json.loads(path.read_text())
    except (OSError, ValueError):
        return
    if isinstance(record, dict):
        check_made_from(record, folder, folder, rerun_command(record))
