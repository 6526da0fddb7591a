"""Ray casting: known hits, and the per-shape ray rectangles never leave out a ray that hits."""
import numpy as np
import pytest

from dcslam.geometry.rotations import rotation_from_rpy
from dcslam.synth.raycast import NO_HIT, CameraGrid, cast, intersect, intersect_terrain, local_normals
from dcslam.synth.street.scene import BOX, CYLINDER, ELLIPSOID, Shape
from dcslam.synth.street.sensors import make_lidar_grid
from dcslam.synth.street.trajectory import Terrain

FLAT = Terrain(amplitude=np.zeros(1), wave=np.ones((1, 2)), phase=np.zeros(1))


def shape(kind, center, half, yaw=0.0, pitch=0.0):
    return Shape(kind, rotation_from_rpy([0.0], [pitch], [yaw])[0], np.asarray(center, float), np.asarray(half, float),
                 0, np.ones(3))


class TestIntersect:
    def test_box_known_answer(self):
        d = np.array([[1.0, 0, 0], [-1.0, 0, 0], [1.0, 0.5, 0], [0, 1.0, 0]], dtype=np.float32)
        t = intersect(shape(BOX, [0, 0, 0], [1, 2, 3]), np.array([-5.0, 0, 0]), d)
        np.testing.assert_allclose(t[:3], [4.0, np.inf, 4.0])
        assert t[3] == np.inf

    def test_cylinder_side_and_cap(self):
        d = np.array([[1.0, 0, 0], [0, 0, -1.0], [1.0, 0, 0.0]], dtype=np.float32)
        cyl = shape(CYLINDER, [0, 0, 0], [0.5, 0.5, 1.0])
        np.testing.assert_allclose(intersect(cyl, np.array([-3.0, 0, 0]), d[:1]), [2.5], rtol=1e-6)
        np.testing.assert_allclose(intersect(cyl, np.array([0.2, 0, 3.0]), d[1:2]), [2.0], rtol=1e-6)
        assert intersect(cyl, np.array([-3.0, 0, 1.5]), d[2:]) == np.inf

    def test_ellipsoid(self):
        t = intersect(shape(ELLIPSOID, [0, 0, 0], [2, 1, 1]), np.array([-5.0, 0, 0]),
                      np.array([[1.0, 0, 0], [0, 1.0, 0]], dtype=np.float32))
        np.testing.assert_allclose(t, [3.0, np.inf], rtol=1e-6)

    @pytest.mark.parametrize("kind", [BOX, CYLINDER, ELLIPSOID])
    def test_normals_are_unit_and_face_outwards(self, kind):
        s = shape(kind, [0, 0, 0], [1.0, 1.5, 2.0])
        rng = np.random.default_rng(0)
        d = rng.normal(size=(500, 3)).astype(np.float32)
        o = np.array([6.0, -4.0, 3.0])
        t = intersect(s, o, -o[None] / 7 + 0.3 * d)
        hit = np.isfinite(t)
        p = (o + t[hit, None] * (-o[None] / 7 + 0.3 * d[hit])).astype(np.float32)
        n = local_normals(s, p)
        np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1, atol=1e-5)
        assert np.all(np.einsum("ij,ij->i", n, p) > 0)


def test_terrain_hit_on_a_slope():
    wave = np.array([[2 * np.pi / 400.0, 0.0]])
    terrain = Terrain(amplitude=np.array([2.0]), wave=wave, phase=np.array([0.3]))
    o = np.array([10.0, 5.0, float(terrain.height(10.0, 5.0)) + 1.73])
    rng = np.random.default_rng(1)
    d = np.concatenate([rng.uniform(-1, 1, (2000, 2)), rng.uniform(-0.3, -0.01, (2000, 1))], 1).astype(np.float32)
    t = intersect_terrain(terrain, o, d, np.full(2000, 500.0, np.float32))
    hit = np.isfinite(t)
    assert hit.mean() > 0.9
    p = o + t[hit, None].astype(np.float64) * d[hit]
    np.testing.assert_allclose(p[:, 2], terrain.height(p[:, 0], p[:, 1]), atol=5e-3)


