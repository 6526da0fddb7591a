"""Vectorised ray casting of a scene (terrain + boxes, cylinders, ellipsoids) on a regular grid of rays.

A sensor is a :class:`RayGrid`: ray directions (R, C, 3) in the sensor frame on a regular grid (pixels for the
camera, beams × azimuth steps for the LiDAR) and a rule that bounds which grid cells a box of corners may cover.
Each shape is intersected only with the rays of that rectangle, so the cost follows what the sensor sees.
"""
from __future__ import annotations

import numpy as np

from dcslam.synth.shapes import BOX, CYLINDER, ELLIPSOID, Shape, corners_in
from dcslam.synth.terrain import Terrain

_EDGES = [(i, j) for i in range(8) for j in range(i + 1, 8) if (i ^ j) in (1, 2, 4)]
NO_HIT, GROUND = -2, -1


class CameraGrid:
    """Pixel rays ``((u - cx) / fx, (v - cy) / fy, 1)`` of a pinhole camera: the ray parameter is the depth z."""

    def __init__(self, K: np.ndarray, width: int, height: int, near: float = 0.05):
        self.K, self.width, self.height, self.near = np.asarray(K, dtype=np.float64), width, height, near
        u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
        x = (u - self.K[0, 2]) / self.K[0, 0]
        y = (v - self.K[1, 2]) / self.K[1, 1]
        self.dirs = np.stack([x, y, np.ones_like(x)], -1).astype(np.float32)  # (H, W, 3)
        self.lengths = np.linalg.norm(self.dirs, axis=-1)

    def rects(self, corners: np.ndarray) -> list[tuple[int, int, int, int]]:
        """Corners (8, 3) of a box in the camera frame → [(row0, row1, col0, col1)] that its image may cover."""
        z = corners[:, 2]
        points = [corners[z > self.near]]
        for i, j in _EDGES:
            if (z[i] > self.near) != (z[j] > self.near):
                a = (self.near - z[i]) / (z[j] - z[i])
                points.append((corners[i] + a * (corners[j] - corners[i]))[None])
        points = np.concatenate(points)
        if len(points) == 0:
            return []
        u = self.K[0, 0] * points[:, 0] / points[:, 2] + self.K[0, 2]
        v = self.K[1, 1] * points[:, 1] / points[:, 2] + self.K[1, 2]
        c0, c1 = max(int(np.floor(u.min())) - 1, 0), min(int(np.ceil(u.max())) + 2, self.width)
        r0, r1 = max(int(np.floor(v.min())) - 1, 0), min(int(np.ceil(v.max())) + 2, self.height)
        return [(r0, r1, c0, c1)] if r0 < r1 and c0 < c1 else []

    def rects_of(self, corners: np.ndarray) -> list[list[tuple[int, int, int, int]]]:
        """:meth:`rects` of each box of ``corners`` (S, 8, 3), the boxes wholly in front of the near plane (most of
        them) at once: the per-box calls were a tenth of a generated frame's time."""
        z = corners[..., 2]
        front = z > self.near
        out: list[list[tuple[int, int, int, int]]] = [[] for _ in range(len(corners))]
        whole = front.all(1)
        if whole.any():
            inside = corners[whole]
            u = self.K[0, 0] * inside[..., 0] / inside[..., 2] + self.K[0, 2]
            v = self.K[1, 1] * inside[..., 1] / inside[..., 2] + self.K[1, 2]
            c0 = np.maximum(np.floor(u.min(1)).astype(np.int64) - 1, 0)
            c1 = np.minimum(np.ceil(u.max(1)).astype(np.int64) + 2, self.width)
            r0 = np.maximum(np.floor(v.min(1)).astype(np.int64) - 1, 0)
            r1 = np.minimum(np.ceil(v.max(1)).astype(np.int64) + 2, self.height)
            for k, a, b, c, d in zip(np.flatnonzero(whole).tolist(), r0.tolist(), r1.tolist(), c0.tolist(),
                                     c1.tolist()):
                if a < b and c < d:
                    out[k] = [(a, b, c, d)]
        for k in np.flatnonzero(front.any(1) & ~whole).tolist():  # across the near plane: clipped edges
            out[k] = self.rects(corners[k])
        return out


