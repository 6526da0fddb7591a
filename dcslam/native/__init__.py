"""Native kernels: a few of dcslam's hot loops in C, built on first use with the system's C compiler.

Contract: a kernel gives the values of the torch code it stands for, bit for bit, on this machine (the tests under
``tests/native/`` compare them), so whether it is used changes the speed only. Where no C compiler is found, the
build fails, or ``DCSLAM_NATIVE=0`` is set, :func:`library` returns None and the callers run their torch code.

Why C through ctypes and not a compiled extension: nothing to build at install (an editable install keeps working),
no torch headers (the build takes about 1.5 s, once), and a machine without a compiler still runs dcslam.

The library is built once per machine and source into ``DCSLAM_NATIVE_DIR`` (default ``$XDG_CACHE_HOME/dcslam`` or
``~/.cache/dcslam``, else the system's temporary folder when that is not writable), written under a temporary name
and renamed, so that processes building it at once never load a half-written file.
"""
from __future__ import annotations

import ctypes
import hashlib
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

#: The environment variable that turns the native kernels off (``0``).
NATIVE_ENV = "DCSLAM_NATIVE"
#: The environment variable naming the folder of the built library.
NATIVE_DIR_ENV = "DCSLAM_NATIVE_DIR"

SOURCE = Path(__file__).with_name("kernels.c")
#: -ffp-contract=off: no product is fused into a sum unless the source says so (torch's own kernels are the rule)
FLAGS = ("-O3", "-std=c11", "-ffp-contract=off", "-fno-math-errno", "-fPIC", "-shared")
VERSION = 2

_lock = threading.Lock()
_loaded: dict[str, object] = {}


def enabled() -> bool:
    """Whether the native kernels may be used (``DCSLAM_NATIVE`` is not ``0``)."""
    return os.environ.get(NATIVE_ENV, "1") != "0"


def _compiler() -> str | None:
    for name in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def _folders() -> list[Path]:
    if os.environ.get(NATIVE_DIR_ENV):
        return [Path(os.environ[NATIVE_DIR_ENV])]
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "dcslam"
    return [cache, Path(tempfile.gettempdir()) / f"dcslam-native-{os.getuid() if hasattr(os, 'getuid') else 0}"]


def _trusted(folder: Path) -> bool:
    """Whether a library in ``folder`` may be loaded: the folder is this user's and no one else may write it (a
    shared temporary folder could otherwise hold another user's library under the expected name)."""
    if not hasattr(os, "getuid") or os.environ.get(NATIVE_DIR_ENV):
        return True
    try:
        info = folder.stat()
    except OSError:
        return False
    return info.st_uid == os.getuid() and not info.st_mode & 0o022


def _build(compiler: str, again: bool = False) -> Path | None:
    """The built library's path (built now when missing, or when ``again``: a cached file that would not load), or
    None when it cannot be built or written."""
    source = SOURCE.read_bytes()
    key = hashlib.sha256(source + " ".join(FLAGS).encode() + compiler.encode() + platform.machine().encode() +
                         sys.platform.encode()).hexdigest()[:16]
    for folder in _folders():
        target = folder / f"dcslam-native-{key}.so"
        try:
            folder.mkdir(mode=0o700, parents=True, exist_ok=True)
        except OSError:
            continue
        if not _trusted(folder):
            continue
        if target.is_file() and not again:
            return target
        try:
            fd, partial = tempfile.mkstemp(prefix=target.name + ".", suffix=".part", dir=folder)
            os.close(fd)
        except OSError:
            continue
        try:
            done = subprocess.run([compiler, *FLAGS, "-o", partial, str(SOURCE), "-lm"], capture_output=True,
                                  timeout=120)
            if done.returncode != 0:
                return None
            os.replace(partial, target)
            return target
        except (OSError, subprocess.SubprocessError):
            continue
        finally:
            if os.path.exists(partial):
                os.unlink(partial)
    return None


def library():
    """The loaded native library (a :class:`ctypes.CDLL` with its functions' types set), or None: turned off, no
    compiler, or the build failed. Built and loaded once per process."""
    if not enabled():
        return None
    with _lock:
        if "lib" not in _loaded:
            _loaded["lib"] = _load()
        return _loaded["lib"]


def _load():
    compiler = _compiler()
    lib = None
    for again in (False, True):      # a cached file that does not load (damaged, another machine's) is rebuilt once
        path = _build(compiler, again) if compiler else None
        if path is None:
            return None
        try:
            lib = ctypes.CDLL(str(path))
            lib.dcslam_native_version.restype = ctypes.c_int
            if lib.dcslam_native_version() == VERSION:
                break
        except (OSError, AttributeError):
            pass
        lib = None
    if lib is None:
        return None
    for name, (argtypes, restype) in _signatures().items():
        function = getattr(lib, "dcslam_" + name)
        function.argtypes, function.restype = argtypes, restype
    return lib


