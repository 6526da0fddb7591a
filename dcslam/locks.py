"""One writer at a time: a lock per output (a run folder, a layer, a SLAM output folder, a workspace).

:func:`output_lock` takes the lock file ``.<name>.lock`` beside the output (beside, not inside, so that ``--force``
removing the output never removes the lock), before anything of the output is removed or written, and holds it until
the block ends, on every exit path (an exception, Ctrl-C). The lock is an exclusive ``flock`` on that file, which the
kernel drops when its process dies, even by SIGKILL; the file records the holder's PID, command line, host and start
time, so that a refusal names them. A lock file left by a process that is gone is taken over, with a note.

On a filesystem without ``flock`` the file itself is the lock (created with ``O_EXCL``) and the recorded PID decides:
a live process on this host holds it; a dead one's is taken over; another host's is refused, naming that host.
"""
from __future__ import annotations

import contextlib
import errno
import json
import os
import socket
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

from dcslam.errors import DcslamError

# The locks this process holds, by lock file: taking one again inside its own block only counts.
_held: dict[Path, int] = {}


def lock_path(path: Path | str) -> Path:
    """The lock file of output ``path``: ``.<name>.lock`` in the same folder."""
    path = Path(path).absolute()
    return path.with_name(f".{path.name}.lock")


def _command() -> str:
    """This process's command line, as the user typed it where possible (``dcslam train ...``)."""
    argv = list(sys.argv) or ["python"]
    first = Path(argv[0])
    argv[0] = first.parent.name if first.name == "__main__.py" else first.name
    text = " ".join(argv)
    return text if len(text) <= 200 else text[:197] + "..."


def _holder_record() -> dict:
    return {"pid": os.getpid(), "command": _command(), "host": socket.gethostname(),
            "started": time.strftime("%Y-%m-%dT%H:%M:%S%z")}


def _read_record(fd: int) -> dict:
    try:
        text = os.pread(fd, 4096, 0).decode("utf-8", "replace")
        record = json.loads(text) if text.strip() else {}
    except (OSError, ValueError):
        return {}
    return record if isinstance(record, dict) else {}


def process_alive(pid) -> bool:
    """Whether process ``pid`` runs on this machine (a zombie does not): its locks and temporary files are kept."""
    try:
        pid = int(pid)
        os.kill(pid, 0)
    except (TypeError, ValueError, ProcessLookupError, OverflowError):
        return False
    except PermissionError:
        return True
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return True
    return stat.rpartition(")")[2].split()[:1] != ["Z"]


def _refusal(what: str, path: Path, record: dict) -> DcslamError:
    pid = record.get("pid", "?")
    command = record.get("command", "command unknown")
    host = record.get("host")
    where = f" on {host}" if host and host != socket.gethostname() else ""
    return DcslamError(f"{what} {path} is being written by PID {pid}{where} ({command}); wait for it or stop it")


def _stale_note(what: str, path: Path, record: dict) -> str:
    return (f"note: {what} {path}: took over the lock of PID {record.get('pid', '?')} "
            f"({record.get('command', 'command unknown')}), which is no longer running")


def _tell(line: str) -> None:
    sys.stderr.write(line + "\n")


def _lock_error(exc: OSError, lock: Path) -> DcslamError:
    return DcslamError(f"could not create the lock file {lock}: {exc.strerror or exc}; check that its folder is "
                       "writable")


def _write_record(fd: int) -> None:
    data = (json.dumps(_holder_record()) + "\n").encode()
    os.ftruncate(fd, 0)
    os.pwrite(fd, data, 0)


