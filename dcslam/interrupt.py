"""Ctrl-C that is never swallowed.

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
_told = False


def _handler(signum, frame) -> None:
    global _received
    _received = True
    raise KeyboardInterrupt


def install() -> None:
    """Record SIGINT and raise :class:`KeyboardInterrupt` (the command line calls this once, in the main thread).

    A :class:`KeyboardInterrupt` that Python cannot raise (it landed in a finalizer or a weak-reference callback) is
    not printed as ``Exception ignored ... Traceback``: it is recorded, and :func:`check` raises it at the next safe
    point. Every other unraisable exception still goes to Python's own hook."""
    signal.signal(signal.SIGINT, _handler)
    default = sys.unraisablehook

    def hook(unraisable) -> None:
        global _received
        if isinstance(unraisable.exc_value, KeyboardInterrupt):
            _received = True
            return
        default(unraisable)

    sys.unraisablehook = hook


def received() -> bool:
    """Whether a SIGINT arrived since :func:`install`."""
    return _received


def check() -> None:
    """Raise :class:`KeyboardInterrupt` if a SIGINT arrived, even one that an earlier finalizer swallowed."""
    if _received:
        raise KeyboardInterrupt


def tell(echo) -> None:
    """Tell the user, once, that the command was interrupted (``echo`` writes a line to stderr)."""
    global _told
    if not _told:
        _told = True
        echo("interrupted: no partial output was kept; rerun the command to finish")
