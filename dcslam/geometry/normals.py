"""Surface normals of a vertex map, from neighbours on the same surface only.

gradSLAM took central differences of the immediate neighbours, across depth edges and holes alike. Here each of the
four directions uses the nearest *valid* pixel within ``search`` pixels (so LiDAR-like sparse scan lines find their
neighbours), and a neighbour whose depth differs by more than ``max_relative_gap`` of the centre depth (a depth edge)
is not used. Central differences where both sides are usable, one-sided otherwise; no normal where a tangent is
missing. Normals face the camera (``n . p < 0``).
"""
from __future__ import annotations

import torch

from dcslam.errors import DcslamError


def _nearest(vertex: torch.Tensor, valid: torch.Tensor, dy: int, dx: int, search: int,
             max_relative_gap: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Nearest valid neighbour along the unit direction (dy, dx) within ``search`` steps, and whether it lies on the
    same surface. One running minimum / maximum over the row or column, so the cost does not grow with ``search``
    (LiDAR rows are a few pixels apart near the car and tens of pixels far away)."""
    dim = 3 if dx else 2
    forward = (dx or dy) > 0
    n = valid.shape[dim]
    shape = [1, 1, 1, 1]
    shape[dim] = n
    position = torch.arange(n, device=valid.device).view(shape)
    if forward:        # nearest valid index > j: running minimum from the far end, shifted by one
        idx = torch.where(valid, position, torch.full_like(position, n))
        idx = torch.flip(torch.flip(idx, [dim]).cummin(dim).values, [dim])
        idx = torch.cat([idx.narrow(dim, 1, n - 1), torch.full_like(idx.narrow(dim, 0, 1), n)], dim)
    else:              # nearest valid index < j: running maximum from the near end, shifted by one
        idx = torch.where(valid, position, torch.full_like(position, -1))
        idx = idx.cummax(dim).values
        idx = torch.cat([torch.full_like(idx.narrow(dim, 0, 1), -1), idx.narrow(dim, 0, n - 1)], dim)
    steps = (idx - position).abs()
    found = (idx >= 0) & (idx < n) & (steps <= search)
    gather = idx.clamp(0, n - 1)
    neighbour = torch.gather(vertex, dim, gather.expand(-1, 3, -1, -1))
    z = vertex[:, 2:3]
    same_surface = found & ((neighbour[:, 2:3] - z).abs() <= max_relative_gap * steps.to(z.dtype) * z)
    return neighbour, same_surface


def vertex_normals(vertex: torch.Tensor, valid: torch.Tensor | None = None, search: int = 1,
                   max_relative_gap: float = 0.1) -> tuple[torch.Tensor, torch.Tensor]:
    """Unit normals of a vertex map (camera frame), facing the camera.

    Args:
        vertex: camera-frame points per pixel (see :func:`dcslam.geometry.camera.backproject`).
        valid: pixels with a point; default ``vertex z > 0``.
        search: how far (pixels) to look for the nearest valid neighbour in each direction; 1 for dense depth,
            about 8 for LiDAR-like sparse depth.
        max_relative_gap: neighbours whose depth differs by more than this fraction of the centre depth per pixel
            of distance are taken to lie across a depth edge and are not used.

    Shape: vertex (B, 3, H, W), valid (B, 1, H, W) bool -> (normals (B, 3, H, W), valid (B, 1, H, W) bool);
    normals are zero where not valid.
    """
    if not isinstance(vertex, torch.Tensor) or vertex.ndim != 4 or vertex.shape[1] != 3:
        raise DcslamError(f"vertex has shape {tuple(getattr(vertex, 'shape', ()))}, expected (B, 3, H, W)")
    if valid is None:
        valid = vertex[:, 2:3] > 0
    elif valid.shape != (vertex.shape[0], 1, *vertex.shape[2:]) or valid.dtype != torch.bool:
        raise DcslamError(f"valid has shape {tuple(valid.shape)} and dtype {valid.dtype}, expected "
                          f"{(vertex.shape[0], 1, *vertex.shape[2:])} bool")
    if search < 1:
        raise DcslamError(f"search must be >= 1, got {search}")
    tangents = []
    for (dy, dx) in ((0, 1), (1, 0)):
        fwd, ok_f = _nearest(vertex, valid, dy, dx, search, max_relative_gap)
        bwd, ok_b = _nearest(vertex, valid, -dy, -dx, search, max_relative_gap)
        t = torch.where(ok_f & ok_b, fwd - bwd,
                        torch.where(ok_f, fwd - vertex, torch.where(ok_b, vertex - bwd, torch.zeros_like(vertex))))
        tangents.append((t, ok_f | ok_b))
    (tx, ok_x), (ty, ok_y) = tangents
    n = torch.cross(tx, ty, dim=1)
    norm2 = (n * n).sum(1, keepdim=True)
    ok = valid & ok_x & ok_y & (norm2 > 1e-20)
    norm = torch.sqrt(torch.where(ok, norm2, torch.ones_like(norm2)))
    n = torch.where(ok, n / norm, torch.zeros_like(n))
    facing = (n * vertex).sum(1, keepdim=True) > 0
    n = torch.where(facing, -n, n)
    return n, ok
