"""glibc's allocator on long SLAM runs: a fixed mmap threshold keeps peak memory flat.

glibc serves large allocations by their own ``mmap`` (given back to the system at ``free``) only above a threshold
that it raises on its own, up to 32 MB, each time such a block is freed. The SLAM's per-frame tensors (a 1242 × 375
float image is 1.8 MB; point and normal arrays of the same order) then come from the heap, where blocks of changing
sizes fragment it, and the peak RSS of a long run grows although nothing of dcslam's does. With the threshold fixed
(``mallopt(M_MMAP_THRESHOLD)``, which also stops glibc's own adjustment of it) the peak stays flat; 4 MB is the
default here, a little slower per frame than glibc's own (the measurements: docs/slam.md, "Memory on long drives").
Fixing it stops the adjustment of the trim threshold too, which then stays at 128 kB: every frame glibc gives the
top of the heap back to the system and faults it in again on the next (a tenth of a sparse frame's CPU, more with
the prefetch thread, whose TLBs each release flushes), so the trim threshold is fixed beside it, at 32 MB. And the
prefetch thread would get a malloc arena of its own, which fragments apart from the main one: one arena for the
process keeps 15-20 MB off the peak of a 200-frame run at the same CPU.

One setting cannot be made from inside a running process: glibc's per-thread cache of freed small blocks (up to 7
of each size under 1 kB, per thread), read from ``GLIBC_TUNABLES`` when the process starts. The blocks it holds are
never merged with their free neighbours, and a SLAM run's heap fragments around them: 1.5-2.4 points more peak
memory over 200 frames than over 15 (three runs each way), at the same CPU. The ``dcslam`` command therefore starts
itself once more with the cache off when the environment names no tunables (:func:`tuned_environment`,
:mod:`dcslam.launch`).
"""
from __future__ import annotations

import ctypes
import os
import sys

#: ``mallopt`` parameter number of M_MMAP_THRESHOLD (glibc's malloc.h).
M_MMAP_THRESHOLD = -3
#: Allocations of at least this many bytes get their own mmap in SLAM processes (see the module docstring).
SLAM_MMAP_THRESHOLD = 4 * 2 ** 20
#: ``mallopt`` parameter number of M_TRIM_THRESHOLD (glibc's malloc.h).
M_TRIM_THRESHOLD = -1
#: Free memory at the top of the heap kept for the next frame, not given back, in SLAM processes.
SLAM_TRIM_THRESHOLD = 32 * 2 ** 20
#: ``mallopt`` parameter number of M_ARENA_MAX (glibc's malloc.h), and the arenas of SLAM processes.
M_ARENA_MAX = -8
SLAM_ARENAS = 1
#: glibc's own environment variables for the same settings; when one is set, the user's choices stand.
ENV = "MALLOC_MMAP_THRESHOLD_"
TRIM_ENV = "MALLOC_TRIM_THRESHOLD_"
ARENA_ENV = "MALLOC_ARENA_MAX"
#: glibc's tunables, read once when a process starts; set (even empty), the user's choice stands.
TUNABLES_ENV = "GLIBC_TUNABLES"
#: The tunables of a ``dcslam`` process: no per-thread cache of small freed blocks (see the module docstring).
SLAM_TUNABLES = "glibc.malloc.tcache_count=0"


def _libc():
    """glibc, or None off Linux or where it cannot be loaded."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL("libc.so.6")
    except OSError:
        return None


class _MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks",
                                                     "fsmblks", "uordblks", "fordblks", "keepcost")]


def heap_mb() -> tuple[float, float, float] | None:
    """glibc's view of this process's heap, in MB: (held by malloc's arenas, of that in use, in mmapped blocks), from
    ``mallinfo2``; None without it (not glibc >= 2.33). Arena bytes not in use are memory malloc keeps after
    ``free``: resident, yet no structure of ours holds them."""
    libc = _libc()
    if libc is None or not hasattr(libc, "mallinfo2"):
        return None
    libc.mallinfo2.restype = _MallInfo2
    info = libc.mallinfo2()
    return info.arena / 2 ** 20, info.uordblks / 2 ** 20, info.hblkhd / 2 ** 20


def trim() -> bool:
    """Ask glibc to return the free memory of its arenas to the system (``malloc_trim(0)``); False if unavailable."""
    libc = _libc()
    if libc is None or not hasattr(libc, "malloc_trim"):
        return False
    libc.malloc_trim(0)
    return True


def fix_allocator(nbytes: int = SLAM_MMAP_THRESHOLD, trim_bytes: int = SLAM_TRIM_THRESHOLD,
                  arenas: int = SLAM_ARENAS) -> bool:
    """Serve every allocation of ``nbytes`` or more by its own mmap from now on, in this process, keep up to
    ``trim_bytes`` free at the top of the heap (0: glibc's 128 kB) and let threads started later share ``arenas``
    malloc arenas (0: glibc's 8 per core). Call it before starting threads. Returns whether the mmap threshold was
    set: not for ``nbytes`` <= 0, when ``MALLOC_MMAP_THRESHOLD_`` or ``MALLOC_TRIM_THRESHOLD_`` is in the
    environment (glibc has applied the user's choice already, and either one stops its own adjustments), or off
    glibc / Linux. ``MALLOC_ARENA_MAX`` in the environment leaves the arenas alone."""
    libc = _libc()
    if libc is None or not hasattr(libc, "mallopt"):
        return False
    mallopt = libc.mallopt
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    if arenas > 0 and ARENA_ENV not in os.environ:
        mallopt(M_ARENA_MAX, int(arenas))
    if nbytes <= 0 or ENV in os.environ or TRIM_ENV in os.environ:
        return False
    if trim_bytes > 0 and mallopt(M_TRIM_THRESHOLD, int(trim_bytes)) != 1:
        return False
    return mallopt(M_MMAP_THRESHOLD, int(nbytes)) == 1


def tuned_environment(environ=None) -> dict | None:
    """``environ`` (default ``os.environ``) with :data:`SLAM_TUNABLES` as ``GLIBC_TUNABLES``, for a process to be
    started; None when there is nothing to add: ``GLIBC_TUNABLES`` is set already (even empty: the user's choice),
    or this is not Linux with glibc, where the variable means nothing."""
    environ = os.environ if environ is None else environ
    if TUNABLES_ENV in environ or not sys.platform.startswith("linux"):
        return None
    try:
        libc = os.confstr("CS_GNU_LIBC_VERSION") or ""
    except (ValueError, OSError):  # no such name: not glibc
        return None
    if not libc.startswith("glibc"):
        return None
    return {**environ, TUNABLES_ENV: SLAM_TUNABLES}
