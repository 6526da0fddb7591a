"""The simulated sensors: camera 2 (true depth + shaded, textured RGB), the HDL-64E-like LiDAR, and KITTI's two
depth-completion products made from the scans (``velodyne_raw`` and the accumulated ``groundtruth``).
"""
from __future__ import annotations

import cv2
import numpy as np
from scipy.spatial import cKDTree

from dcslam.synth.noise import cell_noise, value_noise
from dcslam.synth.raycast import GROUND, NO_HIT, CameraGrid, LidarGrid, cast, local_normals
from dcslam.synth.shapes import Shape
from dcslam.synth.street import scene as sc
from dcslam.synth.street.scene import Scene

MAX_RANGE_M = 120.0  # LiDAR
CAMERA_RANGE_M = 160.0
# stereo matching (KITTI's ground-truth check used SGM) gives no disparity on image patches with less contrast than
# this (grey-level standard deviation over 7 × 7 pixels); KITTI's ground truth has no points there
STEREO_TEXTURE_THRESHOLD = 3.5


def hdl64_elevations_deg() -> np.ndarray:
    """(64,) beam elevations, descending: 32 upper beams +2.0° … −8.33° (1/3° apart) and 32 lower beams −8.83° …
    −24.8° (about 1/2° apart), as the HDL-64E S2's two laser blocks."""
    return np.concatenate([np.linspace(2.0, -8.33, 32), np.linspace(-8.83, -24.8, 32)])


def make_lidar_grid(azimuth_step_deg: float = 0.08) -> LidarGrid:
    """The HDL-64E grid: shots every ``azimuth_step_deg`` across the 64 beams, each laser firing every second step,
    interleaved with its neighbours (a real KITTI scan has 0.18° between consecutive points of one laser). At 0.08°
    that is 64 × 2250 = 144,000 shots a revolution, as the HDL-64E S2's ~1.3 million shots a second at 10 Hz (real
    KITTI scans hold ~120,000 points)."""
    return LidarGrid(hdl64_elevations_deg(), int(round(360.0 / (2 * azimuth_step_deg))), interleave=True)


# ----------------------------------------------------------------------------------------------------- textures
def shape_albedo(shape: Shape, p_world: np.ndarray, p_local: np.ndarray, n_local: np.ndarray) -> np.ndarray:
    """Surface colours (n, 3) in [0, 1] of ``shape`` at world points (n, 3) / local points and normals (n, 3)."""
    m, base = shape.material, shape.color.astype(np.float32)
    if m == sc.FACADE:
        rough = 0.88 + 0.2 * value_noise(p_world, 1.5) + 0.06 * cell_noise(p_world, 0.12)
        colour = base * rough[:, None]
        front = np.abs(n_local[:, 1]) > 0.5
        u = p_local[:, 0] + shape.half[0]
        w = p_local[:, 2] + shape.half[2]
        window = front & ((u % 3.0) > 0.9) & ((u % 3.0) < 2.2) & ((w % 3.2) > 1.2) & ((w % 3.2) < 2.6)
        colour[window] = np.array([0.12, 0.15, 0.2], dtype=np.float32) * (0.8 + 0.4 * cell_noise(
            p_world[window], 1.0))[:, None]
        return colour
    if m == sc.SIDEWALK:
        tile = ((p_local[:, 0] % 0.5) < 0.03) | ((p_local[:, 1] % 0.5) < 0.03)
        return base * ((0.9 + 0.15 * cell_noise(p_world, 0.5)) * np.where(tile, 0.7, 1.0))[:, None]
    if m in (sc.FOLIAGE, sc.HEDGE):
        return base * (0.45 + 0.9 * cell_noise(p_world, 0.15) * value_noise(p_world, 0.8) + 0.2)[:, None]
    if m == sc.BARK:
        return base * (0.6 + 0.7 * value_noise(p_world * np.array([4.0, 4.0, 0.3]), 0.5))[:, None]
    if m == sc.ROOF:
        return base * (0.75 + 0.25 * ((p_local[:, 0] % 0.4) > 0.2) + 0.1 * cell_noise(p_world, 0.2))[:, None]
    if m == sc.GLASS:
        return base * (0.7 + 0.3 * value_noise(p_world, 0.7))[:, None]
    return base * (0.9 + 0.15 * value_noise(p_world, 0.6))[:, None]


