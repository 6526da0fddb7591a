"""dcslam.native: the C kernels give the torch code's values bit for bit, and dcslam runs without them (no compiler,
a failed build, an unwritable cache, DCSLAM_NATIVE=0)."""
import os
import shutil
import subprocess
import sys

import pytest
import torch

import dcslam.native as native
from dcslam.geometry.camera import backproject
from dcslam.geometry.normals import _grid_normals

K = torch.tensor([[60.0, 0, 40.5], [0, 60.0, 15.5], [0, 0, 1]], dtype=torch.float64)
needs_compiler = pytest.mark.skipif(native._compiler() is None or not native.enabled(),
                                    reason="no C compiler on this machine, or DCSLAM_NATIVE=0")


def _bits(x: torch.Tensor) -> torch.Tensor:
    return x.view(torch.int32 if x.dtype == torch.float32 else torch.int64)


def _torch_path(monkeypatch, fn, *args):
    monkeypatch.setenv(native.NATIVE_ENV, "0")
    try:
        return fn(*args)
    finally:
        monkeypatch.setenv(native.NATIVE_ENV, "1")


def _street_depth(g: torch.Generator, H: int = 32, W: int = 81, holes: float = 0.2) -> torch.Tensor:
    """A ground plane, a wall with a depth edge, noise, holes, and ties in depth (rounded values): (1, 1, H, W)."""
    v, u = torch.meshgrid(torch.arange(H, dtype=torch.float64), torch.arange(W, dtype=torch.float64), indexing="ij")
    ground = 1.6 * 60.0 / (v - 15.5).clamp_min(0.5)
    depth = torch.where(u > W // 2, torch.full_like(ground, 7.0), ground.clamp_max(30.0))
    depth = depth + 0.02 * torch.randn(depth.shape, generator=g, dtype=torch.float64)
    depth[:, :5] = torch.round(depth[:, :5])
    depth[torch.rand(depth.shape, generator=g) < holes] = 0
    return depth[None, None]


@needs_compiler
def test_the_library_builds_and_loads_here():
    assert native.library() is not None


@needs_compiler
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("gap", [0.1, 0.05])
def test_grid_normals_are_the_torch_codes_bit_for_bit(monkeypatch, dtype, gap):
    """Holes, depth edges, image borders, isolated pixels, ties in the gap test and a batch of two."""
    g = torch.Generator().manual_seed(7)
    depth = torch.cat([_street_depth(g), _street_depth(g, holes=0.6)]).to(dtype)
    vertex = backproject(depth, K.to(dtype))
    valid = depth > 0
    ours, ours_ok = _grid_normals(vertex, valid, gap)
    theirs, theirs_ok = _torch_path(monkeypatch, _grid_normals, vertex, valid, gap)
    assert native.grid_normals(vertex, valid, gap) is not None          # the native path ran above
    assert torch.equal(ours_ok, theirs_ok) and 0 < int(ours_ok.sum()) < int(valid.sum())
    assert torch.equal(_bits(ours), _bits(theirs))


@needs_compiler
def test_grid_normals_of_a_full_size_frame(monkeypatch):
    """A full KITTI-size frame (375 x 1242): torch's square root is MKL's, which rounds some results otherwise than
    IEEE's; the kernel takes torch's, so the normals stay the same bits."""
    g = torch.Generator().manual_seed(3)
    depth = torch.nn.functional.interpolate(_street_depth(g, 47, 156, holes=0.0), size=(375, 1242)).float()
    vertex = backproject(depth, torch.tensor([[721.5, 0, 609.6], [0, 721.5, 172.9], [0, 0, 1]]))
    valid = depth > 0
    ours, ours_ok = _grid_normals(vertex, valid, 0.1)
    theirs, theirs_ok = _torch_path(monkeypatch, _grid_normals, vertex, valid, 0.1)
    assert torch.equal(ours_ok, theirs_ok) and torch.equal(_bits(ours), _bits(theirs))


def test_grid_normals_leave_autograd_and_other_dtypes_to_torch():
    vertex = backproject(_street_depth(torch.Generator().manual_seed(1)), K).requires_grad_()
    valid = vertex.detach()[:, 2:3] > 0
    assert native.grid_normals(vertex, valid, 0.1) is None
    normals, _ = _grid_normals(vertex, valid, 0.1)
    assert normals.requires_grad
    assert native.grid_normals(vertex.detach().half(), valid, 0.1) is None


def test_cross_probe_says_what_torch_cross_does():
    """The probe's verdict reproduces torch.cross on random vectors (fused: one rounding of a1 b2 - a2 b1)."""
    g = torch.Generator().manual_seed(0)
    a, b = torch.randn(3, 4096, generator=g), torch.randn(3, 4096, generator=g)
    wide = a.double(), b.double()
    if native.cross_fused(torch.float32):
        # a float32 product is exact in float64; one rounding of the difference of an exact and a rounded product
        expected = (wide[0][1] * wide[1][2] - (a[2] * b[1]).double()).float()
    else:
        expected = a[1] * b[2] - a[2] * b[1]
    assert torch.equal(torch.cross(a, b, dim=0)[0], expected)


RUN = """
import dcslam.native as native
print("none" if native.library() is None else "loaded")
"""


def _in_a_process(env_changes: dict) -> str:
    env = {**os.environ, **env_changes}
    done = subprocess.run([sys.executable, "-c", RUN], env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def test_turned_off_by_the_environment():
    assert _in_a_process({native.NATIVE_ENV: "0"}) == "none"


def test_no_compiler_or_a_failing_one_leaves_the_torch_code(tmp_path):
    assert _in_a_process({"CC": "false", "PATH": str(tmp_path), native.NATIVE_DIR_ENV: str(tmp_path)}) == "none"
    fails = shutil.which("false")
    assert _in_a_process({"CC": fails, native.NATIVE_DIR_ENV: str(tmp_path / "cache")}) == "none"
    assert not list((tmp_path / "cache").glob("*"))        # no half-written library left behind


def test_an_unwritable_cache_leaves_the_torch_code(tmp_path):
    """A cache folder that cannot be made (a file stands in its way: refused even to root)."""
    (tmp_path / "blocker").write_text("")
    assert _in_a_process({native.NATIVE_DIR_ENV: str(tmp_path / "blocker" / "cache")}) == "none"


@needs_compiler
def test_built_once_then_reused_and_a_damaged_file_rebuilt(tmp_path):
    assert _in_a_process({native.NATIVE_DIR_ENV: str(tmp_path)}) == "loaded"
    built = list(tmp_path.glob("dcslam-native-*.so"))
    assert len(built) == 1 and not list(tmp_path.glob("*.part"))
    stamp = built[0].stat().st_mtime_ns
    assert _in_a_process({native.NATIVE_DIR_ENV: str(tmp_path)}) == "loaded"
    assert built[0].stat().st_mtime_ns == stamp                   # reused, not rebuilt
    built[0].write_bytes(b"not a library")
    assert _in_a_process({native.NATIVE_DIR_ENV: str(tmp_path)}) == "loaded"
    assert built[0].read_bytes()[:4] == b"\x7fELF"


@needs_compiler
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("height,width,splat,points", [(40, 60, 1, 500), (37, 81, 2, 2000), (5, 7, 0, 10),
                                                       (20, 20, 3, 50), (1, 1, 1, 3), (9, 11, 1, 1)])
def test_zbuffer_window_is_the_torch_codes(monkeypatch, dtype, height, width, splat, points):
    """Depths rounded to a few values (ties at a centre and between centres), pixels reaching in from outside the
    window (down to -splat), several points per centre: the same covered pixels and the same point at each."""
    from dcslam.slam.pointmap import _zbuffer_window

    g = torch.Generator().manual_seed(height * 1000 + points)
    ids = torch.randperm(points * 3, generator=g)[:points]
    px = torch.stack([torch.randint(-splat, width + splat, (points,), generator=g),
                      torch.randint(-splat, height + splat, (points,), generator=g)], 1)
    z = torch.round(torch.rand(points, generator=g, dtype=torch.float64) * 5).to(dtype) + 1
    ours = _zbuffer_window(ids, px, z, height, width, splat)
    theirs = _torch_path(monkeypatch, _zbuffer_window, ids, px, z, height, width, splat)
    assert native.zbuffer_window(ids, px, z, height, width, splat) is not None
    assert torch.equal(ours[0], theirs[0]) and torch.equal(ours[1], theirs[1]) and ours[0].numel() > 0


@needs_compiler
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_rows_times_is_torch_mm(dtype):
    """Rows by a rotation's transpose (a strided view, as the poses give it): torch.mm's bits."""
    from dcslam.geometry.se3 import rows_times

    g = torch.Generator().manual_seed(5)
    points = (torch.randn(5000, 3, generator=g, dtype=torch.float64) * 40).to(dtype)
    R = torch.linalg.qr(torch.randn(3, 3, generator=g, dtype=torch.float64))[0].to(dtype)
    assert native.product_mode(dtype) is not None
    assert torch.equal(rows_times(points, R.T), torch.mm(points, R.T.contiguous()))
    assert native.rows_times(points.requires_grad_(), R.T) is None       # a gradient: torch's


MODES = """
import sys, torch
import dcslam, dcslam.native as native
g = torch.Generator().manual_seed(1)
ok = []
for dtype in (torch.float32, torch.float64):
    points = (torch.randn(3000, 3, generator=g, dtype=torch.float64) * 40).to(dtype)
    M = torch.randn(3, 3, generator=g, dtype=torch.float64).to(dtype)
    ok.append(native.product_mode(dtype) is not None and torch.equal(native.rows_times(points, M), torch.mm(points, M)))
print(all(ok))
"""


@needs_compiler
@pytest.mark.parametrize("cbwr", ["COMPATIBLE", "AUTO"])
def test_rows_times_follows_mkls_mode(cbwr):
    """MKL's reproducible kernels (dcslam's default) and its own (MKL_CBWR=AUTO) sum the three products otherwise;
    the probe finds which, and the kernel gives its bits under either."""
    done = subprocess.run([sys.executable, "-c", MODES], env={**os.environ, "MKL_CBWR": cbwr}, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "True"


def _icp_problem(dtype, weights: bool, gate: float):
    """Two frames of the analytic street at 0.5 m apart, the second's voxel-thinned sources against the first's
    rendered view: a PointToPlane problem with projective association."""
    from dcslam.slam.association import ProjectiveAssociation, view_from_frame
    from dcslam.slam.frame import FrameSettings, prepare_frame
    from dcslam.slam.odometry import PointToPlane
    from dcslam.slam.scene import StreetScene, kitti_K, lidar_mask, street_trajectory

    H, W = 64, 208
    scene, K = StreetScene(0), kitti_K(H, W)
    T = street_trajectory(2, step=0.5)
    mask = lidar_mask(H, W, row_step=3, col_step=2)
    settings = FrameSettings(normal_search=12)
    f0, f1 = (prepare_frame((scene.render(T[i], K, H, W) * mask).to(dtype), K.to(dtype), settings=settings)
              for i in range(2))
    pixels = torch.nonzero(f1.valid.reshape(-1)).squeeze(1)
    source = f1.vertex.reshape(-1, 3).index_select(0, pixels)
    normals = f1.normal.reshape(-1, 3).index_select(0, pixels)
    w = (torch.rand(source.shape[0], generator=torch.Generator().manual_seed(2), dtype=torch.float64) > 0.3).to(dtype)
    associate = ProjectiveAssociation().prepare(view_from_frame(f0, T[0].to(dtype)))
    problem = PointToPlane(source, normals, associate, gate, 0.866, weights=w if weights else None)
    return problem, T.to(dtype)


@needs_compiler
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("weights", [False, True])
@pytest.mark.parametrize("gate", [0.5, 0.1])
def test_point_to_plane_pairs_are_the_torch_codes(monkeypatch, dtype, weights, gate):
    """The pairs, residuals and targets of one linearisation at the prediction and at a pose off it, with and
    without per-point weights and with a narrow gate: the same bits as the torch code."""
    from dcslam.geometry.se3 import FAST_ROWS
    from dcslam.geometry.se3 import se3_exp

    problem, T = _icp_problem(dtype, weights, gate)
    for pose in (T[0], se3_exp(torch.tensor([0.02, -0.01, 0.05, 0.002, -0.004, 0.001], dtype=dtype)) @ T[0]):
        ours = problem.residuals(pose)
        theirs = _torch_path(monkeypatch, problem.residuals, pose)
        assert native.point_to_plane_pairs(problem.source, problem.source_normals, problem._usable, pose,
                                           problem.associate, gate, problem.cos_max_angle, FAST_ROWS) is not None
        assert ours[0].numel() > 0
        for a, b in zip(ours, theirs):
            assert a.dtype == b.dtype and torch.equal(a, b)
        # the normal equations from the native pass's Jacobian rows: the torch code's, bit for bit
        made = native.point_to_plane_pairs(problem.source, problem.source_normals, problem._usable, pose,
                                           problem.associate, gate, problem.cos_max_angle, FAST_ROWS, True)
        assert made[4] is not None and made[4].shape == (ours[0].numel(), 6)
        mine, yours = problem.linearize(pose), _torch_path(monkeypatch, problem.linearize, pose)
        assert mine.count == yours.count and mine.weight == yours.weight
        for a, b in ((mine.H, yours.H), (mine.g, yours.g), (mine.cost, yours.cost)):
            assert a.dtype == b.dtype == torch.float64 and torch.equal(a, b)


def test_point_to_plane_pairs_leave_gradients_to_torch():
    problem, T = _icp_problem(torch.float64, False, 0.5)
    pose = T[0].clone().requires_grad_()
    r, *_ = problem.residuals(pose)
    assert r.requires_grad


@needs_compiler
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("search", [3, 5, 12])
def test_scan_line_normals_are_the_torch_codes(monkeypatch, dtype, search):
    """LiDAR-like scan lines (every third row, every other column), holes, a depth edge, a batch of two: the normals
    of the valid pixels alone (point_normals, as sparse frames take them) and the images, the same bits."""
    from dcslam.geometry.normals import _scan_line_normals, point_normals

    g = torch.Generator().manual_seed(search)
    depth = torch.cat([_street_depth(g, holes=0.1), _street_depth(g, holes=0.4)]).to(dtype)
    depth[:, :, 1::3] = 0
    depth[..., 1::2] = 0
    vertex, valid = backproject(depth, K.to(dtype)), depth > 0
    ours = _scan_line_normals(vertex, valid, search, 0.1)
    theirs = _torch_path(monkeypatch, _scan_line_normals, vertex, valid, search, 0.1)
    assert torch.equal(ours[1], theirs[1]) and 0 < int(ours[1].sum()) < int(valid.sum())
    assert torch.equal(_bits(ours[0].contiguous()), _bits(theirs[0].contiguous()))
    idx = torch.nonzero(valid.reshape(-1)).squeeze(1)
    points = vertex.permute(0, 2, 3, 1).reshape(-1, 3).index_select(0, idx)
    assert native.point_normals(points, idx, (2, 32, 81), search, 0.1) is not None
    mine, yours = (point_normals(points, idx, (2, 32, 81), search, 0.1),
                   _torch_path(monkeypatch, point_normals, points, idx, (2, 32, 81), search, 0.1))
    assert torch.equal(mine[1], yours[1]) and torch.equal(_bits(mine[0]), _bits(yours[0]))


@needs_compiler
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("voxel", [0.2, 0.05, 0.3])
def test_voxel_keys_and_representatives_are_the_torch_codes(monkeypatch, dtype, voxel):
    """Many points per voxel, points on voxel borders, and points far enough out to be clamped."""
    from dcslam.slam.pointmap import voxel_keys, voxel_representatives

    g = torch.Generator().manual_seed(int(voxel * 100))
    points = (torch.randn(20000, 3, generator=g, dtype=torch.float64) * 3).to(dtype)
    points[:500] = torch.round(points[:500] / voxel) * voxel
    points[500:510], points[510:520] = 1e9, -1e9
    points[520:523], points[523:526] = 4e17, -4e17           # near int64's range once divided (0.05 m voxels)
    points[526:529] = 1e30                                    # beyond it: the CPU's conversion
    keys = voxel_keys(points, voxel)
    assert torch.equal(keys, _torch_path(monkeypatch, voxel_keys, points, voxel))
    first = voxel_representatives(points, voxel)
    assert torch.equal(first, _torch_path(monkeypatch, voxel_representatives, points, voxel))
    assert native.voxel_keys(points, voxel) is not None and 100 < first.numel() < 20000


class _Keys:
    """What assign_voxels reads of a map: its length and its voxel keys."""

    def __init__(self, keys: torch.Tensor):
        self.voxel_key = keys

    def __len__(self) -> int:
        return self.voxel_key.shape[0]


@needs_compiler
@pytest.mark.parametrize("map_points,frame_points", [(0, 500), (1000, 3000), (20000, 8000), (300, 0), (5, 100)])
def test_assign_voxels_is_the_torch_codes(monkeypatch, map_points, frame_points):
    """An empty map, a frame whose voxels are half in the map, points already matched (target >= 0), no frame
    points: the same targets and new keys (slots after the map's in the order of keys); the caller's target kept."""
    from dcslam.slam.pointmap import assign_voxels

    g = torch.Generator().manual_seed(map_points + frame_points)
    span = 4000 + 3 * map_points
    pm = _Keys(torch.randperm(span, generator=g)[:map_points] * 7)
    keys = torch.randint(0, span, (frame_points,), generator=g) * 7
    target = torch.where(torch.rand(frame_points, generator=g) < 0.5,
                         torch.randint(0, max(map_points, 1), (frame_points,), generator=g), -1)
    before = target.clone()
    ours = assign_voxels(pm, keys, target, 0.2)
    theirs = _torch_path(monkeypatch, assign_voxels, pm, keys, target, 0.2)
    assert torch.equal(target, before)
    assert torch.equal(ours[0], theirs[0]) and torch.equal(ours[1], theirs[1])
    assert native.voxel_lookup(pm.voxel_key, keys, target) is not None


@needs_compiler
def test_assign_voxels_with_a_key_twice_in_the_map_is_left_to_torch():
    keys = torch.tensor([7, 14, 7])
    assert native.voxel_lookup(keys, torch.tensor([7, 21]), torch.tensor([-1, -1])) is None


@needs_compiler
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("map_points,new_points,frame_points", [(0, 50, 200), (500, 100, 3000), (40, 0, 10)])
def test_merge_is_the_torch_codes(monkeypatch, dtype, map_points, new_points, frame_points):
    """Several frame points per slot, slots left untouched, new slots, weights of zero: every field the same."""
    from dcslam.slam.pointmap import PointMap, merge

    g = torch.Generator().manual_seed(map_points + frame_points)

    def rand(*shape):
        return torch.randn(*shape, generator=g, dtype=torch.float64).to(dtype)

    P, Q, F = map_points, new_points, frame_points
    unit = torch.nn.functional.normalize(rand(P, 3), dim=1)
    pm = PointMap(rand(P, 3) * 10, unit, rand(P, 3).abs(), rand(P).abs() * 3, rand(P).abs() * 0.1,
                  torch.randint(0, 5, (P,), generator=g), torch.randint(1, 5, (P,), generator=g),
                  torch.randperm(10 * P + 1, generator=g)[:P])
    target = torch.randint(0, max(P + Q, 1), (F,), generator=g) if P + Q else torch.zeros(0, dtype=torch.int64)
    weight = rand(F).abs()
    weight[::7] = 0
    args = (pm, target, torch.randperm(10 * Q + 1, generator=g)[:Q] + 10 * P + 1, rand(F, 3) * 10,
            torch.nn.functional.normalize(rand(F, 3), dim=1), rand(F, 3).abs(), rand(F).abs() * 0.1, weight, 7)
    ours, theirs = merge(*args), _torch_path(monkeypatch, merge, *args)
    assert native.merge_averages(pm, target, Q, *args[3:8]) is not None
    for name in ("points", "normals", "colors", "confidence", "radius", "last_seen", "observations", "voxel_key"):
        a, b = getattr(ours, name), getattr(theirs, name)
        assert a.dtype == b.dtype and torch.equal(*((_bits(a), _bits(b)) if a.is_floating_point() else (a, b))), name


@pytest.mark.skipif(not hasattr(os, "getuid"), reason="POSIX permissions")
def test_a_folder_others_may_write_is_not_trusted(tmp_path, monkeypatch):
    """A library is loaded only from a folder of this user's that no one else may write."""
    monkeypatch.delenv(native.NATIVE_DIR_ENV, raising=False)
    shared = tmp_path / "shared"
    shared.mkdir()
    shared.chmod(0o777)
    assert not native._trusted(shared)
    shared.chmod(0o700)
    assert native._trusted(shared)
    assert not native._trusted(tmp_path / "missing")


# The z-buffer of a full KITTI window, first with points in its top rows (the call that allocates the kernel's
# memory), then in its bottom rows: the minor page faults of the second call, in a fresh interpreter.
FAULTS = """
import resource, torch
import dcslam.native as native
H, W = 375, 1242
def call(rows):
    g = torch.Generator().manual_seed(rows.start)
    n = 20000
    u = torch.randint(0, W, (n,), generator=g)
    px = torch.stack([u, torch.randint(rows.start, rows.stop, (n,), generator=g)], 1)
    z = torch.rand(n, generator=g) + 1
    assert native.zbuffer_window(torch.arange(n), px, z, H, W, 1, (H + 2) * (W + 2)) is not None
call(range(0, 40))
call(range(0, 40))
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
call(range(300, 375))
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


@needs_compiler
def test_the_zbuffer_writes_its_memory_when_it_takes_it():
    """Memory the kernel took but never wrote would be the shared zero page until first written: each new part of
    the window it reaches would cost a read fault, then a copy-on-write fault that flushes the TLB of every core
    running the process. Written once when taken, the bottom rows cost the outputs' pages only (120 here); with
    malloc and memset(0) folded into calloc by the compiler they cost 2,440."""
    done = subprocess.run([sys.executable, "-c", FAULTS], capture_output=True, text=True, check=True)
    assert int(done.stdout.strip()) < 600, done.stdout


@needs_compiler
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("bounds", ["defaults", (0.7, 1.3)])   # 0.1 rounds up in float32, 0.7 and 1.3 down
def test_depth_range_is_the_torch_codes(dtype, bounds):
    """prepare_frame's range gate: depths at the bounds as the depth's type holds them and one step either side,
    zeros, negative zero, NaN and infinities, random depths: the same mask, the same bits kept and the same count."""
    from dcslam.native import depth_range
    from dcslam.slam.frame import FrameSettings

    lo, hi = (FrameSettings().min_depth, FrameSettings().max_depth) if bounds == "defaults" else bounds
    g = torch.Generator().manual_seed(7)
    edges = torch.tensor([lo, hi], dtype=dtype)
    special = torch.cat([edges, torch.nextafter(edges, edges - 1), torch.nextafter(edges, edges + 1),
                         torch.tensor([0.0, -0.0, float("nan"), float("inf"), -float("inf"), -1.0], dtype=dtype)])
    depth = torch.cat([special, (torch.rand(5038, generator=g, dtype=torch.float64) * 100).to(dtype)])
    depth = depth[torch.randperm(depth.numel(), generator=g)].reshape(1, 1, 50, -1)
    inside, kept, count = depth_range(depth, lo, hi)
    expected = (depth >= lo) & (depth <= hi)
    assert torch.equal(inside, expected) and count == int(expected.sum())
    zeroed = torch.where(expected, depth, torch.zeros((), dtype=dtype))
    assert torch.equal(_bits(kept), _bits(zeroed))
    assert depth_range(depth.requires_grad_(), lo, hi) is None              # a gradient: the torch code's
