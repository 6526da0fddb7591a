"""Pinhole camera: back-projection of depth images to vertex maps and point clouds, and projection.

Camera frame: x right, y down, z forward; pixel (u, v) = (column, row) with integer coordinates at pixel centres
(the OpenCV / KITTI ``P_rect`` convention). Depth is in metres, 0 = no measurement.
"""
from __future__ import annotations

import torch

from dcslam.errors import DcslamError


def check_depth(depth: torch.Tensor, name: str = "depth") -> tuple[int, int, int]:
    """Check a (B, 1, H, W) floating-point tensor and return (B, H, W)."""
    if not isinstance(depth, torch.Tensor):
        raise DcslamError(f"{name} must be a torch.Tensor, got {type(depth).__name__}")
    if depth.ndim != 4 or depth.shape[1] != 1:
        raise DcslamError(f"{name} has shape {tuple(depth.shape)}, expected (B, 1, H, W)")
    if not depth.is_floating_point():
        raise DcslamError(f"{name} must be floating point, got {depth.dtype}")
    return depth.shape[0], depth.shape[2], depth.shape[3]


def check_K(K: torch.Tensor, batch: int | None = None) -> torch.Tensor:
    """Intrinsics (3, 3) or (B, 3, 3) -> (B or 1, 3, 3)."""
    if not isinstance(K, torch.Tensor):
        raise DcslamError(f"K must be a torch.Tensor, got {type(K).__name__}")
    if K.shape == (3, 3):
        K = K[None]
    if K.ndim != 3 or K.shape[1:] != (3, 3) or (batch is not None and K.shape[0] not in (1, batch)):
        raise DcslamError(f"K has shape {tuple(K.shape)}, expected (3, 3) or ({batch or 'B'}, 3, 3)")
    return K


def pixel_grid(height: int, width: int, dtype: torch.dtype = torch.float32,
               device: torch.device | str | None = None) -> torch.Tensor:
    """Pixel coordinates. Shape: (2, H, W) with [0] = u (column) and [1] = v (row)."""
    v, u = torch.meshgrid(torch.arange(height, dtype=dtype, device=device),
                          torch.arange(width, dtype=dtype, device=device), indexing="ij")
    return torch.stack([u, v])


def backproject(depth: torch.Tensor, K: torch.Tensor) -> torch.Tensor:
    """Vertex map: the 3-D point of every pixel in the camera frame (zero where depth is zero).

    Shape: depth (B, 1, H, W), K (3, 3) or (B, 3, 3) -> (B, 3, H, W).
    """
    B, H, W = check_depth(depth)
    K = check_K(K, B).to(depth.dtype)
    uv = pixel_grid(H, W, depth.dtype, depth.device)
    fx, fy = K[:, 0, 0].view(-1, 1, 1), K[:, 1, 1].view(-1, 1, 1)
    cx, cy = K[:, 0, 2].view(-1, 1, 1), K[:, 1, 2].view(-1, 1, 1)
    z = depth[:, 0]
    x = (uv[0] - cx) / fx * z
    y = (uv[1] - cy) / fy * z
    return torch.stack([x, y, z], 1)


def backproject_pixels(z: torch.Tensor, pixels: torch.Tensor, K: torch.Tensor, width: int) -> torch.Tensor:
    """The 3-D points of some pixels in the camera frame: :func:`backproject`'s values there, bit for bit (the same
    operations in the same order), at a cost that follows the number of pixels, not the image size.

    Shape: z (N,) depth at ``pixels`` (N,) int64 flat indices into an image ``width`` pixels wide, K (3, 3) ->
    (N, 3).
    """
    K = check_K(K)[0].to(z.dtype)
    u = (pixels % width).to(z.dtype)
    v = torch.div(pixels, width, rounding_mode="floor").to(z.dtype)
    return torch.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], 1)


def project(points: torch.Tensor, K: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Project camera-frame points to pixels. Points with z <= 0 get non-finite-free but meaningless pixels;
    test ``z > 0`` before use.

    Shape: points (N, 3) or (B, N, 3), K (3, 3) or (B, 3, 3) -> (uv (..., N, 2), z (..., N)).
    """
    if not isinstance(points, torch.Tensor) or points.ndim not in (2, 3) or points.shape[-1] != 3:
        raise DcslamError(f"points has shape {tuple(getattr(points, 'shape', ()))}, expected (N, 3) or (B, N, 3)")
    K = check_K(K).to(points.dtype)
    if points.ndim == 2:
        K = K[0]
    z = points[..., 2]
    z_safe = torch.where(z.abs() > 1e-9, z, torch.full_like(z, 1e-9))
    fx, fy = K[..., 0, 0, None], K[..., 1, 1, None]
    cx, cy = K[..., 0, 2, None], K[..., 1, 2, None]
    u = fx * points[..., 0] / z_safe + cx
    v = fy * points[..., 1] / z_safe + cy
    return torch.stack([u, v], -1), z


def depth_to_points(depth: torch.Tensor, K: torch.Tensor,
                    T_world_cam: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """Point cloud of one depth image (pixels with depth > 0), in the world frame if a pose is given.

    Shape: depth (1, 1, H, W) or (H, W), K (3, 3), T_world_cam (4, 4) -> (points (P, 3), pixel index (P,) into H*W).
    """
    if isinstance(depth, torch.Tensor) and depth.ndim == 2:
        depth = depth[None, None]
    B, H, W = check_depth(depth)
    if B != 1:
        raise DcslamError(f"depth_to_points takes one frame, got a batch of {B}")
    vertex = backproject(depth, K)[0].reshape(3, -1)
    index = torch.nonzero(depth.reshape(-1) > 0).squeeze(1)
    points = vertex[:, index].T
    if T_world_cam is not None:
        from dcslam.geometry.se3 import transform_points

        points = transform_points(T_world_cam.to(points.dtype), points)
    return points, index
