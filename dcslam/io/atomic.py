"""Atomic writes: every file is written under a temporary name in its final folder and renamed when complete, so an
interrupted write leaves no half-written file; nothing is overwritten without ``force``."""
from __future__ import annotations

import contextlib
import io
import json
import math
import os
from collections.abc import Iterator
from pathlib import Path

from dcslam.errors import DcslamError, write_error
from dcslam.interrupt import check
from dcslam.locks import process_alive


def _temporary_name(path: Path) -> Path:
    return path.with_name(f".{path.name}.tmp-{os.getpid()}")


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
        if pid == str(os.getpid()) or not process_alive(pid):
            leftover.unlink(missing_ok=True)
    for pattern in (f".{path.name}.set-*", f"..{path.name}.set-*.tmp-*") if sets else ():
        for leftover in path.parent.glob(pattern):
            leftover.unlink(missing_ok=True)


def final_name(path: Path | str) -> Path:
    """The path a temporary name stands for: ``.<name>.tmp-<pid>`` and ``.<name>.set-<pid>`` (and a set member's
    ``..<name>.set-<pid>.tmp-<pid>``) → ``<name>``; any other path is its own final name."""
    path = Path(path)
    name = path.name
    for marker in (".tmp-", ".set-"):
        while name.startswith(".") and marker in name:
            name = name[1:].rpartition(marker)[0]
    return path.with_name(name) if name else path


def _ours(exc: BaseException, *paths: Path) -> bool:
    """Whether ``exc`` is about one of ``paths`` (or one of their folders), or names no file: an error reading an
    input inside a ``with`` block stays the input's."""
    filename = getattr(exc, "filename", None)
    if filename is None:
        return True
    filename = Path(os.fsdecode(filename)).absolute()
    return any(filename == p.absolute() or filename in p.absolute().parents for p in paths)


def as_write_error(exc: BaseException, path: Path, *also: Path) -> DcslamError | None:
    """The one-line :class:`DcslamError` for ``exc`` if it is a failed write of ``path`` (or of ``also``, its
    temporary names): a full disk, a read-only filesystem, a denied permission, an I/O error
    (:data:`dcslam.errors.WRITE_ERRNOS`); None for anything else."""
    if not isinstance(exc, OSError) or not _ours(exc, path, *also):
        return None
    return write_error(exc, final_name(path))