class GroundTexture:
    """Asphalt with lane markings between the road edges, grass outside (sidewalks are boxes of their own)."""

    def __init__(self, scene: Scene):
        path = scene.drive.path
        every = max(int(round(1.0 / (path.s[1] - path.s[0]))), 1)  # path samples 1 m apart suffice
        self.s, self.xy, self.heading = path.s[::every], path.xy[::every], path.heading[::every]
        self.tree = cKDTree(self.xy)
        self.right, self.left = scene.road_right_m, scene.road_left_m

    def albedo(self, p: np.ndarray) -> np.ndarray:
        _, i = self.tree.query(p[:, :2])
        heading = self.heading[i]
        delta = p[:, :2] - self.xy[i]
        s = self.s[i] + np.cos(heading) * delta[:, 0] + np.sin(heading) * delta[:, 1]
        lateral = -np.sin(heading) * delta[:, 0] + np.cos(heading) * delta[:, 1]
        road = (lateral > self.right) & (lateral < self.left)
        asphalt = 0.3 * (0.8 + 0.35 * value_noise(p, 0.8) + 0.15 * cell_noise(p, 0.06))
        colour = np.repeat(asphalt[:, None], 3, 1)
        lane = sc.LANE_WIDTH_M
        marking = road & (((np.abs(lateral - lane / 2) < 0.07) & ((s % 9.0) < 3.0))
                          | (np.abs(lateral + lane / 2) < 0.08) | (np.abs(lateral - 1.5 * lane) < 0.08))
        colour[marking] = 0.85
        grass = ~road
        colour[grass] = np.array([0.25, 0.4, 0.14], dtype=np.float32) * (
            0.6 + 0.6 * value_noise(p[grass], 1.7) * (0.7 + 0.6 * cell_noise(p[grass], 0.1)))[:, None]
        return colour


# ----------------------------------------------------------------------------------------------------- camera
def _groups(index: np.ndarray):
    """Yield (value, flat positions) for each distinct value ≥ GROUND of ``index``."""
    flat = index.ravel()
    order = np.argsort(flat, kind="stable")
    values, starts = np.unique(flat[order], return_index=True)
    ends = np.append(starts[1:], len(order))
    for value, a, b in zip(values, starts, ends):
        if value >= GROUND:
            yield int(value), order[a:b]