class LidarGrid:
    """A spinning multi-beam LiDAR: unit rays for ``elevations_deg`` (R,) (descending) × ``columns`` azimuths
    ``−π + (j + offset_r) · 2π / columns``, where odd beams are offset by half a column (``interleave``: neighbouring
    lasers fire alternately); the ray parameter is the range."""

    def __init__(self, elevations_deg: np.ndarray, columns: int, interleave: bool = True):
        self.elevation = np.deg2rad(np.asarray(elevations_deg, dtype=np.float64))
        self.columns = columns
        self._step = 2 * np.pi / columns
        offset = (np.arange(len(self.elevation)) % 2) * 0.5 if interleave else np.zeros(len(self.elevation))
        az = -np.pi + (np.arange(columns)[None, :] + offset[:, None]) * self._step
        el = self.elevation[:, None]
        self.dirs = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el) + 0 * az],
                             -1).astype(np.float32)
        self.lengths = np.ones(self.dirs.shape[:2], dtype=np.float32)

    def rects_of(self, corners: np.ndarray) -> list[list[tuple[int, int, int, int]]]:
        """Grid rectangles that each box of ``corners`` (S, 8, 3), in the LiDAR frame, may cover, every box at once
        (a call per box was a tenth of a generated frame's time).

        Seen from outside its footprint, a convex box spans the azimuths of its corners (one rectangle, or two across
        the ±180° seam), and its elevations are bounded using the nearest and farthest horizontal distances of its
        footprint; a box around the sensor spans every azimuth.
        """
        if not len(corners):
            return []
        xy = corners[..., :2]
        z_hi, z_lo = corners[..., 2].max(1), corners[..., 2].min(1)
        mean = xy.mean(1)
        az_c = np.arctan2(mean[:, 1], mean[:, 0])
        rel = np.angle(np.exp(1j * (np.arctan2(xy[..., 1], xy[..., 0]) - az_c[:, None])))
        outside = rel.max(1) - rel.min(1) < np.pi - 1e-3
        rho_max = np.linalg.norm(xy, axis=2).max(1)
        a, b = xy[:, [i for i, _ in _EDGES]], xy[:, [j for _, j in _EDGES]]
        ab = b - a
        u = np.clip(-np.einsum("sij,sij->si", a, ab) / np.maximum(np.einsum("sij,sij->si", ab, ab), 1e-12), 0, 1)
        rho_min = np.linalg.norm(a + u[..., None] * ab, axis=2).min(1)
        el_hi = np.where(outside, np.arctan2(z_hi, np.where(z_hi > 0, rho_min, rho_max)),
                         np.where(z_hi > 0, np.pi / 2, np.arctan2(z_hi, rho_max)))
        el_lo = np.where(outside, np.arctan2(z_lo, np.where(z_lo > 0, rho_max, rho_min)),
                         np.where(z_lo < 0, -np.pi / 2, np.arctan2(z_lo, rho_max)))
        margin = 2e-3
        rows = (self.elevation <= el_hi[:, None] + margin) & (self.elevation >= el_lo[:, None] - margin)
        r0 = rows.argmax(1)
        r1 = rows.shape[1] - rows[:, ::-1].argmax(1)
        lo = az_c + rel.min(1) - self._step
        first = np.floor((lo + np.pi) / self._step).astype(np.int64)
        last = np.ceil((az_c + rel.max(1) + self._step + np.pi) / self._step).astype(np.int64) + 1
        out: list[list[tuple[int, int, int, int]]] = []
        for k in range(len(corners)):
            if not rows[k, r0[k]]:
                out.append([])
                continue
            a0, a1 = int(r0[k]), int(r1[k])
            if not outside[k] or last[k] - first[k] >= self.columns:
                out.append([(a0, a1, 0, self.columns)])
                continue
            c0 = int(first[k]) % self.columns
            c1 = c0 + int(last[k] - first[k])
            out.append([(a0, a1, c0, c1)] if c1 <= self.columns else
                       [(a0, a1, c0, self.columns), (a0, a1, 0, c1 - self.columns)])
        return out


