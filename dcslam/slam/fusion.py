"""PointFusion (Keller et al., 3DV 2013, as gradSLAM implements it), with bounded growth and pruning.

Each frame: (1) associate its surfels to map points by projection: a map point that projects onto a pixel whose
surfel lies within the distance gate and whose normal agrees within the angle gate is a candidate, and the candidate
with the highest confidence wins the pixel; (2) frame surfels without a match go to the map point of their voxel, or
start a new point per new voxel (so the map grows with the explored volume, not with time); (3) matched points are
merged by confidence-weighted averaging, with the weight ``alpha = exp(-gamma^2 / 2 sigma^2)`` of the *normalised
radial image distance* gamma of the pixel (Keller's definition: gradSLAM used the metric point norm, which at street
ranges clamps every weight to the same tiny value), times the frame's per-pixel weight where it has one
(:attr:`~dcslam.slam.frame.Frame.weight`, e.g. a completer's confidence; pixels of weight 0 are not fused);
(4) unstable points are pruned: points seen in fewer than
``min_observations`` frames and not updated for ``prune_after`` frames, and unstable points found in front of a
surface the current frame sees (free space).
"""
from __future__ import annotations

import math

import torch

from dcslam.geometry.camera import project
from dcslam.geometry.se3 import inverse, rotate, transform_points
from dcslam.slam.frame import Frame, valid_colors, valid_normals, valid_points
from dcslam.slam.pointmap import MapperBase, PointMap, assign_voxels, merge, voxel_keys


def surfel_weights(frame: Frame, pixels: torch.Tensor, sigma: float) -> torch.Tensor:
    """Keller's confidence weight of frame pixels: exp(-gamma^2 / 2 sigma^2), gamma = radial distance from the
    principal point normalised by the largest one in the image. Shape: pixels (F,) flat indices -> (F,)."""
    H, W = frame.shape
    u = (pixels % W).to(frame.K.dtype)
    v = torch.div(pixels, W, rounding_mode="floor").to(frame.K.dtype)
    cx, cy = frame.K[0, 2], frame.K[1, 2]
    far = math.hypot(max(float(cx), W - 1 - float(cx)), max(float(cy), H - 1 - float(cy)))
    gamma2 = ((u - cx) ** 2 + (v - cy) ** 2) / far ** 2
    return torch.exp(-gamma2 / (2 * sigma ** 2))


def pixel_weights(frame: Frame, pixels: torch.Tensor) -> torch.Tensor:
    """The frame's per-pixel weight (:attr:`Frame.weight`, e.g. a completer's confidence) at ``pixels``, 1 where the
    frame has none. Shape: pixels (F,) flat indices -> (F,)."""
    if frame.weight is None:
        return torch.ones(pixels.shape[0], dtype=frame.depth.dtype, device=pixels.device)
    return frame.weight.reshape(-1).index_select(0, pixels)


def surfel_radius(frame: Frame, points_cam: torch.Tensor, normals_cam: torch.Tensor) -> torch.Tensor:
    """Keller's surfel radius sqrt(2) z / f / |cos(view angle)| (cosine clamped at 0.2). Shape: (F, 3) -> (F,)."""
    f = 0.5 * (frame.K[0, 0].abs() + frame.K[1, 1].abs())  # fy < 0 for ICL-NUIM
    z = points_cam[:, 2]
    # vector_norm: the op Tensor.norm runs, without torch.functional.norm's Python around it (the same bits)
    ray = points_cam / torch.linalg.vector_norm(points_cam, dim=1, keepdim=True).clamp_min(1e-9)
    cos = (ray * normals_cam).sum(1).abs().clamp_min(0.2)
    return math.sqrt(2) * z / f / cos