def render_camera(scene: Scene, ground: GroundTexture, grid: CameraGrid, T_world_cam: np.ndarray, t: float,
                  rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """True depth (H, W) float32 in metres (0 = sky / beyond 160 m) and shaded RGB (H, W, 3) uint8 at time ``t``.

    Colour = the surface's albedo (per-object colour × procedural texture in world or object coordinates) × Lambert
    shading under the drive's sun, a sky gradient where no surface is hit; colour edges therefore fall exactly on
    the depth edges of the same ray cast."""
    shapes = scene.shapes_at(t, T_world_cam[:3, 3], CAMERA_RANGE_M)
    depth, index, d_world = cast(grid, T_world_cam, shapes, scene.drive.terrain, CAMERA_RANGE_M)
    H, W = depth.shape
    rgb = np.empty((H * W, 3), dtype=np.float32)
    d_flat = d_world.reshape(-1, 3)
    elevation = d_flat[:, 2] / np.linalg.norm(d_flat, axis=1)
    sky = np.clip(elevation, 0, 1)[:, None]
    rgb[:] = (1 - sky) * np.array([0.75, 0.82, 0.9], dtype=np.float32) + sky * np.array([0.35, 0.55, 0.85],
                                                                                           dtype=np.float32)
    sun = (scene.sun / np.linalg.norm(scene.sun)).astype(np.float32)
    origin = T_world_cam[:3, 3]
    t_flat = depth.ravel()
    for value, pos in _groups(index):
        p = (origin + t_flat[pos, None] * d_flat[pos]).astype(np.float64)
        if value == GROUND:
            gx, gy = scene.drive.terrain.gradient(p[:, 0], p[:, 1])
            normal = np.stack([-gx, -gy, np.ones_like(gx)], -1)
            normal /= np.linalg.norm(normal, axis=1, keepdims=True)
            albedo = ground.albedo(p)
        else:
            shape = shapes[value]
            p_local = ((p - shape.center) @ shape.R_world_obj).astype(np.float32)
            n_local = local_normals(shape, p_local)
            normal = n_local @ shape.R_world_obj.T.astype(np.float32)
            albedo = shape_albedo(shape, p, p_local, n_local)
        facing = np.sign(-np.einsum("ij,ij->i", normal, d_flat[pos]))[:, None]
        light = 0.35 + 0.65 * np.clip((normal * facing) @ sun, 0, 1)
        rgb[pos] = albedo * light[:, None]
    image = np.clip(rgb.reshape(H, W, 3) * 255 + rng.normal(0, 1.5, (H, W, 1)), 0, 255).astype(np.uint8)
    depth = np.where(np.isfinite(depth), depth, 0).astype(np.float32)
    return depth, image


# ----------------------------------------------------------------------------------------------------- LiDAR
def scan_lidar(scene: Scene, grid: LidarGrid, T_world_velo: np.ndarray, t: float, rng: np.random.Generator,
               range_noise_m: float = 0.02, dropout: float = 0.03) -> np.ndarray:
    """One revolution at time ``t`` → (N, 4) float32 points (x, y, z in the Velodyne frame, reflectance).

    Returns within 120 m, Gaussian range noise of ``range_noise_m``, a random fraction ``dropout`` of returns lost
    (half of those on glass); the scan is instantaneous (no motion distortion within a revolution).
    """
    shapes = scene.shapes_at(t, T_world_velo[:3, 3], MAX_RANGE_M)
    rng_m, index, _ = cast(grid, T_world_velo, shapes, scene.drive.terrain, MAX_RANGE_M)
    # scan order: azimuth by azimuth, beams top to bottom within each, as the sensor spins
    rng_m, index, dirs = rng_m.T.ravel(), index.T.ravel(), np.transpose(grid.dirs, (1, 0, 2)).reshape(-1, 3)
    hit = np.flatnonzero(index != NO_HIT)
    material = np.full(len(hit), sc.ASPHALT)
    is_shape = index[hit] >= 0
    shape_material = np.array([s.material for s in shapes] + [sc.ASPHALT], dtype=np.int64)
    material[is_shape] = shape_material[index[hit][is_shape]]
    lose = rng.random(len(hit)) < np.where(material == sc.GLASS, 0.5, dropout)
    hit, material = hit[~lose], material[~lose]
    r = rng_m[hit] + rng.normal(0, range_noise_m, len(hit)).astype(np.float32)
    xyz = dirs[hit] * r[:, None]
    reflectance = np.clip(sc.REFLECTANCE[material] * rng.uniform(0.7, 1.3, len(hit)), 0, 0.99)
    return np.concatenate([xyz, reflectance[:, None]], 1).astype(np.float32)


# ----------------------------------------------------------------------------------------------------- projections
def project_points(points_cam: np.ndarray, K: np.ndarray, width: int, height: int) -> np.ndarray:
    """Points (N, 3) in the camera frame → a depth image (H, W) float32 keeping the nearest point per pixel (no
    occlusion reasoning beyond that: points hidden from the camera still land where no nearer point does)."""
    return _zbuffer(*_pixels(points_cam, K, width, height), height, width)


def _pixels(points_cam: np.ndarray, K: np.ndarray, width: int, height: int):
    """Points (N, 3) in the camera frame -> pixel columns u, rows v (int64) and depths z of those more than 0.1 m
    ahead that land inside the image."""
    z = points_cam[:, 2]
    front = z > 0.1
    p, z = points_cam[front], z[front]
    u = np.rint(K[0, 0] * p[:, 0] / z + K[0, 2]).astype(np.int64)
    v = np.rint(K[1, 1] * p[:, 1] / z + K[1, 2]).astype(np.int64)
    inside = (u >= 0) & (u < width) & (v >= 0) & (v < height)
    return u[inside], v[inside], z[inside]


def _zbuffer(u: np.ndarray, v: np.ndarray, z: np.ndarray, height: int, width: int) -> np.ndarray:
    order = np.argsort(-z, kind="stable")  # far first, so the nearest is written last
    image = np.zeros(height * width, dtype=np.float32)
    image[(v * width + u)[order]] = z[order]
    return image.reshape(height, width)


def stereo_valid(rgb: np.ndarray, texture_threshold: float = STEREO_TEXTURE_THRESHOLD) -> np.ndarray:
    """(H, W, 3) uint8 image → (H, W) bool: where a stereo matcher would return a disparity, modelled as pixels
    whose grey level varies by at least ``texture_threshold`` (standard deviation over 7 × 7 pixels)."""
    grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY).astype(np.float32)
    mean = cv2.blur(grey, (7, 7))
    return cv2.blur(grey * grey, (7, 7)) - mean * mean >= texture_threshold ** 2


