"""dcslam.allocator: the fixed glibc mmap threshold of SLAM processes (each check in a fresh interpreter, so that this
test process's allocator keeps glibc's defaults)."""
import subprocess
import sys


from dcslam.allocator import ARENA_ENV, ENV, SLAM_MMAP_THRESHOLD, SLAM_TRIM_THRESHOLD, TRIM_ENV, fix_allocator
from tests.fixtures.glibc import needs_mallinfo2


# Frees an 8 MB block that glibc served by mmap (glibc then raises its own threshold to 8 MB), then allocates 6 MB
# and prints whether that block was mmapped too (heap_mb's third figure: MB in mmapped blocks).
PROBE = """
import ctypes, sys
from dcslam.allocator import fix_allocator, heap_mb
libc = ctypes.CDLL("libc.so.6")
libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, [ctypes.c_size_t]
libc.free.argtypes = [ctypes.c_void_p]
fixed = fix_allocator() if sys.argv[1] == "fix" else False
libc.free(libc.malloc(8 << 20))
before = heap_mb()[2]
block = libc.malloc(6 << 20)
print(fixed, heap_mb()[2] - before >= 6)
libc.free(block)
"""

def _probe(mode: str, env: dict | None = None, code: str = PROBE) -> str:
    import os

    environ = {k: v for k, v in os.environ.items() if k not in (ENV, TRIM_ENV, ARENA_ENV)} | (env or {})
    out = subprocess.run([sys.executable, "-c", code, mode], capture_output=True, text=True, env=environ, check=True)
    return out.stdout.strip()


@needs_mallinfo2
def test_a_fixed_threshold_keeps_serving_large_blocks_by_mmap_after_glibc_would_have_raised_it():
    assert SLAM_MMAP_THRESHOLD < 6 << 20
    assert _probe("default") == "False False"   # glibc's own threshold rose to 8 MB: 6 MB came from the heap
    assert _probe("fix") == "True True"         # fixed at 4 MB: 6 MB is its own mmap, returned at free


@needs_mallinfo2
def test_the_environment_variable_wins():
    # glibc applied MALLOC_MMAP_THRESHOLD_ itself (here 16 MB, so the 6 MB block is from the heap); dcslam leaves it
    assert _probe("fix", {ENV: str(16 << 20)}) == "False False"


# A 3 MB block (under the 4 MB threshold: from the heap, at its top) allocated and freed: does the heap keep the
# memory (the arena as large as with the block in it) or give it back to the system?
# (mallinfo2 bound once, before the block: nothing between malloc and free may take heap memory above the block)
TRIM_PROBE = """
import ctypes, sys
from dcslam.allocator import _MallInfo2, fix_allocator
libc = ctypes.CDLL("libc.so.6")
libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, [ctypes.c_size_t]
libc.free.argtypes = [ctypes.c_void_p]
libc.mallinfo2.restype = _MallInfo2
mallinfo2 = libc.mallinfo2
fixed = fix_allocator(trim_bytes=0 if sys.argv[1] == "no-trim" else 32 << 20)
mallinfo2()
block = libc.malloc(3 << 20)
held = mallinfo2().arena
libc.free(block)
print(fixed, mallinfo2().arena > held - (1 << 20))
"""


@needs_mallinfo2
def test_the_top_of_the_heap_is_kept_for_the_next_frame():
    assert 3 << 20 < SLAM_TRIM_THRESHOLD
    assert _probe("no-trim", code=TRIM_PROBE) == "True False"   # glibc's 128 kB: the freed top goes back at once
    assert _probe("trim", code=TRIM_PROBE) == "True True"       # kept, for the next frame's blocks
    # a trim threshold in the environment is the user's choice: dcslam then sets neither (with both glibc's own, the
    # block is on the heap and the freed top goes back)
    assert _probe("trim", {TRIM_ENV: str(1 << 20)}, code=TRIM_PROBE).startswith("False ")
    assert _probe("trim", {TRIM_ENV: str(1 << 20), ENV: str(4 << 20)}, code=TRIM_PROBE) == "False False"


def test_nothing_is_set_for_a_threshold_of_zero():
    assert fix_allocator(0) is False and fix_allocator(-1) is False


@needs_mallinfo2
def test_heap_figures_see_a_block_in_use():
    # in a fresh interpreter, like the checks above: in this process, a free chunk that earlier tests left in the
    # heap may serve the block without a mapping of its own
    code = """
import ctypes
from dcslam.allocator import heap_mb, trim
libc = ctypes.CDLL("libc.so.6")
libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, [ctypes.c_size_t]
libc.free.argtypes = [ctypes.c_void_p]
held, used, mapped = heap_mb()
block = libc.malloc(64 << 20)  # far above any mmap threshold: its own mapping
grown = heap_mb()[2] - mapped
libc.free(block)
print(grown >= 64, 0 <= used <= held, trim())
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["True", "True", "True"]


# Which arena serves a thread's first allocation: the main one (its block lies in the main heap, which mallinfo2's
# ``arena`` figure grows by) or one of its own? With one arena for the process, a thread shares the main one.
ARENA_PROBE = """
import ctypes, sys, threading
from dcslam.allocator import fix_allocator
libc = ctypes.CDLL("libc.so.6")
libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, [ctypes.c_size_t]
fix_allocator(arenas=1 if sys.argv[1] == "one" else 0)
main = libc.malloc(64)
seen = []
thread = threading.Thread(target=lambda: seen.append(libc.malloc(64)))
thread.start()
thread.join()
# a block of a thread arena lies in that arena's own mapping, far (>= 1 MB aligned heaps) from the main heap
print(abs(seen[0] - main) < (64 << 20))
"""


@needs_mallinfo2
def test_threads_share_the_one_arena():
    assert _probe("one", code=ARENA_PROBE) == "True"
    assert _probe("glibc", code=ARENA_PROBE) == "False"
    assert _probe("one", {ARENA_ENV: "8"}, code=ARENA_PROBE) == "False"   # the user's choice stands