def _signatures() -> dict[str, tuple[list, object]]:
    """Each exported function of kernels.c (less its ``dcslam_`` prefix) -> (argument types, result type)."""
    p, i64, i32 = ctypes.c_void_p, ctypes.c_int64, ctypes.c_int
    out = {"take_pairs": ([p, p, i64], None), "first_of_each": ([p, i64, p], i64),
           "voxel_lookup": ([p, i64, p, p, i64, p, p, p, p, p], i64)}
    for suffix, real in (("f32", ctypes.c_float), ("f64", ctypes.c_double)):
        out.update({f"{name}_{suffix}": types for name, types in {
            "grid_normals": ([p, p, i64, i64, real, p, p, p, i32], None),
            "grid_finish": ([p, p, p, p, i64, p], None),
            "point_normals": ([p, p, i64, i64, i64, i64, i64, real, p, p, p, p, p, i32], None),
            "point_finish": ([p, p, p, i64, p], None),
            "zbuffer_window": ([p, p, p, i64, i64, i64, i64, i64], i64),
            "voxel_keys": ([p, i64, real, p], None),
            "merge": ([i64, i64, p, i64] + [p] * 17, None),
            "rows_times": ([p, p, i64, p, i32], None),
            "depth_range": ([p, i64, real, real, p, p], i64),
            "pairs": ([p, p, p, i64, p, p, p, p, real, real, real, real, i64, i64, p, p, real, real, i32, i32,
                       p, p, p, p, p, i32, p], i64),
        }.items()})
    return out


def _kernel(name: str, dtype=None):
    """The loaded function ``dcslam_<name>`` (with ``_f32`` or ``_f64`` for a float ``dtype``), or None without the
    library."""
    lib = library()
    if lib is None:
        return None
    if dtype is not None:
        import torch

        name += "_f32" if dtype == torch.float32 else "_f64"
    return getattr(lib, "dcslam_" + name)


def cross_fused(dtype) -> bool:
    """Whether torch.cross on this machine rounds ``a1 b2 - a2 b1`` once (a fused multiply-add, as torch's kernels
    built for AVX2 do) rather than each product apart; cached per dtype. ``(1 + 2^-12)^2 - (1 + 2^-11)`` is 2^-24
    fused and 0 apart (in float64, ``(1 + 2^-27)^2 - (1 + 2^-26)``: 2^-54 and 0)."""
    key = ("cross", str(dtype))
    if key not in _loaded:
        import torch

        e = 12 if dtype == torch.float32 else 27
        x, y = 1 + 2.0 ** -e, 1 + 2.0 ** -(e - 1)
        a = torch.tensor([0.0, x, y], dtype=dtype)
        b = torch.tensor([1.0, 0.0, x], dtype=dtype)
        _loaded[key] = float(torch.cross(a, b, dim=0)[0]) != 0.0
    return bool(_loaded[key])


def grid_normals(vertex, valid, max_relative_gap: float):
    """The native :func:`dcslam.geometry.normals._grid_normals`, or None when it does not apply here (no library;
    a tensor not on the CPU, not float32/float64, or needing a gradient): the caller then runs the torch code.
    Shape: vertex (B, 3, H, W), valid (B, 1, H, W) bool -> (normals (B, 3, H, W), valid (B, 1, H, W) bool)."""
    import torch

    if not _plain(vertex) or (cross := _kernel("grid_normals", vertex.dtype)) is None:
        return None
    finish = _kernel("grid_finish", vertex.dtype)
    B, _, H, W = vertex.shape
    vertex = vertex.detach().contiguous()
    valid = valid.contiguous()
    normal = torch.empty_like(vertex)
    square = torch.empty(B, 1, H, W, dtype=vertex.dtype)
    ok = torch.empty(B, 1, H, W, dtype=torch.bool)
    # the gap as torch multiplies it: a Python float times a 0-d tensor of the vertex's dtype
    gap = float(torch.tensor(max_relative_gap, dtype=vertex.dtype))
    fused = int(cross_fused(vertex.dtype))
    for b in range(B):
        cross(vertex[b].data_ptr(), valid[b].data_ptr(), H, W, gap, normal[b].data_ptr(), square[b].data_ptr(),
              ok[b].data_ptr(), fused)
    root = torch.sqrt(square)   # torch's root, as the torch code takes it (MKL's: not always IEEE's)
    for b in range(B):
        finish(vertex[b].data_ptr(), valid[b].data_ptr(), ok[b].data_ptr(), root[b].data_ptr(), H * W,
               normal[b].data_ptr())
    return normal, ok


