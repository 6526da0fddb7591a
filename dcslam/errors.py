"""The one exception type for known failures.

Library code raises :class:`DcslamError` for bad input, a missing file or an artefact that would be overwritten;
the command line prints its message as one line on stderr and exits with code 1. Any other exception is a bug.
"""
from __future__ import annotations

import errno
import os
import re


class DcslamError(Exception):
    """A known failure, told to the user as one line: what was wrong, which file, what to do."""


#: The errors of a write that are the machine's, not the code's: a full disk or quota, a read-only or failing
#: filesystem, a denied permission, a file-size limit (``ulimit -f``).
WRITE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM, errno.EIO,
                          errno.EFBIG})

# HDF5 reports a failed system call in its message, not in the exception's errno: "..., errno = 28, error message
# = 'No space left on device', ..."
_HDF5_ERRNO = re.compile(r"\berrno = (\d+)")


def error_number(exc: BaseException) -> int | None:
    """The operating system's error number behind ``exc``: its ``errno``, or the one HDF5 names in its message."""
    number = getattr(exc, "errno", None)
    if isinstance(number, int):
        return number
    if isinstance(exc, (OSError, RuntimeError)):
        found = _HDF5_ERRNO.search(str(exc))
        if found:
            return int(found.group(1))
    return None


def reason(number: int) -> str:
    """``os.strerror`` as a clause: "no space left on device"."""
    text = os.strerror(number)
    return text[:1].lower() + text[1:]


def write_error(exc: BaseException, path) -> DcslamError | None:
    """The one-line error for a write of ``path`` that failed with ``exc`` ("could not write <path>: no space left
    on device"), or None when ``exc`` is no write failure of the machine (:data:`WRITE_ERRNOS`)."""
    number = error_number(exc)
    if number not in WRITE_ERRNOS:
        return None
    return DcslamError(f"could not write {path}: {reason(number)}")