@pytest.mark.parametrize("grid_kind", ["camera", "lidar"])
def test_ray_rectangles_are_conservative(grid_kind):
    """Casting with rectangles equals brute force over every ray, for shapes all around the sensor."""
    if grid_kind == "camera":
        grid = CameraGrid(np.array([[60.0, 0, 48], [0, 60.0, 32], [0, 0, 1]]), 96, 64)
    else:
        grid = make_lidar_grid(1.0)
    rng = np.random.default_rng(3)
    T = np.eye(4)
    T[:3, :3] = rotation_from_rpy([0.02], [-0.03], [0.4])[0] @ (np.array([[0, 0, 1.0], [-1, 0, 0], [0, -1, 0]])
                                                             if grid_kind == "camera" else np.eye(3))
    T[:3, 3] = [0, 0, 1.7]
    shapes = [shape(int(rng.integers(3)), np.append(rng.uniform(-25, 25, 2), rng.uniform(-1, 6)),
                    rng.uniform(0.2, 6, 3), yaw=rng.uniform(-3, 3), pitch=rng.uniform(-0.3, 0.3)) for _ in range(40)]
    shapes = [s for s in shapes if np.linalg.norm(s.center - T[:3, 3]) > s.radius + 0.5]
    t_fast, index, _ = cast(grid, T, shapes, FLAT, 100.0)
    # brute force
    d = grid.dirs.reshape(-1, 3) @ T[:3, :3].T.astype(np.float32)
    best = np.full(len(d), np.inf, np.float32)
    for s in shapes:
        t = intersect(s, s.R_world_obj.T @ (T[:3, 3] - s.center), d @ s.R_world_obj.astype(np.float32))
        best = np.minimum(best, t)
    ground = intersect_terrain(FLAT, T[:3, 3], d, np.full(len(d), 1e4, np.float32))
    best = np.minimum(best, ground)
    best[best * grid.lengths.ravel() > 100.0] = np.inf
    np.testing.assert_allclose(t_fast.ravel(), best, rtol=1e-4)  # float32 products in another order
    assert np.sum(index >= 0) > 50 and np.any(index == NO_HIT)


def test_camera_rectangles_of_all_boxes_at_once_are_those_of_each_box():
    """The camera's rects_of (the boxes wholly in front of it at once) gives each box the rectangle rects gives it,
    for boxes in front of the camera, behind it and across its near plane (a negative fy, as the indoor rooms')."""
    from dcslam.synth.shapes import corners_in

    grid = CameraGrid(np.array([[60.0, 0, 48], [0, -60.0, 32], [0, 0, 1]]), 96, 64)
    rng = np.random.default_rng(11)
    shapes = [shape(int(rng.integers(3)), rng.uniform(-20, 20, 3), rng.uniform(0.05, 8, 3), yaw=rng.uniform(-3, 3),
                    pitch=rng.uniform(-1, 1)) for _ in range(400)]
    shapes += [shape(BOX, [0, 0, 0.3], [1, 1, 0.2]), shape(BOX, [0, 0, -0.3], [1, 1, 0.2])]  # across the plane
    corners = corners_in(shapes, np.eye(4))
    np.testing.assert_allclose(corners, [s.corners() for s in shapes], rtol=0, atol=1e-12)
    front = corners[..., 2] > grid.near
    assert front.all(1).sum() > 100 and (front.any(1) & ~front.all(1)).sum() > 50 and (~front.any(1)).sum() > 100
    assert grid.rects_of(corners) == [grid.rects(c) for c in corners]
    assert grid.rects_of(corners[:0]) == []


def test_lidar_rectangles_hold_every_ray_that_hits_each_box_and_little_else():
    """Every LiDAR ray that hits a box (brute force over the whole grid) lies in one of the box's rectangles, for
    boxes around the sensor, across the ±180° azimuth seam, above, below and all around it; a box away from the
    sensor gets a small part of the grid."""
    from dcslam.synth.shapes import corners_in

    grid = make_lidar_grid(0.5)
    rng = np.random.default_rng(11)
    shapes = []
    for _ in range(150):
        kind, half = int(rng.integers(3)), rng.uniform(0.05, 4, 3)
        half[1] = half[0] if kind == CYLINDER else half[1]  # a cylinder's radius, twice
        shapes.append(shape(kind, rng.uniform(-20, 20, 3), half, yaw=rng.uniform(-3, 3), pitch=rng.uniform(-1, 1)))
    shapes += [shape(BOX, [0, 0, 0], [2, 2, 2]), shape(BOX, [-5, 0.01, 0], [1, 1, 1]),  # around it; on the seam
               shape(BOX, [-5, -0.01, 3], [1, 1, 0.5])]
    rects = grid.rects_of(corners_in(shapes, np.eye(4)))
    dirs = grid.dirs.reshape(-1, 3)
    full = grid.dirs.shape[0] * grid.columns
    for s, boxes in zip(shapes, rects):
        hit = np.isfinite(intersect(s, s.R_world_obj.T @ -s.center, dirs @ s.R_world_obj.astype(np.float32)))
        covered = np.zeros(grid.dirs.shape[:2], bool)
        for r0, r1, c0, c1 in boxes:
            covered[r0:r1, c0:c1] = True
        assert not (hit.reshape(covered.shape) & ~covered).any(), s
        if np.linalg.norm(s.center) > 3 * s.radius:
            assert covered.sum() < 0.25 * full, s
    assert any(len(r) == 2 for r in rects[-2:]) and rects[-3] == [(0, grid.dirs.shape[0], 0, grid.columns)]
    assert sum(len(r) == 0 for r in rects) > 10  # boxes above or below every beam
    assert grid.rects_of(np.zeros((0, 8, 3))) == []