def point_normals(points, idx, shape: tuple[int, int, int], search: int, max_relative_gap: float):
    """The native :func:`dcslam.geometry.normals.point_normals`, or None where it does not apply (no library; not
    float32 / float64 on the CPU; a gradient): the caller runs the torch code. Shape: points (N, 3), idx (N,) int64
    flat indices into ``shape`` (B, H, W) in raster order -> (normals (N, 3), ok (N,) bool)."""
    import torch

    if (not _plain(points) or idx.dtype != torch.int64 or idx.device.type != "cpu" or idx.numel() == 0
            or (cross := _kernel("point_normals", points.dtype)) is None):
        return None
    finish = _kernel("point_finish", points.dtype)
    B, H, W = shape
    N, dtype = idx.numel(), points.dtype
    points, idx = points.detach().contiguous(), idx.contiguous()
    normal, square = torch.empty(N, 3, dtype=dtype), torch.empty(N, dtype=dtype)
    ok = torch.empty(N, dtype=torch.bool)
    order, count = torch.empty(N, dtype=torch.int64), torch.empty(B * W + 1, dtype=torch.int64)
    cross(points.data_ptr(), idx.data_ptr(), N, B, H, W, search, _in_dtype(dtype)(max_relative_gap),
          normal.data_ptr(), square.data_ptr(), ok.data_ptr(), order.data_ptr(), count.data_ptr(),
          int(cross_fused(dtype)))
    root = torch.sqrt(square)   # torch's root, as the torch code takes it (MKL's: not always IEEE's)
    finish(points.data_ptr(), ok.data_ptr(), root.data_ptr(), N, normal.data_ptr())
    return normal, ok


def depth_range(depth, lo: float, hi: float):
    """The native range gate of :func:`dcslam.slam.frame.prepare_frame`, or None where it does not apply (no library;
    not float32 / float64 on the CPU; a gradient): the caller runs the torch code. Shape: depth (...) -> (in range
    (...) bool: ``lo <= depth <= hi``, the depth with the others at +0 (...), how many are in range)."""
    import torch

    if not _plain(depth) or (kernel := _kernel("depth_range", depth.dtype)) is None:
        return None
    depth = depth.detach().contiguous()
    inside, kept = torch.empty(depth.shape, dtype=torch.bool), torch.empty_like(depth)
    cast = _in_dtype(depth.dtype)
    count = kernel(depth.data_ptr(), depth.numel(), cast(lo), cast(hi), inside.data_ptr(), kept.data_ptr())
    return inside, kept, int(count)


def voxel_keys(points, voxel_size: float):
    """The native :func:`dcslam.slam.pointmap.voxel_keys` (``voxel_size`` > 0, checked by the caller), or None where
    it does not apply (no library; not float32 / float64 on the CPU). Shape: (P, 3) -> (P,) int64."""
    import torch

    if (not _plain(points) or points.ndim != 2 or points.shape[1] != 3
            or (kernel := _kernel("voxel_keys", points.dtype)) is None):
        return None
    points = points.detach().contiguous()
    keys = torch.empty(points.shape[0], dtype=torch.int64)
    kernel(points.data_ptr(), points.shape[0], _in_dtype(points.dtype)(voxel_size), keys.data_ptr())
    return keys


def first_of_each(keys):
    """Indices of the first of each distinct key, increasing (:func:`dcslam.slam.pointmap.voxel_representatives`
    after its keys), or None where it does not apply. keys: (N,) int64 >= 0 on the CPU -> (Q,) int64."""
    import torch

    if (keys.dtype != torch.int64 or keys.device.type != "cpu" or keys.ndim != 1
            or (kernel := _kernel("first_of_each")) is None):
        return None
    keys = keys.contiguous()
    first = torch.empty(keys.shape[0], dtype=torch.int64)
    count = kernel(keys.data_ptr(), keys.shape[0], first.data_ptr())
    if count < 0:
        raise MemoryError("dcslam.native: no memory for the voxels' table")
    return first[:count].clone()


