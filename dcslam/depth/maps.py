"""The chamfer training loss: maps built from predicted depth and from ground-truth dense depth, with ground-truth
poses, compared by the chamfer distance.

Maps are built over windows of consecutive frames (``map_frames`` = 1: one map per frame; 8: frames 0–7, 8–15, …;
the thesis's text says 8, its published code used 7). The map builder is a callable
``build_map(depth (N, 1, H, W), K (3, 3), T_world_cam (N, 4, 4)) -> map with .points (P, 3)``, differentiable
w.r.t. depth; by default dcslam's PointFusion mapping, :func:`dcslam.slam.pipeline.build_map`.
"""
from __future__ import annotations

from collections.abc import Callable
from types import SimpleNamespace

import torch

from dcslam.depth.chamfer import chamfer_distance, plane_chamfer_distance
from dcslam.depth.data import frame_windows
from dcslam.errors import DcslamError


def default_map_builder() -> Callable:
    """dcslam's differentiable mapping (PointFusion with ground-truth poses)."""
    try:
        from dcslam.slam.pipeline import build_map
    except ImportError as exc:
        raise DcslamError(f"the chamfer loss needs dcslam.slam.pipeline.build_map, which is missing ({exc})") from None
    return build_map


def stacked_points_map(depth: torch.Tensor, K: torch.Tensor, T_world_cam: torch.Tensor, **_) -> SimpleNamespace:
    """The simplest differentiable map: every valid pixel of every frame back-projected to the world, no fusion.

    Shape:
        depth (N, 1, H, W), K (3, 3), T_world_cam (N, 4, 4) → namespace with ``points`` (P, 3)
    """
    from dcslam.geometry.camera import depth_to_points

    clouds = [depth_to_points(depth[i:i + 1], K, T_world_cam[i])[0] for i in range(depth.shape[0])]
    return SimpleNamespace(points=torch.cat(clouds))


class MapChamfer:
    """``MapChamfer(map_frames)(pred, dense, K, T_world_cam)``: the mean over windows of the chamfer distance
    between the map of the predicted depth and the map of the ground-truth depth; with ``distance="plane"``, its
    point-to-plane form along the ground-truth map's normals (:func:`dcslam.depth.chamfer.plane_chamfer_distance`;
    the map builder's maps must carry ``normals``, as PointFusion's do).

    Shape:
        pred, dense: (N, 1, H, W) metres; K: (3, 3); T_world_cam: (N, 4, 4) → scalar (m²)
    """

    def __init__(self, map_frames: int = 1, map_builder: Callable | None = None, distance: str = "point"):
        from dcslam.depth.recipes import CHAMFER_DISTANCES

        if map_frames < 1:
            raise DcslamError(f"--map-frames must be >= 1, got {map_frames}")
        if distance not in CHAMFER_DISTANCES:
            raise DcslamError(f"unknown --chamfer-distance {distance!r}; expected one of "
                              f"{', '.join(CHAMFER_DISTANCES)}")
        self.map_frames = map_frames
        self.map_builder = map_builder
        self.distance = distance

    def _builder(self) -> Callable:
        if self.map_builder is None:
            self.map_builder = default_map_builder()
        return self.map_builder

    def __call__(self, pred: torch.Tensor, dense: torch.Tensor, K: torch.Tensor,
                 T_world_cam: torch.Tensor) -> torch.Tensor:
        if pred.shape != dense.shape or pred.ndim != 4 or T_world_cam.shape != (pred.shape[0], 4, 4):
            raise DcslamError(f"pred {tuple(pred.shape)}, dense {tuple(dense.shape)} and poses "
                              f"{tuple(T_world_cam.shape)} do not match (N, 1, H, W), (N, 4, 4)")
        build = self._builder()
        K = K.to(pred.dtype)
        T_world_cam = T_world_cam.to(pred.dtype)
        losses = []
        for window in frame_windows(pred.shape[0], self.map_frames):
            sl = slice(window.start, window.stop)
            pred_map = build(pred[sl], K, T_world_cam[sl]).points
            with torch.no_grad():
                gt = build(dense[sl], K, T_world_cam[sl])
            gt_map = gt.points
            if pred_map.shape[0] == 0 or gt_map.shape[0] == 0:
                continue  # a window with no prediction or no ground truth has no map to compare
            if self.distance == "plane":
                if getattr(gt, "normals", None) is None:
                    raise DcslamError("--chamfer-distance plane needs a map builder whose maps have normals "
                                      "(dcslam's PointFusion mapping)")
                losses.append(plane_chamfer_distance(pred_map, gt_map.detach(), gt.normals.detach()))
            else:
                losses.append(chamfer_distance(pred_map, gt_map.detach()))
        if not losses:
            return (pred * 0).sum()
        return torch.stack(losses).mean()