def camera_surfels(frame: Frame):
    """Valid pixels of a frame as camera-frame surfels: (pixels (F,), points (F, 3), normals (F, 3), colors (F, 3),
    radius (F,)). They depend on the frame alone: kept in :attr:`Frame.cache`, so they may be computed ahead."""
    if "surfels" not in frame.cache:
        pixels, v_cam = valid_points(frame)
        n_cam, colors = valid_normals(frame), valid_colors(frame)
        if colors is None:
            colors = torch.full_like(v_cam, 0.5)
        frame.cache["surfels"] = (pixels, v_cam, n_cam, colors, surfel_radius(frame, v_cam, n_cam))
    return frame.cache["surfels"]


def frame_surfels(frame: Frame, T_world_cam: torch.Tensor):
    """Valid pixels of a frame as world-frame surfels: (pixels (F,), points (F, 3), normals (F, 3), colors (F, 3),
    radius (F,), points in the camera frame (F, 3))."""
    pixels, v_cam, n_cam, colors, radius = camera_surfels(frame)
    T = T_world_cam.to(v_cam.dtype)
    return pixels, transform_points(T, v_cam), rotate(T, n_cam), colors, radius, v_cam


def fusion_weights(frame: Frame, sigma: float) -> torch.Tensor:
    """Keller's weight times the frame's own weight at the pixels of :func:`camera_surfels` (cached per sigma)."""
    key = ("fusion-weights", sigma)
    if key not in frame.cache:
        pixels = camera_surfels(frame)[0]
        frame.cache[key] = surfel_weights(frame, pixels, sigma) * pixel_weights(frame, pixels)
    return frame.cache[key]