def voxel_lookup(map_keys, keys, target):
    """What :func:`dcslam.slam.pointmap.assign_voxels` looks up, by hashes of the keys: (free (M,) the frame points
    without a target, voxel_of (M,) each one's voxel, voxels (D,) the distinct voxels in order of first appearance,
    slot (D,) each one's map point or -1), or None where it does not apply (no library; not on the CPU; a key twice
    in the map). Shape: map_keys (P,), keys (F,), target (F,) int64."""
    import torch

    if (any(t.dtype != torch.int64 or t.device.type != "cpu" for t in (map_keys, keys, target))
            or (kernel := _kernel("voxel_lookup")) is None):
        return None
    map_keys, keys, target = map_keys.contiguous(), keys.contiguous(), target.contiguous()
    F = keys.shape[0]
    free, voxel_of, voxels, slot = (torch.empty(F, dtype=torch.int64) for _ in range(4))
    n_free = ctypes.c_int64(0)
    D = kernel(map_keys.data_ptr(), map_keys.shape[0], keys.data_ptr(), target.data_ptr(), F, free.data_ptr(),
               voxel_of.data_ptr(), voxels.data_ptr(), slot.data_ptr(), ctypes.byref(n_free))
    if D == -2:
        return None
    if D < 0:
        raise MemoryError("dcslam.native: no memory for the voxels' tables")
    M = n_free.value
    return free[:M], voxel_of[:M], voxels[:D], slot[:D]


def merge_averages(pm, target, new_count: int, points, normals, colors, radius, weight):
    """The sums and averages of :func:`dcslam.slam.pointmap.merge` in one pass: (points, normals, colors (S, 3),
    radius (S,), confidence (S,), observed (S,) int64, square (S,)), S = len(pm) + new_count, the normals averaged
    but not yet divided by the root of ``square``; or None where it does not apply (no library; not one CPU float
    dtype; a gradient). Shape: target (F,) int64, points / normals / colors (F, 3), radius, weight (F,)."""
    import torch

    old = (pm.points, pm.normals, pm.colors, pm.radius, pm.confidence)
    if (not _plain(points, normals, colors, radius, weight, *old) or target.dtype != torch.int64
            or (kernel := _kernel("merge", points.dtype)) is None):
        return None
    dtype, P, F = points.dtype, len(pm), target.shape[0]
    S = P + new_count
    args = [t.detach().contiguous() for t in (weight, pm.confidence, points, normals, colors, radius, pm.points,
                                                pm.normals, pm.colors, pm.radius)]
    out = [torch.empty(S, 3, dtype=dtype) for _ in range(3)] + [torch.empty(S, dtype=dtype) for _ in range(2)]
    observed, square = torch.empty(S, dtype=torch.int64), torch.empty(S, dtype=dtype)
    target = target.contiguous()
    kernel(P, new_count, target.data_ptr(), F, *(t.data_ptr() for t in args), *(t.data_ptr() for t in out),
           observed.data_ptr(), square.data_ptr())
    return (*out, observed, square)


def zbuffer_window(ids, px, z, height: int, width: int, splat: int, capacity: int = 0):
    """The native :func:`dcslam.slam.pointmap._zbuffer_window`, or None where it does not apply (no library; not
    on the CPU; depths not float32/float64): the caller runs the torch code. ``capacity``: the padded pixels of the
    whole image (0: unknown), the memory the kernel keeps from the first call. Shape: ids (N,) int64, px (N, 2)
    int64, z (N,) -> (pixels (C,) flat indices into the window in raster order, points (C,) int64)."""
    import torch

    if not _plain(z) or px.dtype != torch.int64 or (kernel := _kernel("zbuffer_window", z.dtype)) is None:
        return None
    ids, px, z = ids.contiguous(), px.contiguous(), z.detach().contiguous()
    count = kernel(ids.data_ptr(), px.data_ptr(), z.data_ptr(), z.shape[0], height, width, splat, capacity)
    if count < 0:
        raise MemoryError("dcslam.native: no memory for the z-buffer")
    pix, hit = torch.empty(count, dtype=torch.int64), torch.empty(count, dtype=torch.int64)
    _kernel("take_pairs")(pix.data_ptr(), hit.data_ptr(), count)
    return pix, hit


def _rows_times_raw(points, M, mode: int):
    import torch

    out = torch.empty_like(points)
    _kernel("rows_times", points.dtype)(points.data_ptr(), M.data_ptr(), points.shape[0], out.data_ptr(), mode)
    return out


