"""Committed results: a workspace's result files copied into a folder of the repository with a provenance record.

``results/<name>/`` holds the Markdown and CSV files ``dcslam score`` wrote to ``<workspace>/results/`` and a
``provenance.json`` saying where they came from (commit, date, profile, command, machine). Pages splice their tables
from there (:mod:`dcslam.report.splice`), each with the provenance line this module writes.
"""
from __future__ import annotations

import json
import os
import platform
import shutil
import subprocess
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from dcslam.errors import DcslamError

PROVENANCE_FILE = "provenance.json"
PROVENANCE_PREFIX = "Provenance:"  # the one kind of line in the docs that may name a commit
DEFAULT_PATTERNS = ("*.md", "*.csv")


@dataclass(frozen=True)
class CollectResult:
    """The results folder written, the files copied into it and its provenance record."""

    dest: Path
    files: tuple[Path, ...]
    provenance: dict


def read_provenance(folder: Path) -> dict:
    """The ``provenance.json`` of a results folder (at least ``commit`` and ``date``)."""
    path = folder / PROVENANCE_FILE
    if not path.is_file():
        raise DcslamError(f"{path}: missing; copy the results with `dcslam score collect` (make results), which "
                          f"writes it")
    try:
        record = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DcslamError(f"{path}: not a provenance record ({exc}); rewrite it with `dcslam score collect`") from None
    if not isinstance(record, dict) or not record.get("commit") or not record.get("date"):
        raise DcslamError(f"{path}: a provenance record needs at least commit and date; rewrite it with "
                          f"`dcslam score collect`")
    return record


def provenance_line(record: dict) -> str:
    """``Provenance: commit C, D, profile P, `command`, machine: M. NOTE.`` with what the record holds."""
    commit = str(record["commit"]) + (" (with uncommitted changes)" if record.get("modified") else "")
    parts = [f"commit {commit}", str(record["date"])]
    if record.get("profile"):
        parts.append(f"profile {record['profile']}")
    if record.get("command"):
        parts.append(f"`{record['command']}`")
    if record.get("machine"):
        parts.append(f"machine: {record['machine']}")
    line = f"{PROVENANCE_PREFIX} " + ", ".join(parts) + "."
    return f"{line} {record['note'].rstrip('.')}." if record.get("note") else line


def _git(repo: Path, *args: str) -> str | None:
    try:
        done = subprocess.run(["git", "-C", str(repo), *args], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def checkout_commit(repo: Path) -> tuple[str, bool] | None:
    """The short commit of the git checkout holding ``repo`` and whether tracked files differ from it (None
    outside a checkout)."""
    commit = _git(repo, "rev-parse", "--short=12", "HEAD")
    if not commit:
        return None
    return commit, bool(_git(repo, "status", "--porcelain", "--untracked-files=no"))


def cpu_name(cpuinfo: str | None = None) -> str:
    """This machine's processor in words: its model name and, from ``/proc/cpuinfo`` (or the text ``cpuinfo``), its
    family and model numbers and widest x86 vector extension, e.g. ``AMD EPYC (family 25, model 17; AVX-512)``;
    what the platform module names where the file has no model name. The extension is named because results differ
    with it: NumPy and oneDNN pick their kernels by it (RESULTS.md, a table made on three CPUs)."""
    if cpuinfo is None:
        try:
            cpuinfo = Path("/proc/cpuinfo").read_text()
        except OSError:
            cpuinfo = ""
    fields: dict[str, str] = {}
    for line in cpuinfo.splitlines():
        key, sep, value = line.partition(":")
        if sep:
            fields.setdefault(key.strip(), value.strip())  # the first processor's, where each lists its own
    name = fields.get("model name") or platform.processor() or platform.machine()
    details = []
    if "cpu family" in fields and "model" in fields:
        details.append(f"family {fields['cpu family']}, model {fields['model']}")
    flags = set(fields.get("flags", "").split())
    extension = next((label for flag, label in (("avx512f", "AVX-512"), ("avx2", "AVX2"), ("avx", "AVX"))
                      if flag in flags), None)
    if extension:
        details.append(extension)
    return f"{name} ({'; '.join(details)})" if details else name


def default_machine() -> str:
    """This machine in a few words: CPU cores, processor (:func:`cpu_name`), system."""
    return f"{os.cpu_count()} CPU cores, {cpu_name()}, {platform.system()}"


def _written_date(source: Path, files: list[Path]) -> str:
    """The day the results were written: ``score-tables.json``'s ``written``, else the newest file's time (UTC)."""
    record = source / "score-tables.json"
    if record.is_file():
        try:
            written = json.loads(record.read_text()).get("written")
        except (OSError, json.JSONDecodeError):
            written = None
        if isinstance(written, str) and len(written) >= 10:
            return written[:10]
    newest = max(f.stat().st_mtime for f in files)
    return datetime.fromtimestamp(newest, timezone.utc).strftime("%Y-%m-%d")


def collect_results(source: Path, dest: Path, *, profile: str | None = None, command: str | None = None,
                    machine: str | None = None, commit: str | None = None,
                    patterns: tuple[str, ...] = DEFAULT_PATTERNS, force: bool = False) -> CollectResult:
    """Copy the files of ``source`` (a workspace's ``results/``) that match ``patterns`` into ``dest`` with a
    ``provenance.json``; the files appear together or not at all.

    ``commit`` defaults to the checkout holding ``dest`` (recorded ``modified`` when its tracked files differ from
    the commit). An existing ``dest`` with files is replaced only with ``force``; then files of the earlier set
    that the new one lacks are removed.
    """
    from dcslam.io.atomic import AtomicSet, write_json_atomic

    if not source.is_dir():
        raise DcslamError(f"{source}: no results folder; run `dcslam score tables` (or `dcslam reproduce`) first")
    files = sorted({f for pattern in patterns for f in source.glob(pattern)
                    if f.is_file() and f.name != PROVENANCE_FILE})
    if not files:
        raise DcslamError(f"{source}: no results files matching {' '.join(patterns)}; run `dcslam score tables` "
                          f"(or `dcslam reproduce`) first")
    earlier = sorted(f for f in dest.iterdir() if f.is_file()) if dest.is_dir() else []
    if earlier and not force:
        raise DcslamError(f"{dest} holds results already; pass --force to replace them")
    modified = False
    if commit is None:
        existing = next(p for p in (dest, *dest.parents) if p.exists())
        found = checkout_commit(existing)
        if found is None:
            raise DcslamError(f"{dest}: not inside a git checkout; pass --commit to say which code made the results")
        commit, modified = found
    record = {"commit": commit, "modified": modified, "date": _written_date(source, files),
              "profile": profile, "command": command, "machine": machine or default_machine(),
              "files": [f.name for f in files]}
    dest.mkdir(parents=True, exist_ok=True)
    with AtomicSet() as staged:
        for f in files:
            shutil.copyfile(f, staged.stage(dest / f.name))
    write_json_atomic(dest / PROVENANCE_FILE, record, force=True)
    kept = {f.name for f in files} | {PROVENANCE_FILE}
    for old in earlier:
        if old.name not in kept:
            old.unlink()
    return CollectResult(dest, tuple(dest / f.name for f in files), record)
