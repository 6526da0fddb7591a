"""Atomic writes: every file is written under a temporary name in its final folder and renamed when complete, so an
interrupted write leaves no half-written file; nothing is overwritten without ``force``."""
from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Iterator
from pathlib import Path

from dcslam.errors import DcslamError
from dcslam.interrupt import check


def _temporary_name(path: Path) -> Path:
    return path.with_name(f".{path.name}.tmp-{os.getpid()}")


@contextlib.contextmanager
def atomic_output(path: Path | str, force: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it to ``path`` only if the block completes.

    Raises :class:`DcslamError` if ``path`` exists and ``force`` is false. On any exception (Ctrl-C included) the
    temporary file is removed and ``path`` is left as it was.
    """
    path = Path(path)
    if path.exists() and not force:
        raise DcslamError(f"{path} exists; pass --force to overwrite it")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _temporary_name(path)
    try:
        yield tmp
        check()  # never publish after a Ctrl-C, even one a finalizer swallowed
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise


def write_text_atomic(path: Path | str, text: str, force: bool = True) -> Path:
    """Write ``text`` to ``path`` atomically (overwriting by default: used for small derived files)."""
    with atomic_output(path, force=force) as tmp:
        tmp.write_text(text)
    return Path(path)


def write_json_atomic(path: Path | str, obj, force: bool = True) -> Path:
    """Write ``obj`` as indented JSON atomically; paths become strings and arrays lists."""
    return write_text_atomic(path, json.dumps(obj, indent=2, sort_keys=False, default=_json_default) + "\n", force)


def _json_default(obj):
    if isinstance(obj, Path):
        return str(obj)
    if hasattr(obj, "tolist"):
        return obj.tolist()
    raise TypeError(f"cannot write {type(obj).__name__} as JSON")