def product_mode(dtype) -> int | None:
    """How torch.mm of (N, 3) rows by a 3 x 3 matrix sums on this machine, as the kernels' ``mode``: 0 (each
    product rounded, summed left to right: MKL's reproducible mode, which dcslam sets), 1 (fused multiply-adds: MKL's
    own kernels), None (neither, or no library: the torch code runs). Found once per dtype on random rows."""
    if library() is None:
        return None
    key = ("mm", str(dtype))
    if key not in _loaded:
        import torch

        g = torch.Generator().manual_seed(0)
        points = (torch.randn(4096, 3, generator=g, dtype=torch.float64) * 30).to(dtype)
        M = torch.linalg.qr(torch.randn(3, 3, generator=g, dtype=torch.float64))[0].to(dtype).contiguous()
        expected = torch.mm(points, M)
        _loaded[key] = next((mode for mode in (0, 1) if torch.equal(_rows_times_raw(points, M, mode), expected)),
                            None)
    return _loaded[key]


def _plain(*tensors) -> bool:
    """CPU float32 / float64 tensors of one dtype, none needing a gradient."""
    import torch

    dtype = tensors[0].dtype
    return (dtype in (torch.float32, torch.float64) and all(t.dtype == dtype and t.device.type == "cpu"
                                                            for t in tensors)
            and not (torch.is_grad_enabled() and any(t.requires_grad for t in tensors)))


def _in_dtype(dtype):
    """A Python number as it meets a tensor of ``dtype`` in torch's arithmetic (cast to that dtype)."""
    import numpy as np
    import torch

    return (lambda x: float(np.float32(x))) if dtype == torch.float32 else float


def rows_times(points, M):
    """The native ``torch.mm(points, M)`` of (N, 3) rows and a 3 x 3 matrix, or None where it does not apply."""
    if not _plain(points, M) or points.ndim != 2 or points.shape[1] != 3 or M.shape != (3, 3):
        return None
    mode = product_mode(points.dtype)
    if mode is None:
        return None
    return _rows_times_raw(points.detach().contiguous(), M.detach().contiguous(), mode)


def point_to_plane_pairs(source, normals, usable, T, prepared, max_distance: float, cos_max_angle: float,
                         min_rows: int, jacobian: bool = False):
    """The native :meth:`dcslam.slam.odometry.PointToPlane.residuals` with projective association ``prepared``
    (``ProjectiveAssociation._Prepared``) -> (residuals (M,), source index (M,), target points (M, 3), target
    normals (M, 3), Jacobian (M, 6) float64 or None), or None where it does not apply (no library or product mode;
    a gradient; fewer than ``min_rows`` sources or pairs, which the torch code multiplies by another kernel than
    torch.mm: it runs). ``jacobian``: also :meth:`~dcslam.slam.odometry.PointToPlane.linearize`'s Jacobian of the
    pairs, ``cat(n @ R, cross(source, n @ R)).double()``, where M is at least ``min_rows`` (None otherwise: below
    that the torch code's product takes another kernel)."""
    import torch

    table, index = prepared.table, prepared.index
    if not _plain(source, normals, T, table) or source.shape[0] < min_rows:
        return None
    mode = product_mode(source.dtype)
    if mode is None:
        return None
    dtype, F = source.dtype, source.shape[0]
    source, normals = source.detach().contiguous(), normals.detach().contiguous()
    R, t = T.detach()[:3, :3].contiguous(), T.detach()[:3, 3].contiguous()
    RrT, tr = prepared.R_T.contiguous(), prepared.t.contiguous()
    if RrT.dtype != dtype or index.dtype != torch.int64:
        return None
    table = table.detach().contiguous()
    usable = None if usable is None else usable.contiguous()
    r, src = torch.empty(F, dtype=dtype), torch.empty(F, dtype=torch.int64)
    q, n = torch.empty(F, 3, dtype=dtype), torch.empty(F, 3, dtype=dtype)
    paired = ctypes.c_int64(0)
    J = torch.empty(F, 6, dtype=torch.float64) if jacobian else None
    real = _in_dtype(dtype)
    kernel = _kernel("pairs", dtype)
    count = kernel(source.data_ptr(), normals.data_ptr(), None if usable is None else usable.data_ptr(), F,
                   R.data_ptr(), t.data_ptr(), RrT.data_ptr(), tr.data_ptr(), real(prepared.fx), real(prepared.fy),
                   real(prepared.cx), real(prepared.cy), prepared.height, prepared.width, index.data_ptr(),
                   table.data_ptr(), real(max_distance ** 2), real(cos_max_angle), mode,
                   int(dtype == torch.float64 or prepared.few_pixels), r.data_ptr(), src.data_ptr(), q.data_ptr(),
                   n.data_ptr(), ctypes.byref(paired), int(cross_fused(dtype)), None if J is None else J.data_ptr())
    if paired.value < min_rows:
        return None              # the torch code rotates so few normals with another kernel: its bits, not ours
    return r[:count], src[:count], q[:count], n[:count], None if J is None or count < min_rows else J[:count]