class PointFusion(MapperBase):
    """The PointFusion mapper: call :meth:`integrate` once per frame with its pose, read :attr:`map`.

    Args:
        voxel_size: metres; one map point per voxel (0 disables voxel merging: growth then follows time).
        max_distance, max_relative_distance: association gate max(max_distance, max_relative_distance * depth), m.
        max_normal_angle_deg: association gate on the angle between map and frame normals.
        sigma: Keller's sigma of the radial confidence weight.
        min_observations, prune_after: points seen in fewer frames and not updated for ``prune_after`` frames are
            removed.
        keep_graph: keep the autograd graph across frames (for a loss on the final map); otherwise the map is
            detached after every frame and memory stays flat.
        splat: rendering footprint (pixels each side) of map points when the map is rendered for odometry.
        window, archive: local map of the last ``window`` frames (0: the whole map), see
            :class:`~dcslam.slam.pointmap.MapperBase`.
    """

    def __init__(self, voxel_size: float = 0.05, max_distance: float = 0.1, max_relative_distance: float = 0.02,
                 max_normal_angle_deg: float = 30.0, sigma: float = 0.6, min_observations: int = 2,
                 prune_after: int = 5, keep_graph: bool = False, splat: int = 1, window: int = 0,
                 archive: bool = True):
        self.voxel_size, self.window, self.archive = voxel_size, window, archive
        self.max_distance, self.max_relative_distance = max_distance, max_relative_distance
        self.cos_max_angle = math.cos(math.radians(max_normal_angle_deg))
        self.sigma = sigma
        self.min_observations, self.prune_after = min_observations, prune_after
        self.keep_graph, self.splat = keep_graph, splat
        self.reset()

    def integrate(self, frame: Frame, T_world_cam: torch.Tensor, scale: float = 1.0) -> PointMap:
        """Fuse one frame seen from ``T_world_cam`` (4, 4) into the map, at the voxel size ``voxel_size * scale``
        (``scale``: the scene scale, see :class:`dcslam.slam.parts.Mapper`); returns the new map."""
        t = self.frames
        dtype, device = frame.depth.dtype, frame.depth.device
        pm = self.map if self.map is not None else PointMap.empty(dtype, device)
        pixels, p_w, n_w, colors, radius, v_cam = frame_surfels(frame, T_world_cam)
        weight = fusion_weights(frame, self.sigma)
        target = torch.full_like(pixels, -1)
        free_space = torch.zeros(len(pm), dtype=torch.bool, device=device)
        if len(pm) and len(pixels):
            target, free_space = self._associate(pm, frame, T_world_cam, pixels, v_cam, n_w)
        voxel = self.voxel_size * scale
        target, new_keys = assign_voxels(pm, voxel_keys(p_w, voxel) if voxel > 0 else torch.zeros_like(pixels),
                                         target, voxel)
        pm = merge(pm, target, new_keys, p_w, n_w, colors, radius, weight, t)
        stale = (pm.observations < self.min_observations) & (pm.last_seen < t - self.prune_after)
        unstable_in_free_space = torch.cat([free_space, torch.zeros(len(new_keys), dtype=torch.bool, device=device)])
        unstable_in_free_space &= (pm.observations < self.min_observations) & (pm.last_seen < t)
        drop = stale | unstable_in_free_space
        if bool(drop.any()):
            pm = pm.select(~drop)
        if not self.keep_graph:
            pm = pm.detach()
        self.map = self._slide(pm)
        self.frames += 1
        return self.map

    def precompute(self, frame: Frame) -> None:
        """Do the work on ``frame`` that does not depend on the map or the pose (its surfels and weights)."""
        fusion_weights(frame, self.sigma)

    def _associate(self, pm: PointMap, frame: Frame, T_world_cam: torch.Tensor, pixels: torch.Tensor,
                   v_cam: torch.Tensor, n_w: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Projective association: (target (F,) map index or -1, free-space flags (P,) bool)."""
        H, W = frame.shape
        device = pixels.device
        p_cam = transform_points(inverse(T_world_cam.to(pm.points.dtype)), pm.points.detach())
        uv, z = project(p_cam, frame.K)
        px = torch.round(uv).to(torch.int64)
        inside = (z > 0) & (px[:, 0] >= 0) & (px[:, 0] < W) & (px[:, 1] >= 0) & (px[:, 1] < H)
        # the frame surfel at each pixel: int32 slots written by index_copy_ (half the image, twice as fast to
        # fill as int64 slots written by index_put)
        slot_of_pixel = torch.full((H * W,), -1, dtype=torch.int32, device=device)
        slot_of_pixel.index_copy_(0, pixels, torch.arange(len(pixels), dtype=torch.int32, device=device))
        j = torch.nonzero(inside).squeeze(1)
        pj = px.index_select(0, j)
        i = slot_of_pixel.index_select(0, pj[:, 1] * W + pj[:, 0]).long()
        kept = torch.nonzero(i >= 0).squeeze(1)
        j, i = j.index_select(0, kept), i.index_select(0, kept)
        v_i = v_cam.detach().index_select(0, i)
        z_frame = v_i[:, 2]
        gate = torch.clamp(self.max_relative_distance * z_frame, min=self.max_distance)
        dist = torch.linalg.vector_norm(p_cam.index_select(0, j) - v_i, dim=1)
        agree = (pm.normals.detach().index_select(0, j) * n_w.detach().index_select(0, i)).sum(1) > self.cos_max_angle
        ok = (dist < gate) & agree
        free_space = torch.zeros(len(pm), dtype=torch.bool, device=device)
        free_space[j[z.index_select(0, j) < z_frame - gate]] = True
        target = torch.full_like(pixels, -1)
        ok = torch.nonzero(ok).squeeze(1)
        if ok.numel():
            i_ok, j_ok = i.index_select(0, ok), j.index_select(0, ok)
            score = pm.confidence.detach().index_select(0, j_ok) - dist.index_select(0, ok) / (
                2 * gate.index_select(0, ok))
            best = torch.full((len(pixels),), -float("inf"), dtype=score.dtype, device=device)
            best.scatter_reduce_(0, i_ok, score, reduce="amax")
            win = score >= best[i_ok]
            target[i_ok[win]] = j_ok[win]
        return target, free_space
