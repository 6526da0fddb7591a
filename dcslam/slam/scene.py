"""A small analytic street scene rendered to exact depth by ray casting: ground plane, building blocks with
varying set-backs, parked boxes and poles. Used by the SLAM tests and benchmarks (no dataset needed); the full
procedural generator with LiDAR and KITTI files is ``dcslam synth``.
"""
from __future__ import annotations

import math

import numpy as np
import torch

from dcslam.errors import DcslamError
from dcslam.geometry.camera import pixel_grid
from dcslam.geometry.se3 import from_rotation_translation, so3_exp


def kitti_K(height: int = 375, width: int = 1242, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """KITTI-like intrinsics (f = 721.5 px at 1242 px width) scaled to ``width``. Shape: (3, 3)."""
    f = 721.5377 * width / 1242
    return torch.tensor([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1]], dtype=dtype)


class StreetScene:
    """Axis-aligned boxes over a ground plane ``y = ground_y`` (camera frame at the start: x right, y down, z ahead).

    Shape: boxes (B, 6) = (xmin, ymin, zmin, xmax, ymax, zmax) metres.
    """

    def __init__(self, seed: int = 0, length: float = 120.0, width: float = 14.0, ground_y: float = 1.65):
        rng = np.random.default_rng(seed)
        boxes = []
        z = -10.0
        while z < length:                                  # building blocks on both sides
            depth = rng.uniform(6, 14)
            for side in (-1, 1):
                setback = width / 2 + rng.uniform(0, 2.5)
                height = rng.uniform(4, 12)
                x0, x1 = (setback, setback + 8) if side > 0 else (-setback - 8, -setback)
                boxes.append([x0, ground_y - height, z, x1, ground_y, z + depth - rng.uniform(0.5, 2)])
            z += depth
        for _ in range(int(length / 6)):                   # parked cars and poles
            side = rng.choice([-1, 1])
            zc = rng.uniform(0, length)
            if rng.random() < 0.6:
                x = side * rng.uniform(3.5, 5.0)
                boxes.append([x - 0.9, ground_y - 1.5, zc, x + 0.9, ground_y, zc + 4.2])
            else:
                x = side * rng.uniform(4.5, 6.0)
                boxes.append([x - 0.15, ground_y - 5.0, zc, x + 0.15, ground_y, zc + 0.3])
        self.boxes = torch.tensor(boxes, dtype=torch.float64)
        self.ground_y = ground_y

    def render(self, T_world_cam: torch.Tensor, K: torch.Tensor, height: int, width: int,
               max_depth: float = 80.0, mask: torch.Tensor | None = None) -> torch.Tensor:
        """Exact depth (metres, 0 = sky or beyond ``max_depth``); with ``mask``, rays are cast only through the
        pixels it sets (the others are 0), e.g. a :func:`lidar_mask`, which is as many times cheaper.

        Shape: T_world_cam (4, 4), K (3, 3), mask (H, W) bool or None -> (H, W).
        """
        if mask is not None and mask.shape != (height, width):
            raise DcslamError(f"mask has shape {tuple(mask.shape)}, expected ({height}, {width})")
        T = T_world_cam.double()
        K = K.double()
        uv = pixel_grid(height, width, torch.float64).reshape(2, -1)
        if mask is not None:
            uv = uv[:, mask.reshape(-1).to(uv.device)]
        rays_cam = torch.stack([(uv[0] - K[0, 2]) / K[0, 0], (uv[1] - K[1, 2]) / K[1, 1],
                                torch.ones_like(uv[0])], 1)                     # z = 1: t is the depth
        d = rays_cam @ T[:3, :3].T
        o = T[:3, 3]
        t_best = torch.full((d.shape[0],), math.inf, dtype=torch.float64)
        dy = d[:, 1]
        t_ground = (self.ground_y - o[1]) / torch.where(dy.abs() > 1e-12, dy, torch.full_like(dy, 1e-12))
        t_best = torch.where(t_ground > 0, t_ground, t_best)
        inv = 1.0 / torch.where(d.abs() > 1e-12, d, torch.full_like(d, 1e-12))
        centre = 0.5 * (self.boxes[:, :3] + self.boxes[:, 3:])
        reach = 0.5 * (self.boxes[:, 3:] - self.boxes[:, :3]).norm(dim=1) + max_depth
        near = self.boxes[(centre - o).norm(dim=1) <= reach]    # boxes beyond max_depth cannot be seen
        for chunk in near.split(16):
            t1 = (chunk[None, :, :3] - o) * inv[:, None, :]
            t2 = (chunk[None, :, 3:] - o) * inv[:, None, :]
            t_near = torch.minimum(t1, t2).amax(-1)
            t_far = torch.maximum(t1, t2).amin(-1)
            hit = (t_far >= t_near) & (t_near > 1e-6)
            t_hit = torch.where(hit, t_near, torch.full_like(t_near, math.inf)).amin(-1)
            t_best = torch.minimum(t_best, t_hit)
        depth = torch.where(torch.isfinite(t_best) & (t_best <= max_depth), t_best, torch.zeros_like(t_best))
        if mask is not None:
            return torch.zeros(height * width, dtype=torch.float64).masked_scatter(mask.reshape(-1), depth) \
                .reshape(height, width)
        return depth.reshape(height, width)


def street_trajectory(frames: int, step: float = 1.0, sway: float = 0.4, yaw_deg: float = 3.0) -> torch.Tensor:
    """A car-like path along +z with a gentle weave: T_world_cam of each frame, the first at the origin.

    Shape: -> (N, 4, 4) float64.
    """
    poses = []
    for k in range(frames):
        s = k * step
        x = sway * math.sin(2 * math.pi * s / 40)
        yaw = math.radians(yaw_deg) * math.cos(2 * math.pi * s / 40) - math.radians(yaw_deg)
        R = so3_exp(torch.tensor([0.0, yaw, 0.0], dtype=torch.float64))
        poses.append(from_rotation_translation(R, torch.tensor([x, 0.0, s], dtype=torch.float64)))
    return torch.stack(poses)


def lidar_mask(height: int, width: int, row_step: int = 5, col_step: int = 4) -> torch.Tensor:
    """Scan-line sampling like projected LiDAR (about 1 / (row_step col_step) of the pixels). Shape: (H, W) bool."""
    mask = torch.zeros(height, width, dtype=torch.bool)
    mask[row_step // 2::row_step, ::col_step] = True
    return mask
