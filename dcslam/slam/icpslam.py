"""The ICP-SLAM map (gradSLAM's ICPSLAM): every frame's points accumulated in the world frame, downsampled on a
voxel grid (points falling in one voxel are averaged, weighted by the frame's per-pixel weight where it has one),
and rendered for frame-to-model ICP. No confidence gating and no pruning: the plain accumulated model that
PointFusion improves on.
"""
from __future__ import annotations

import torch

from dcslam.slam.frame import Frame
from dcslam.slam.fusion import camera_surfels, frame_surfels, pixel_weights
from dcslam.slam.pointmap import MapperBase, PointMap, assign_voxels, merge, voxel_keys


class ICPSLAM(MapperBase):
    """Accumulated, voxel-downsampled point map; same interface as :class:`~dcslam.slam.fusion.PointFusion`.

    Args:
        voxel_size: metres (> 0); one point per voxel, so the map grows with the explored volume.
        keep_graph: keep the autograd graph across frames; otherwise detach after every frame.
        splat: rendering footprint (pixels each side) for odometry.
        window, archive: local map of the last ``window`` frames (0: the whole map), see
            :class:`~dcslam.slam.pointmap.MapperBase`.
    """

    def __init__(self, voxel_size: float = 0.05, keep_graph: bool = False, splat: int = 1, window: int = 0,
                 archive: bool = True):
        self.voxel_size, self.keep_graph, self.splat = voxel_size, keep_graph, splat
        self.window, self.archive = window, archive
        self.reset()

    def precompute(self, frame: Frame) -> None:
        """Do the work on ``frame`` that does not depend on the map or the pose (its surfels)."""
        camera_surfels(frame)

    def integrate(self, frame: Frame, T_world_cam: torch.Tensor, scale: float = 1.0) -> PointMap:
        """Add one frame seen from ``T_world_cam`` (4, 4) at the voxel size ``voxel_size * scale`` (``scale``: the
        scene scale, see :class:`dcslam.slam.parts.Mapper`); returns the new map."""
        dtype, device = frame.depth.dtype, frame.depth.device
        pm = self.map if self.map is not None else PointMap.empty(dtype, device)
        pixels, p_w, n_w, colors, radius, _ = frame_surfels(frame, T_world_cam)
        voxel = self.voxel_size * scale
        target, new_keys = assign_voxels(pm, voxel_keys(p_w, voxel), torch.full_like(pixels, -1), voxel)
        pm = merge(pm, target, new_keys, p_w, n_w, colors, radius, pixel_weights(frame, pixels), self.frames)
        if not self.keep_graph:
            pm = pm.detach()
        self.map = self._slide(pm)
        self.frames += 1
        return self.map
