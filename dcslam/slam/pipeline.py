"""Whole-sequence calls: :func:`build_map` (mapping with given poses)."""
from __future__ import annotations

import torch

from dcslam.errors import DcslamError
from dcslam.geometry.camera import check_depth
from dcslam.slam.fusion import PointFusion
from dcslam.slam.frame import FrameSettings, prepare_frame
from dcslam.slam.pointmap import PointMap


def build_map(depth: torch.Tensor, K: torch.Tensor, T_world_cam: torch.Tensor, rgb: torch.Tensor | None = None,
              mapper=None, frame_settings: FrameSettings = FrameSettings()) -> PointMap:
    """Fuse depth frames seen from given poses (e.g. ground-truth odometry) into one point map.

    Differentiable: gradients of the map's points (and normals, radii) flow back to ``depth``, those of its colours
    to ``rgb``. The mapper (default: a new ``PointFusion(keep_graph=True)``) is reset first.

    Shape: depth (N, 1, H, W) metres (0 = none), K (3, 3), T_world_cam (N, 4, 4), rgb (N, 3, H, W) in [0, 1] or
    None -> :class:`PointMap`.
    """
    N, H, W = check_depth(depth)
    if not isinstance(T_world_cam, torch.Tensor) or T_world_cam.shape != (N, 4, 4):
        raise DcslamError(f"T_world_cam has shape {tuple(getattr(T_world_cam, 'shape', ()))}, expected ({N}, 4, 4)")
    if rgb is not None and rgb.shape != (N, 3, H, W):
        raise DcslamError(f"rgb has shape {tuple(rgb.shape)}, expected ({N}, 3, {H}, {W})")
    if mapper is None:
        mapper = PointFusion(keep_graph=True)
    mapper.reset()
    pm = PointMap.empty(depth.dtype, depth.device)
    for i in range(N):
        frame = prepare_frame(depth[i:i + 1], K, None if rgb is None else rgb[i:i + 1], frame_settings)
        pm = mapper.integrate(frame, T_world_cam[i].to(depth.dtype))
    return pm
