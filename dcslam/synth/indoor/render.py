"""Rendering a view of the room: exact z-depth by ray casting, and colour from per-material albedo lit by the lamp."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dcslam.synth.indoor.room import BOOKS, CEILING, FABRIC, PICTURE, PLANT, RUG, WALL, WOOD, Room
from dcslam.synth.noise import cell_noise, value_noise
from dcslam.synth.raycast import GROUND, CameraGrid, cast, local_normals
from dcslam.synth.shapes import Shape
from dcslam.synth.terrain import Terrain

MAX_RANGE_M = 15.0
FLAT_FLOOR = Terrain(amplitude=np.zeros(1), wave=np.zeros((1, 2)), phase=np.zeros(1))


def albedo(shape: Shape, p_world: np.ndarray, p_local: np.ndarray) -> np.ndarray:
    """Surface colours (n, 3) float32 in [0, 1] of ``shape`` at world points / local points (n, 3)."""
    m, base = shape.material, shape.color.astype(np.float32)
    if m == WALL:
        return base * (0.93 + 0.1 * value_noise(p_world, 0.9))[:, None]
    if m == CEILING:
        return base * (0.97 + 0.03 * cell_noise(p_world, 0.05))[:, None]
    if m == WOOD:
        grain = np.sin(p_local[:, 0] * 40.0 + 6.0 * cell_noise(p_world, 0.3)) * 0.06
        return base * (0.92 + grain + 0.06 * cell_noise(p_world, 0.04))[:, None]
    if m in (FABRIC, RUG):
        weave = 0.9 + 0.12 * cell_noise(p_world, 0.01 if m == FABRIC else 0.02)
        if m == RUG:
            stripes = (np.floor(p_local[:, 0] / 0.15) % 2) * 0.25 + ((np.abs(p_local[:, 1]) % 0.4) < 0.05) * 0.3
            weave = weave * (0.75 + stripes)
        return base * weave[:, None]
    if m == BOOKS:  # spines: a colour per few centimetres
        spine = cell_noise(np.stack([p_local[:, 0] * 30.0, 0 * p_local[:, 1], 0 * p_local[:, 2]], 1), 1.0)
        return np.clip(base * (0.55 + 0.9 * spine)[:, None], 0, 1)
    if m == PICTURE:
        return base * (0.3 + 1.0 * value_noise(p_world, 0.12))[:, None]
    if m == PLANT:
        return base * (0.5 + 0.9 * cell_noise(p_world, 0.04))[:, None]
    return base * (0.95 + 0.05 * cell_noise(p_world, 0.1))[:, None]


def floor_albedo(p: np.ndarray, tint: np.ndarray, along_x: bool) -> np.ndarray:
    """Wooden planks (0.18 x 1.2 m, staggered), one shade per plank."""
    u, v = (p[:, 0], p[:, 1]) if along_x else (p[:, 1], p[:, 0])
    row = np.floor(v / 0.18)
    col = np.floor((u + 0.37 * row) / 1.2)
    shade = cell_noise(np.stack([row, col, 0 * row], 1), 1.0)
    seam = ((v % 0.18) < 0.006) | (((u + 0.37 * row) % 1.2) < 0.006)
    grain = 0.04 * np.sin(u * 55.0 + 9.0 * shade)
    return tint[None, :] * ((0.75 + 0.35 * shade + grain) * np.where(seam, 0.55, 1.0))[:, None]


@dataclass(frozen=True)
class Look:
    """How one room looks beyond its shapes: the floor planks' tint (3,) and direction."""

    floor_tint: np.ndarray
    planks_along_x: bool


def render(room: Room, look: Look, grid: CameraGrid, T_world_cam: np.ndarray,
           rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """True z-depth (H, W) float32 metres (0 = nothing within 15 m) and RGB (H, W, 3) uint8 of one view."""
    depth, index, d_world = cast(grid, T_world_cam, room.shapes, FLAT_FLOOR, MAX_RANGE_M)
    H, W = depth.shape
    t = depth.ravel()
    d = d_world.reshape(-1, 3)
    hit = np.isfinite(t)
    rgb = np.zeros((H * W, 3), dtype=np.float32)
    p = (T_world_cam[:3, 3].astype(np.float32) + t[hit, None] * d[hit])
    idx = index.ravel()[hit]
    normal = np.zeros_like(p)
    colour = np.zeros_like(p)
    order = np.argsort(idx, kind="stable")
    values, starts = np.unique(idx[order], return_index=True)
    for value, a, b in zip(values, starts, np.append(starts[1:], len(order))):
        pos = order[a:b]
        if value == GROUND:
            normal[pos] = (0.0, 0.0, 1.0)
            colour[pos] = floor_albedo(p[pos], look.floor_tint, look.planks_along_x)
            continue
        shape = room.shapes[value]
        p_local = ((p[pos] - shape.center) @ shape.R_world_obj).astype(np.float32)
        n_local = local_normals(shape, p_local)
        normal[pos] = n_local @ shape.R_world_obj.T.astype(np.float32)
        colour[pos] = albedo(shape, p[pos], p_local)
    to_lamp = room.lamp.astype(np.float32) - p
    distance = np.linalg.norm(to_lamp, axis=1)
    facing = np.sign(-np.einsum("ij,ij->i", normal, d[hit]))[:, None]
    lambert = np.clip(np.einsum("ij,ij->i", normal * facing, to_lamp) / np.maximum(distance, 1e-6), 0, 1)
    light = 0.3 + 0.8 * lambert / (1.0 + (distance / 3.0) ** 2)
    rgb[hit] = colour * light[:, None]
    image = np.clip(rgb.reshape(H, W, 3) * 255 + rng.normal(0, 1.2, (H, W, 1)).astype(np.float32), 0, 255)
    depth = np.where(np.isfinite(depth), depth, 0).astype(np.float32)
    return depth, image.astype(np.uint8)
