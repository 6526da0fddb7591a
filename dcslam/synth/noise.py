"""Procedural texture noise for both generators: smooth value noise and blocky cell noise over 3-D points."""
from __future__ import annotations

import numpy as np


def _hash(ix: np.ndarray, iy: np.ndarray, iz: np.ndarray) -> np.ndarray:
    h = (ix * 73856093) ^ (iy * 19349663) ^ (iz * 83492791)
    h = (h ^ (h >> 13)) * 1274126177
    return ((h ^ (h >> 16)) & 0xFFFF).astype(np.float32) / 65535.0


def value_noise(p: np.ndarray, cell: float) -> np.ndarray:
    """Smooth pseudo-random values in [0, 1] (n,) at points p (n, 3), varying over ``cell`` metres."""
    q = p / cell
    i = np.floor(q)
    f = (q - i).astype(np.float32)
    f = f * f * (3 - 2 * f)
    i = i.astype(np.int64)
    out = np.zeros(len(p), dtype=np.float32)
    for dx in (0, 1):
        wx = f[:, 0] if dx else 1 - f[:, 0]
        for dy in (0, 1):
            wy = f[:, 1] if dy else 1 - f[:, 1]
            for dz in (0, 1):
                wz = f[:, 2] if dz else 1 - f[:, 2]
                out += wx * wy * wz * _hash(i[:, 0] + dx, i[:, 1] + dy, i[:, 2] + dz)
    return out


def cell_noise(p: np.ndarray, cell: float) -> np.ndarray:
    """Blocky pseudo-random values in [0, 1] (n,), constant over cubes of ``cell`` metres."""
    i = np.floor(p / cell).astype(np.int64)
    return _hash(i[:, 0], i[:, 1], i[:, 2])
