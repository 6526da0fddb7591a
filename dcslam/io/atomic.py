"""Atomic writes: every file is written under a temporary name in its final folder and renamed when complete, so an
interrupted write leaves no half-written file; nothing is overwritten without ``force``."""
from __future__ import annotations

import contextlib
import json
import math
import os
from collections.abc import Iterator
from pathlib import Path

from dcslam.errors import DcslamError
from dcslam.interrupt import check


def _temporary_name(path: Path) -> Path:
    return path.with_name(f".{path.name}.tmp-{os.getpid()}")


def _alive(pid: str) -> bool:
    """Whether a process of this id runs on this machine (a temporary name of a live writer is not removed)."""
    try:
        os.kill(int(pid), 0)
    except (ValueError, ProcessLookupError):
        return False
    except PermissionError:
        return True
    return True


def remove_stale_temporaries(path: Path | str, sets: bool = False) -> None:
    """Remove the temporary files a killed writer of ``path`` left beside it: ``.<name>.tmp-<pid>``
    (:func:`atomic_output`) unless its process still runs here; with ``sets`` also, whatever their process,
    ``.<name>.set-<pid>`` (:class:`AtomicSet`, one writer of a set at a time) and ``..<name>.set-<pid>.tmp-<pid>``
    (a set member written through :func:`atomic_output`)."""
    path = Path(path)
    if not path.parent.is_dir():
        return
    for leftover in path.parent.glob(f".{path.name}.tmp-*"):
        pid = leftover.name.rpartition(".tmp-")[2]
        if pid == str(os.getpid()) or not _alive(pid):
            leftover.unlink(missing_ok=True)
    for pattern in (f".{path.name}.set-*", f"..{path.name}.set-*.tmp-*") if sets else ():
        for leftover in path.parent.glob(pattern):
            leftover.unlink(missing_ok=True)


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
    remove_stale_temporaries(path)
    tmp = _temporary_name(path)
    try:
        yield tmp
        check()  # never publish after a Ctrl-C, even one a finalizer swallowed
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise


class AtomicSet:
    """Files that appear together or not at all: :meth:`stage` gives each final path a temporary name beside it,
    and leaving the ``with`` block cleanly renames them all; any exception (Ctrl-C included) removes them all.

    >>> with AtomicSet() as files:
    ...     for drive in drives:
    ...         write_layer(files.stage(out / f"{drive}.h5"), layer, force=True)
    """

    def __init__(self) -> None:
        self._staged: list[tuple[Path, Path]] = []

    def stage(self, path: Path | str) -> Path:
        """The temporary name to write ``path`` under (``.<name>.set-<pid>``; those a killed run left, of every kind,
        removed first: :func:`remove_stale_temporaries`)."""
        path = Path(path)
        remove_stale_temporaries(path, sets=True)
        tmp = path.with_name(f".{path.name}.set-{os.getpid()}")
        self._staged.append((tmp, path))
        return tmp

    def __enter__(self) -> "AtomicSet":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            if exc_type is None:
                check()
                for tmp, path in self._staged:
                    os.replace(tmp, path)
        finally:
            for tmp, _ in self._staged:
                with contextlib.suppress(FileNotFoundError):
                    tmp.unlink()


def write_text_atomic(path: Path | str, text: str, force: bool = True) -> Path:
    """Write ``text`` to ``path`` atomically (overwriting by default: used for small derived files)."""
    with atomic_output(path, force=force) as tmp:
        tmp.write_text(text)
    return Path(path)


def write_json_atomic(path: Path | str, obj, force: bool = True) -> Path:
    """Write ``obj`` as indented JSON atomically; paths become strings, arrays lists, and NaN or infinite numbers
    ``null`` (bare ``NaN`` is not JSON)."""
    text = json.dumps(_finite(json.loads(json.dumps(obj, default=_json_default))), indent=2, sort_keys=False,
                      allow_nan=False)
    return write_text_atomic(path, text + "\n", force)


def _finite(obj):
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_finite(v) for v in obj]
    return obj


def _json_default(obj):
    if isinstance(obj, Path):
        return str(obj)
    if hasattr(obj, "tolist"):
        return obj.tolist()
    raise TypeError(f"cannot write {type(obj).__name__} as JSON")