def intersect(shape: Shape, o: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Ray parameters (n,) float32 of the first hit of rays ``o + t d`` (o (3,), d (n, 3) in the shape's frame) from
    outside the shape; ``inf`` where they miss."""
    h = shape.half.astype(np.float32)
    o = o.astype(np.float32)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        if shape.kind == BOX:
            t_near, t_far = None, None
            for axis in range(3):  # slabs, one axis at a time (faster than reductions over (n, 3))
                inv = 1.0 / d[:, axis]
                t1, t2 = (-h[axis] - o[axis]) * inv, (h[axis] - o[axis]) * inv
                lo, hi = np.minimum(t1, t2), np.maximum(t1, t2)
                t_near = lo if t_near is None else np.maximum(t_near, lo)
                t_far = hi if t_far is None else np.minimum(t_far, hi)
            hit = (t_near <= t_far) & (t_near > 0)
            return np.where(hit, t_near, np.float32(np.inf))
        if shape.kind == ELLIPSOID:
            o_s, d_s = o / h, d / h
            a = np.einsum("ij,ij->i", d_s, d_s)
            b = d_s @ o_s
            c = float(o_s @ o_s) - 1.0
            disc = b * b - a * c
            t = (-b - np.sqrt(np.maximum(disc, 0))) / a
            return np.where((disc >= 0) & (t > 0), t, np.float32(np.inf))
        if shape.kind == CYLINDER:
            r, hz = h[0], h[2]
            a = d[:, 0] ** 2 + d[:, 1] ** 2
            b = d[:, 0] * o[0] + d[:, 1] * o[1]
            c = o[0] ** 2 + o[1] ** 2 - r * r
            disc = b * b - a * c
            t = (-b - np.sqrt(np.maximum(disc, 0))) / a
            z = o[2] + t * d[:, 2]
            best = np.where((disc >= 0) & (t > 0) & (np.abs(z) <= hz), t, np.float32(np.inf))
            if abs(o[2]) > hz:  # the cap facing the sensor
                cap = np.sign(o[2]) * hz
                tc = (cap - o[2]) / d[:, 2]
                x, y = o[0] + tc * d[:, 0], o[1] + tc * d[:, 1]
                best = np.where((tc > 0) & (x * x + y * y <= r * r) & (tc < best), tc, best)
            return best
    raise ValueError(f"unknown shape kind {shape.kind}")


def local_normals(shape: Shape, p: np.ndarray) -> np.ndarray:
    """Outward unit normals (n, 3) at surface points ``p`` (n, 3) given in the shape's frame."""
    h = shape.half.astype(np.float32)
    if shape.kind == BOX:
        axis = np.argmax(np.abs(p) / h, axis=1)
        n = np.zeros_like(p)
        n[np.arange(len(p)), axis] = np.sign(p[np.arange(len(p)), axis])
        return n
    if shape.kind == ELLIPSOID:
        n = p / (h * h)
    else:
        on_cap = np.abs(p[:, 2]) >= h[2] - 1e-3
        n = np.where(on_cap[:, None], np.stack([0 * p[:, 0], 0 * p[:, 1], np.sign(p[:, 2])], -1),
                     np.stack([p[:, 0], p[:, 1], 0 * p[:, 2]], -1))
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-9)


def intersect_terrain(terrain: Terrain, o: np.ndarray, d: np.ndarray, max_t: np.ndarray) -> np.ndarray:
    """Ray parameters (n,) float32 of rays ``o + t d`` (o (3,), d (n, 3) world) with the ground, ``inf`` where they
    miss within ``max_t`` (n,). Newton's method from the hit with the tangent plane below ``o`` (the terrain is
    gentle: slopes of a few per cent varying over hundreds of metres)."""
    o = o.astype(np.float64)
    h0 = float(terrain.height(o[0], o[1]))
    g = terrain.gradient(o[0], o[1])
    denominator = d[:, 2] - np.float32(g[0]) * d[:, 0] - np.float32(g[1]) * d[:, 1]
    candidates = np.flatnonzero(denominator < -1e-6)
    tv = np.float32(h0 - o[2]) / denominator[candidates]
    keep = tv < max_t[candidates] * 1.5
    valid, tv = candidates[keep], tv[keep]
    dv, limit = d[valid], max_t[valid] * 2
    height_above = np.float32(o[2])
    for _ in range(2):
        h, gx, gy = terrain.around(o[0], o[1], tv * dv[:, 0], tv * dv[:, 1])
        f = height_above + tv * dv[:, 2] - h
        slope = dv[:, 2] - gx * dv[:, 0] - gy * dv[:, 1]
        tv = np.clip(tv - f / np.minimum(slope, np.float32(-1e-6)), 0, limit)
    h = terrain.height_around(o[0], o[1], tv * dv[:, 0], tv * dv[:, 1])
    residual = np.abs(height_above + tv * dv[:, 2] - h)
    ok = (residual < 5e-3) & (tv > 0) & (tv < max_t[valid])
    out = np.full(len(d), np.inf, dtype=np.float32)
    out[valid[ok]] = tv[ok]
    return out


def cast(grid, T_world_sensor: np.ndarray, shapes: list[Shape], terrain: Terrain, max_range_m: float):
    """Cast every ray of ``grid`` from the sensor at pose ``T_world_sensor`` (4, 4).

    Returns the ray parameter (R, C) float32 (``inf`` = no hit within ``max_range_m`` metres of range), the index of
    the hit (R, C) int32 (shape index, ``GROUND`` or ``NO_HIT``) and the world ray directions (R, C, 3) float32.
    """
    R_ws = T_world_sensor[:3, :3]
    o_world = T_world_sensor[:3, 3]
    dirs = grid.dirs
    rows, cols = dirs.shape[:2]
    d_world = (dirs.reshape(-1, 3) @ R_ws.T.astype(np.float32))
    lengths = grid.lengths
    max_t = (max_range_m / lengths).astype(np.float32).ravel()
    t_best = intersect_terrain(terrain, o_world, d_world, max_t).reshape(rows, cols)
    index = np.where(np.isfinite(t_best), GROUND, NO_HIT).astype(np.int32)
    T_sensor_world = np.linalg.inv(T_world_sensor)
    for k, (shape, rects) in enumerate(zip(shapes, grid.rects_of(corners_in(shapes, T_sensor_world)))):
        if not rects:
            continue
        M = (shape.R_world_obj.T @ R_ws).astype(np.float32)  # sensor → object rotation
        o_local = shape.R_world_obj.T @ (o_world - shape.center)
        for r0, r1, c0, c1 in rects:
            sub = dirs[r0:r1, c0:c1].reshape(-1, 3)
            t = intersect(shape, o_local, sub @ M.T).reshape(r1 - r0, c1 - c0)
            view_t = t_best[r0:r1, c0:c1]
            closer = t < view_t
            if closer.any():
                view_t[closer] = t[closer]
                index[r0:r1, c0:c1][closer] = k
    far = t_best * lengths > max_range_m
    t_best[far] = np.inf
    index[far] = NO_HIT
    return t_best, index, d_world.reshape(rows, cols, 3)