@contextlib.contextmanager
def atomic_output(path: Path | str, force: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it to ``path`` only if the block completes.

    Raises :class:`DcslamError` if ``path`` exists and ``force`` is false. On any exception (Ctrl-C included) the
    temporary file is removed and ``path`` is left as it was. A write that fails for the machine's reasons (a full
    disk, a read-only filesystem, a denied permission, an I/O error) becomes one :class:`DcslamError` line naming
    ``path`` and the reason: "could not write <path>: no space left on device".
    """
    path = Path(path)
    if path.exists() and not force:
        raise DcslamError(f"{path} exists; pass --force to overwrite it")
    tmp = _temporary_name(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        remove_stale_temporaries(path)
        yield tmp
        check()  # never publish after a Ctrl-C, even one a finalizer swallowed
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        error = as_write_error(exc, path, tmp)
        if error is not None:
            raise error from exc
        raise


def write_bytes_atomic(path: Path | str, data: bytes, force: bool = True) -> Path:
    """Write ``data`` to ``path`` atomically (overwriting by default); a failed write is one :class:`DcslamError`
    line naming the path and the reason."""
    with atomic_output(path, force=force) as tmp:
        with open(tmp, "wb") as f:
            f.write(data)
    return Path(path)


class WriteSink(io.RawIOBase):
    """A binary file for a library that cannot survive its own failed write (HDF5: a write that fails leaves the
    file unclosable, and h5py's cleanup at exit then crashes the process). The first failed write is kept in
    :attr:`error` and every later write is dropped, so the library finishes and closes normally; the owner then
    reads :attr:`error`, raises it and removes the file.

    >>> with WriteSink(tmp) as sink, h5py.File(sink, "w") as h5:
    ...     ...
    """

    def __init__(self, path: Path | str) -> None:
        super().__init__()
        self.path = Path(path)
        self._file = open(self.path, "w+b", buffering=0)
        self.error: OSError | None = None

    def readable(self) -> bool:
        return True

    def writable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def readinto(self, buffer) -> int:
        return self._file.readinto(buffer)

    def write(self, data) -> int:
        size = memoryview(data).nbytes
        if self.error is None:
            try:
                written = 0
                view = memoryview(data).cast("B")
                while written < size:  # a short write (a nearly full disk) is finished or fails with its errno
                    written += self._file.write(view[written:])
            except OSError as exc:
                self.error = exc
                self._file.seek(size - written, os.SEEK_CUR)
            return size
        self._file.seek(size, os.SEEK_CUR)
        return size

    def seek(self, offset: int, whence: int = os.SEEK_SET) -> int:
        return self._file.seek(offset, whence)

    def tell(self) -> int:
        return self._file.tell()

    def truncate(self, size: int | None = None) -> int:
        if self.error is not None:
            return self._file.tell() if size is None else size
        try:
            return self._file.truncate(size)
        except OSError as exc:
            self.error = exc
            return self._file.tell() if size is None else size

    def flush(self) -> None:
        if self.error is None and not self._file.closed:
            try:
                self._file.flush()
            except OSError as exc:
                self.error = exc

    def close(self) -> None:
        if not self._file.closed:
            try:
                self._file.close()
            except OSError as exc:
                if self.error is None:
                    self.error = exc
        super().close()

    def raise_error(self, path: Path | str | None = None) -> None:
        """Raise the kept write failure as one :class:`DcslamError` line naming ``path`` (the file's final name by
        default); a failure of another kind keeps its own type."""
        if self.error is None:
            return
        error = write_error(self.error, final_name(path or self.path))
        if error is None:
            raise self.error
        raise error from self.error


class AtomicSet:
    """Files that appear together or not at all: :meth:`stage` gives each final path a temporary name beside it,
    and leaving the ``with`` block cleanly renames them all; any exception (Ctrl-C included) removes them all. A
    failed write of a member (a full disk, ...) is one :class:`DcslamError` line naming it and the reason.

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
                    try:
                        os.replace(tmp, path)
                    except OSError as error:
                        translated = as_write_error(error, path, tmp)
                        if translated is not None:
                            raise translated from error
                        raise
        finally:
            for tmp, _ in self._staged:
                with contextlib.suppress(OSError):
                    tmp.unlink()
        if isinstance(exc, OSError) and self._staged:  # a failed write of a member names the member
            filename = getattr(exc, "filename", None)
            named = [(path, tmp) for tmp, path in self._staged
                     if filename is not None and Path(os.fsdecode(filename)).absolute() in (tmp.absolute(),
                                                                                            path.absolute())]
            if filename is None or named:  # the member's final name, its temporary one accepted as the file
                translated = as_write_error(exc, *(named or [self._staged[-1][::-1]])[0])
                if translated is not None:
                    raise translated from exc


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


class CommittedSet(AtomicSet):
    """An :class:`AtomicSet` whose completion is recorded by a marker file written last (the names and sizes of its
    files), so that a set is complete or, for every reader, absent: a crash or a full disk between two renames, or
    before the marker, leaves files that :func:`is_committed` rejects. Entering the block first removes the marker
    of an older set of the same name, whose files are about to be replaced.

    >>> with CommittedSet(out / f"{drive}.done") as files:
    ...     write_tum(files.stage(out / f"{drive}.txt"), ...)
    ...     write_json_atomic(files.stage(out / f"{drive}.json"), ...)
    >>> is_committed(out / f"{drive}.done")
    True
    """

    def __init__(self, marker: Path | str) -> None:
        super().__init__()
        self.marker = Path(marker)

    def __enter__(self) -> "CommittedSet":
        try:
            self.marker.unlink(missing_ok=True)
        except OSError as exc:
            error = as_write_error(exc, self.marker)
            if error is not None:
                raise error from exc
            raise
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        super().__exit__(exc_type, exc, tb)
        if exc_type is None:
            files = [{"name": os.path.relpath(path, self.marker.parent), "bytes": path.stat().st_size}
                     for _, path in self._staged]
            write_json_atomic(self.marker, {"schema": COMMIT_SCHEMA, "files": files})


#: The schema of a :class:`CommittedSet`'s marker file.
COMMIT_SCHEMA = "dcslam.commit/1"


def committed_files(marker: Path | str) -> list[Path]:
    """The files of the set that ``marker`` commits; :class:`DcslamError` naming what is wrong when the set is not
    committed (no marker, an unreadable marker, a file missing or of another size than committed)."""
    marker = Path(marker)
    try:
        record = json.loads(marker.read_text())
    except FileNotFoundError:
        raise DcslamError(f"{marker} not found: the output set was not completed; rerun the command that makes it "
                          "with --force") from None
    except (OSError, ValueError) as exc:
        raise DcslamError(f"{marker}: not a readable commit marker ({exc}); rerun the command that makes it with "
                          "--force") from None
    if (not isinstance(record, dict) or record.get("schema") != COMMIT_SCHEMA
            or not isinstance(record.get("files"), list)):
        raise DcslamError(f"{marker}: not a {COMMIT_SCHEMA} commit marker; rerun the command that makes it with "
                          "--force")
    files = []
    for entry in record["files"]:
        path = marker.parent / str(entry.get("name", "")) if isinstance(entry, dict) else None
        if path is None or not path.is_file() or path.stat().st_size != entry.get("bytes"):
            what = "missing" if path is None or not path.is_file() else "changed since it was committed"
            raise DcslamError(f"{path or marker}: {what} (committed by {marker}); rerun the command that makes it "
                              "with --force")
        files.append(path)
    return files


def is_committed(marker: Path | str) -> bool:
    """Whether ``marker`` commits a complete set: every file it names is there, at its committed size."""
    try:
        committed_files(marker)
    except DcslamError:
        return False
    return True