def consistent_groundtruth(points_cam: np.ndarray, depth_true: np.ndarray, K: np.ndarray,
                           valid: np.ndarray | None = None, tolerance_m: float = 0.1,
                           tolerance_rel: float = 0.01) -> np.ndarray:
    """KITTI-style ground truth: accumulated points (N, 3) in the current camera frame → depth (H, W) float32.

    A point is kept where it agrees with the current view: its depth is within ``max(tolerance_m, tolerance_rel ·
    depth)`` of the true depth of the pixel it lands on, widened by how much the surface's depth changes towards the
    neighbouring pixels (a point may sit half a pixel off the pixel centre; on the road far ahead that is metres)
    where that surface continues (depth steps over 10 % are occlusion edges and widen nothing). This plays the
    role of KITTI's consistency check against the current frame (Uhrig et al. 2017): it removes points seen
    through occluders by the displaced LiDAR or by other scans, and points on cars that moved meanwhile.
    KITTI's check compared with semi-global stereo matching, so it also dropped points wherever stereo had no
    answer; ``valid`` (H, W) bool (see :func:`stereo_valid`) plays that part when given.
    """
    H, W = depth_true.shape
    u, v, z = _pixels(points_cam, K, W, H)
    valid_depth = depth_true > 0
    slack = np.zeros_like(depth_true)
    for axis in (0, 1):
        step = np.abs(np.diff(depth_true, axis=axis))
        both = valid_depth[1:] & valid_depth[:-1] if axis == 0 else valid_depth[:, 1:] & valid_depth[:, :-1]
        near = depth_true[1:] if axis == 0 else depth_true[:, 1:]
        step = np.where(both & (step < 0.1 * near), step, 0)
        if axis == 0:
            slack[1:] = np.maximum(slack[1:], step)
            slack[:-1] = np.maximum(slack[:-1], step)
        else:
            slack[:, 1:] = np.maximum(slack[:, 1:], step)
            slack[:, :-1] = np.maximum(slack[:, :-1], step)
    tol = np.maximum(tolerance_m, tolerance_rel * z) + slack[v, u]
    ok = valid_depth[v, u] & (np.abs(z - depth_true[v, u]) <= tol)
    if valid is not None:
        ok &= valid[v, u]
    return _zbuffer(u[ok], v[ok], z[ok], H, W)
