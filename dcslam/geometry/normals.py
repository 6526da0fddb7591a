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


def _neighbours(key: torch.Tensor, line: torch.Tensor, step: torch.Tensor, search: int):
    """For points sorted by ``key`` (their position along scan lines), the previous and next point on the same line
    within ``search`` pixels. Shape: key, line, step (N,) -> (order (N,), prev (N,), next (N,), prev_steps (N,),
    next_steps (N,)) where prev / next index into the sorted order, -1 = none."""
    order = torch.argsort(key)
    line_s, step_s = line[order], step[order]
    n = key.shape[0]
    same = (line_s[1:] == line_s[:-1]) & (step_s[1:] - step_s[:-1] <= search)
    ar = torch.arange(n, device=key.device)
    none = torch.full((1,), -1, dtype=torch.int64, device=key.device)
    nxt = torch.cat([torch.where(same, ar[1:], -1), none])
    prv = torch.cat([none, torch.where(same, ar[:-1], -1)])
    gap = torch.cat([step_s[1:] - step_s[:-1], torch.zeros(1, dtype=step.dtype, device=step.device)])
    return order, prv, nxt, torch.cat([gap[-1:] * 0, gap[:-1]]), gap


def _tangent(points: torch.Tensor, key: torch.Tensor, line: torch.Tensor, step: torch.Tensor, search: int,
             max_relative_gap: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Central (or one-sided) difference along scan lines of valid points, skipping neighbours across a depth edge.
    Shape: points (N, 3) -> (tangents (N, 3) in the input order, ok (N,) bool)."""
    order, prv, nxt, prv_steps, nxt_steps = _neighbours(key, line, step, search)
    p = points[order]
    z = p[:, 2].detach()

    def side(index, steps):
        q = p[index.clamp_min(0)]
        ok = (index >= 0) & ((q[:, 2].detach() - z).abs() <= max_relative_gap * steps.to(z.dtype) * z)
        return q, ok

    fwd, ok_f = side(nxt, nxt_steps)
    bwd, ok_b = side(prv, prv_steps)
    t = torch.where((ok_f & ok_b)[:, None], fwd - bwd,
                    torch.where(ok_f[:, None], fwd - p, torch.where(ok_b[:, None], p - bwd, torch.zeros_like(p))))
    out = torch.empty_like(t).index_copy(0, order, t)
    ok = torch.empty_like(ok_f).index_copy(0, order, ok_f | ok_b)
    return out, ok


def vertex_normals(vertex: torch.Tensor, valid: torch.Tensor | None = None, search: int = 1,
                   max_relative_gap: float = 0.1) -> tuple[torch.Tensor, torch.Tensor]:
    """Unit normals of a vertex map (camera frame), facing the camera.

    Neighbours are the nearest valid pixels along the row and along the column (scan lines), found by sorting the
    valid pixels only: the cost follows the number of measurements, not the image size or ``search``.

    Args:
        vertex: camera-frame points per pixel (see :func:`dcslam.geometry.camera.backproject`).
        valid: pixels with a point; default ``vertex z > 0``.
        search: how far (pixels) to look for the nearest valid neighbour in each direction; 1 for dense depth,
            tens of pixels for LiDAR-like sparse depth (its rows are tens of pixels apart far from the car).
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
    B, _, H, W = vertex.shape
    idx = torch.nonzero(valid.reshape(-1)).squeeze(1)                 # (b, v, u) raster order
    if idx.numel() == 0:
        return torch.zeros_like(vertex), torch.zeros_like(valid)
    b, rem = torch.div(idx, H * W, rounding_mode="floor"), idx % (H * W)
    v, u = torch.div(rem, W, rounding_mode="floor"), rem % W
    points = vertex.permute(0, 2, 3, 1).reshape(-1, 3)[idx]
    tx, ok_x = _tangent(points, idx, b * H + v, u, search, max_relative_gap)
    ty, ok_y = _tangent(points, (b * W + u) * H + v, b * W + u, v, search, max_relative_gap)
    n = torch.cross(tx, ty, dim=1)
    norm2 = (n * n).sum(1, keepdim=True)
    ok = ok_x & ok_y & (norm2[:, 0] > 1e-20)
    n = torch.where(ok[:, None], n / torch.sqrt(torch.where(ok[:, None], norm2, torch.ones_like(norm2))),
                    torch.zeros_like(n))
    n = torch.where(((n * points).sum(1, keepdim=True) > 0), -n, n)
    normals = torch.zeros(B * H * W, 3, dtype=vertex.dtype, device=vertex.device).index_put((idx,), n)
    mask = torch.zeros(B * H * W, dtype=torch.bool, device=vertex.device).index_put((idx,), ok)
    return normals.view(B, H, W, 3).permute(0, 3, 1, 2), mask.view(B, 1, H, W)