def _take_flock(lock: Path, what: str, path: Path, note: Callable[[str], None]) -> int | None:
    """The open, locked lock file's descriptor; None where the filesystem has no ``flock``."""
    import fcntl

    for attempt in range(1000):
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
        except FileNotFoundError as exc:  # the folder, made by a sibling output's holder, removed as it left
            if attempt >= 3:
                raise _lock_error(exc, lock) from None
            with contextlib.suppress(OSError):
                lock.parent.mkdir(parents=True, exist_ok=True)
            continue
        except OSError as exc:
            raise _lock_error(exc, lock) from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            record = {}
            for _ in range(20):  # the holder writes its record just after taking the lock
                record = _read_record(fd)
                if record:
                    break
                time.sleep(0.01)
            os.close(fd)
            raise _refusal(what, path, record) from None
        except OSError as exc:
            os.close(fd)
            if exc.errno in (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS, errno.EINVAL):
                return None
            raise
        try:  # the file may have been removed by a holder that released it between our open and our lock
            same = os.fstat(fd).st_ino == os.stat(lock).st_ino
        except FileNotFoundError:
            same = False
        if not same:
            os.close(fd)
            continue
        record = _read_record(fd)
        if record.get("pid") not in (None, os.getpid()):
            note(_stale_note(what, path, record))
        try:
            _write_record(fd)
        except OSError as exc:
            os.close(fd)
            raise _lock_error(exc, lock) from None
        return fd
    raise DcslamError(f"{what} {path}: could not take its lock file {lock}; another process keeps taking it")


def _take_exclusive(lock: Path, what: str, path: Path, note: Callable[[str], None]) -> int:
    """The lock file created with ``O_EXCL`` (no ``flock`` here); a dead holder's on this host is taken over."""
    for _ in range(3):
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            try:
                fd = os.open(lock, os.O_RDONLY)
            except FileNotFoundError:
                continue
            record = _read_record(fd)
            os.close(fd)
            if not record or record.get("host") != socket.gethostname() or process_alive(record.get("pid")):
                raise _refusal(what, path, record) from None
            note(_stale_note(what, path, record))
            lock.unlink(missing_ok=True)
            continue
        except OSError as exc:
            raise _lock_error(exc, lock) from None
        _write_record(fd)
        return fd
    raise DcslamError(f"{what} {path}: could not take its lock file {lock}; another process keeps taking it")


@contextlib.contextmanager
def output_lock(path: Path | str, what: str = "output",
                note: Callable[[str], None] | None = None) -> Iterator[Path]:
    """Hold the lock of output ``path`` for the block; yields the lock file's path.

    ``what`` names the output in messages ("run", "layer", "SLAM output", "workspace"). Raises :class:`DcslamError`
    "<what> <path> is being written by PID N (<command>); wait for it or stop it" while another process holds it.
    A lock file of a process that is gone is taken over and ``note`` (default: a line on stderr) says so. The lock is
    released, and its file removed, however the block ends. Taken again by the same process inside its block, it
    only counts.
    """
    path = Path(path).absolute()
    lock = lock_path(path)
    note = note or _tell
    if lock in _held:
        _held[lock] += 1
        try:
            yield lock
        finally:
            _held[lock] -= 1
        return
    made = [folder for folder in (lock.parent, *lock.parent.parents) if not folder.exists()]
    try:
        lock.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _lock_error(exc, lock) from None
    try:
        fd = _take_flock(lock, what, path, note)
        if fd is None:
            fd = _take_exclusive(lock, what, path, note)
    except BaseException:
        _remove_empty(made)
        raise
    _held[lock] = 1
    try:
        yield lock
    finally:
        del _held[lock]
        with contextlib.suppress(OSError):  # removed while still locked, so no one locks a file about to vanish
            lock.unlink()
        os.close(fd)
        _remove_empty(made)


def _remove_empty(folders: list[Path]) -> None:
    """Remove the folders made for a lock file (deepest first) that are still empty: a refused or failed command
    leaves no empty ``predictions/`` or ``slam/`` behind."""
    for folder in folders:
        with contextlib.suppress(OSError):
            folder.rmdir()


def holder(path: Path | str) -> dict | None:
    """The record (``pid``, ``command``, ``host``, ``started``) of the process holding output ``path``'s lock;
    None when no process holds it."""
    import fcntl

    lock = lock_path(path)
    try:
        fd = os.open(lock, os.O_RDONLY)
    except OSError:
        return None
    try:
        record = _read_record(fd)
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return record or {"pid": "?"}
        except OSError:  # no flock here: the recorded process decides
            held = record.get("host") not in (None, socket.gethostname()) or process_alive(record.get("pid"))
            return record if held else None
        return None
    finally:
        os.close(fd)
