"""Data association for point-to-plane ICP: which target point (and normal) each source point is compared with.

A target is a :class:`~dcslam.slam.pointmap.ModelView`: a map rendered into a camera, or a frame's own vertex map
(:func:`view_from_frame`). Associations return indices into the source points and the matched target points and
normals in the world frame; the gates are applied by the ICP problem.
"""
from __future__ import annotations

import torch

from dcslam.geometry.se3 import inverse, rotate, rows_times, transform_points
from dcslam.slam.frame import Frame
from dcslam.slam.pointmap import ModelView


def view_from_frame(frame: Frame, T_world_cam: torch.Tensor) -> ModelView:
    """A frame's vertex and normal maps as an ICP target seen from ``T_world_cam`` (frame-to-frame ICP): its points
    are the frame's pixels, each pixel's index its own (-1 where invalid)."""
    T = T_world_cam.to(frame.vertex.dtype)
    H, W = frame.shape
    flat = frame.valid.reshape(-1)
    index = torch.where(flat, torch.arange(H * W, device=flat.device), torch.full_like(flat, -1, dtype=torch.int64))
    points = transform_points(T, frame.vertex.reshape(-1, 3))
    return ModelView(index.view(H, W), points, rotate(T, frame.normal.reshape(-1, 3)), frame.valid, T, frame.K)


class ProjectiveAssociation:
    """Project each source point (moved by the current pose) into the target view and take that pixel's point:
    O(pixels), the association of KinectFusion and gradSLAM."""

    def prepare(self, target: ModelView) -> "ProjectiveAssociation._Prepared":
        return self._Prepared(target)

    class _Prepared:
        def __init__(self, target: ModelView):
            self.target = target
            self.T_ref_world = inverse(target.T_world_cam)
            self.height, self.width = target.valid.shape
            self.index = target.index.reshape(-1)
            # point and normal side by side: one gather per iteration fetches both (the target's points, not an
            # image of them: a map has a few times fewer points than the image has pixels)
            self.table = torch.cat([target.points, target.normals], 1)
            # what transform_points and project take from the pose and K on every call, taken once: the same
            # products in the same order (an ICP iteration costs its calls more than its arithmetic). rows_times
            # makes the rotation contiguous on the CPU, where it is so made here once; elsewhere it stays the view
            R_T = self.T_ref_world[:3, :3].transpose(-1, -2)
            self.R_T, self.t = (R_T.contiguous() if R_T.device.type == "cpu" else R_T), self.T_ref_world[:3, 3]
            # K's entries as numbers: a number meets a tensor in the tensor's dtype, as K.to(points' dtype) does
            self.fx, self.fy, self.cx, self.cy = (float(target.K[i, j]) for i, j in ((0, 0), (1, 1), (0, 2), (1, 2)))
            self.few_pixels = self.height * self.width <= 2 ** 24     # v * width + u exact in float32

        def __call__(self, points_world: torch.Tensor):
            """points_world (F, 3) -> (source index (M,), target points (M, 3), target normals (M, 3)); the targets
            are views into one (M, 6) tensor. The pixels are :func:`~dcslam.geometry.camera.project`'s of
            ``transform_points(T_ref_world, points_world)``, rounded."""
            x, y, z = (rows_times(points_world.detach(), self.R_T) + self.t).unbind(1)
            z_safe = torch.where(z.abs() > 1e-9, z, 1e-9)
            u, v = torch.round(self.fx * x / z_safe + self.cx), torch.round(self.fy * y / z_safe + self.cy)
            inside = (z > 0) & (u >= 0) & (u <= self.width - 1) & (v >= 0) & (v <= self.height - 1)
            # every point's pixel (0 outside the image) and its target's index, then one nonzero over inside & a
            # target (gathers with index_select: several times faster than boolean masks and advanced indexing)
            exact = v.dtype == torch.float64 or (v.dtype == torch.float32 and self.few_pixels)
            lin = v * self.width + u if exact else v.double() * self.width + u.double()
            target = self.index.index_select(0, torch.where(inside, lin, 0).to(torch.int64))
            src = torch.nonzero(inside & (target >= 0)).squeeze(1)
            pairs = self.table.index_select(0, target.index_select(0, src))
            return src, pairs[:, :3], pairs[:, 3:]


class NearestNeighbourAssociation:
    """The nearest target point in 3-D (a KD-tree, scipy ``cKDTree``, built once per target, searched without
    gradient; residuals are then computed in torch), as in Open3D's ``registration_icp``."""

    def __init__(self, workers: int = -1):
        self.workers = workers

    def prepare(self, target: ModelView) -> "NearestNeighbourAssociation._Prepared":
        return self._Prepared(target, self.workers)

    class _Prepared:
        def __init__(self, target: ModelView, workers: int):
            from scipy.spatial import cKDTree

            index = target.index.reshape(-1)
            index = index.index_select(0, torch.nonzero(index >= 0).squeeze(1))
            self.points = target.points.index_select(0, index)
            self.normals = target.normals.index_select(0, index)
            self.workers = workers
            self.tree = cKDTree(self.points.detach().cpu().double().numpy()) if len(self.points) else None

        def __call__(self, points_world: torch.Tensor):
            device = points_world.device
            if self.tree is None:
                empty = torch.zeros(0, dtype=torch.int64, device=device)
                return empty, self.points, self.normals
            _, nearest = self.tree.query(points_world.detach().cpu().double().numpy(), k=1, workers=self.workers)
            nearest = torch.from_numpy(nearest).to(device)
            src = torch.arange(points_world.shape[0], device=device)
            return src, self.points[nearest], self.normals[nearest]
