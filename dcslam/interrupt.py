"""Ctrl-C (and SIGTERM) that is never swallowed.

SIGTERM (what ``kill``, a batch system or a container runtime sends) is handled exactly as SIGINT: it raises
:class:`KeyboardInterrupt` in the main thread, the command publishes nothing more, says it was interrupted and exits
128 + the signal's number (130 for SIGINT, 143 for SIGTERM; :func:`exit_code`).

Python raises :class:`KeyboardInterrupt` wherever the main thread happens to be when SIGINT arrives; when that is a
finalizer or a weak-reference callback (h5py closing a file, a ``WeakValueDictionary`` cleaning up), Python prints
``Exception ignored in: ...`` and carries on, and the command would finish and exit 0. :func:`install` (called by
the command line) records every SIGINT; :func:`check` raises it again at the next safe point (each progress step,
before an atomic rename), so a swallowed interrupt still stops the command and publishes nothing more.
"""
from __future__ import annotations

import signal
import sys

_received = False
_signal: int | None = None  # the first interrupting signal received
_told = False
_kept = None  # what the interrupted command kept and how to go on: a line, or a function giving one (or None)
_kept_final = False


def keep(line, final: bool = False) -> None:
    """Say, in the interrupt message, what the command kept and how to go on (``line``: "the run folder ... is kept
    with last.pt; continue it with ... --resume", or a function returning such a line, or None when nothing is kept,
    asked when the interrupt is told: what is on disk then); by default the message says that nothing was kept.
    ``final``: a
    command that runs others in its process (``reproduce``) says it for all of them, and their own lines are
    ignored; ``keep(None)`` starts afresh (the command line calls it before each command)."""
    global _kept, _kept_final
    if _kept_final and line is not None:
        return
    _kept, _kept_final = line, final and line is not None

#: The signals that interrupt a command.
SIGNALS = (signal.SIGINT, signal.SIGTERM)


def _handler(signum, frame) -> None:
    global _received, _signal
    _received = True
    if _signal is None:
        _signal = signum
    raise KeyboardInterrupt


def install() -> None:
    """Record SIGINT and SIGTERM and raise :class:`KeyboardInterrupt` (the command line calls this once, in the main
    thread).

    A :class:`KeyboardInterrupt` that Python cannot raise (it landed in a finalizer or a weak-reference callback) is
    not printed as ``Exception ignored ... Traceback``: it is recorded, and :func:`check` raises it at the next safe
    point. Every other unraisable exception still goes to Python's own hook."""
    for signum in SIGNALS:
        signal.signal(signum, _handler)
    default = sys.unraisablehook

    def hook(unraisable) -> None:
        global _received
        if isinstance(unraisable.exc_value, KeyboardInterrupt):
            _received = True
            return
        default(unraisable)

    sys.unraisablehook = hook


#: What a C extension makes of an interrupt raised inside it, the interrupt as its cause: a :class:`SystemError`
#: from a callback (h5py iterating a file's attributes under its lock: "returned a result with an exception set"),
#: an :class:`ImportError` from a module's initialisation (a pybind11 module imported lazily, such as SciPy's HiGHS
#: under ``scipy.stats``: "initialization failed").
WRAPPED = (SystemError, ImportError)
#: The exceptions to catch where an interrupt may arrive; :func:`is_interrupt` tells which of them are one.
CAUGHT = (KeyboardInterrupt, *WRAPPED)


def is_interrupt(error: BaseException) -> bool:
    """Whether ``error`` is an interrupt: a :class:`KeyboardInterrupt`, or one a C extension wrapped (:data:`WRAPPED`,
    caused by the interrupt)."""
    return isinstance(error, KeyboardInterrupt) or (isinstance(error, WRAPPED)
                                                     and isinstance(error.__cause__, KeyboardInterrupt))


def received() -> bool:
    """Whether a SIGINT or SIGTERM arrived since :func:`install`."""
    return _received


def exit_code() -> int:
    """The exit status of an interrupted command: 128 + the first signal's number (143 for SIGTERM); 130 (as for
    Ctrl-C) when the interrupt came without a signal (a :class:`KeyboardInterrupt` raised some other way)."""
    return 128 + (_signal if _signal is not None else signal.SIGINT)


def ignore() -> None:
    """Ignore SIGINT and SIGTERM from now on (the outcome is decided: Python is shutting down)."""
    for signum in SIGNALS:
        signal.signal(signum, signal.SIG_IGN)


def check() -> None:
    """Raise :class:`KeyboardInterrupt` if a SIGINT or SIGTERM arrived, even one that a finalizer swallowed."""
    if _received:
        raise KeyboardInterrupt


def tell(echo) -> None:
    """Tell the user, once, that the command was interrupted (``echo`` writes a line to stderr)."""
    global _told
    if not _told:
        _told = True
        kept = _kept() if callable(_kept) else _kept
        echo(f"interrupted: {kept}" if kept else "interrupted: no partial output was kept; rerun the command to "
             "finish")
