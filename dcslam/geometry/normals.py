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


#: the integer type of each floating type's bits, for :func:`choose`
_BITS = {torch.float32: torch.int32, torch.float64: torch.int64}


def choose(condition: torch.Tensor, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """``torch.where(condition, a, b)`` for tensors of one floating dtype (broadcast as where broadcasts), bit for
    bit. Without a graph on the CPU it selects the bits by integer masks, ``b ^ ((a ^ b) & mask)``: three vectorised
    passes, 2.5 times faster than torch.where's kernel on a 1242 x 375 x 3 image (0.9 against 2.3 ms); otherwise,
    and for other dtypes, torch.where."""
    bits = _BITS.get(a.dtype)
    if (bits is None or b.dtype != a.dtype or a.device.type != "cpu" or b.device.type != "cpu"
            or (torch.is_grad_enabled() and (a.requires_grad or b.requires_grad))):
        return torch.where(condition, a, b)
    mask = condition.to(bits).neg_()            # all ones where true, zero where false
    ai, bi = a.view(bits), b.view(bits)
    # in place where the condition does not widen the result: one new image, as torch.where makes (each new
    # image costs page faults as well as its writes)
    x = torch.bitwise_xor(ai, bi)
    wider = mask.dim() > x.dim() or any(m > n for m, n in zip(mask.shape[::-1], x.shape[::-1]))
    x = torch.bitwise_and(x, mask) if wider else x.bitwise_and_(mask)
    return x.bitwise_xor_(bi).view(a.dtype)


def _neighbours(line: torch.Tensor, step: torch.Tensor, search: int):
    """For points in scan-line order (sorted by line, then by step along the line), the previous and next point on
    the same line within ``search`` pixels. Shape: line, step (N,) -> (prev (N,), next (N,), prev_steps (N,),
    next_steps (N,)) where prev / next index into that order, -1 = none."""
    n = line.shape[0]
    gap = step[1:] - step[:-1]
    same = (line[1:] == line[:-1]) & (gap <= search)
    ar = torch.arange(n, device=line.device)
    none = torch.full((1,), -1, dtype=torch.int64, device=line.device)
    nxt = torch.cat([torch.where(same, ar[1:], -1), none])
    prv = torch.cat([none, torch.where(same, ar[:-1], -1)])
    zero = torch.zeros(1, dtype=step.dtype, device=step.device)
    return prv, nxt, torch.cat([zero, gap]), torch.cat([gap, zero])


def _tangent(points: torch.Tensor, order: torch.Tensor | None, line: torch.Tensor, step: torch.Tensor, search: int,
             max_relative_gap: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Central (or one-sided) difference along scan lines of valid points, skipping neighbours across a depth edge.
    ``order`` puts the points in scan-line order (None: they already are); ``line`` and ``step`` are given in that
    order. Shape: points (N, 3) -> (tangents (N, 3) in the input order, ok (N,) bool)."""
    prv, nxt, prv_steps, nxt_steps = _neighbours(line, step, search)
    p = points if order is None else points.index_select(0, order)   # index_select: advanced indexing is slower
    z = p[:, 2].detach()

    def side(index, steps):
        q = p.index_select(0, index.clamp_min(0))
        ok = (index >= 0) & ((q[:, 2].detach() - z).abs() <= max_relative_gap * steps.to(z.dtype) * z)
        return q, ok

    fwd, ok_f = side(nxt, nxt_steps)
    bwd, ok_b = side(prv, prv_steps)
    # both sides: fwd - bwd; one side: fwd - p or p - bwd; none: p - p = 0
    t = torch.where(ok_f[:, None], fwd, p) - torch.where(ok_b[:, None], bwd, p)
    ok = ok_f | ok_b
    if order is None:
        return t, ok
    return torch.empty_like(t).index_copy(0, order, t), torch.empty_like(ok).index_copy(0, order, ok)


def _grid_normals(vertex: torch.Tensor, valid: torch.Tensor,
                  max_relative_gap: float) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`vertex_normals` for ``search`` = 1 (dense depth) in one pass over the pixel grid: each pixel's four
    neighbours are views into one zero-padded copy of the vertex map (no sorting, gathering or shifted copies), and
    the values per valid pixel are the general path's (:func:`_tangent`, :func:`_unit_normals`), bit for bit.

    A neighbour or the pixel itself is chosen as :func:`_tangent` chooses, ``torch.where``'s values (by
    :func:`choose`: four times faster than blending with 0/1 masks); the normalisation and the turn to the camera
    multiply by 0/1 masks (``x * 1`` is ``x`` exactly). Shape: vertex (B, 3, H, W), valid (B, 1, H, W) ->
    (normals (B, 3, H, W), valid (B, 1, H, W))."""
    from dcslam.native import grid_normals

    native = grid_normals(vertex, valid, max_relative_gap)   # the same values in one pass, where it applies
    if native is not None:
        return native
    B, _, H, W = vertex.shape
    dtype = vertex.dtype
    P = choose(valid, vertex, torch.zeros((), dtype=dtype, device=vertex.device))
    padded = P.new_zeros(B, 3, H + 2, W + 2)
    padded[:, :, 1:-1, 1:-1] = P
    has = valid.new_zeros(B, 1, H + 2, W + 2)
    has[:, :, 1:-1, 1:-1] = valid
    z = P[:, 2:3].detach()
    limit = max_relative_gap * torch.ones((), dtype=z.dtype, device=z.device) * z   # as _tangent (one pixel apart)

    def side(dy: int, dx: int) -> tuple[torch.Tensor, torch.Tensor]:
        """The neighbour at (dy, dx) where it is usable, else the pixel itself: ((B, 3, H, W), ok (B, 1, H, W))."""
        q = padded[:, :, 1 + dy:1 + dy + H, 1 + dx:1 + dx + W]
        ok = has[:, :, 1 + dy:1 + dy + H, 1 + dx:1 + dx + W] & ((q[:, 2:3].detach() - z).abs() <= limit)
        return choose(ok, q, P), ok

    # both sides: fwd - bwd; one side: fwd - p or p - bwd; none: p - p = 0
    (fwd, ok_r), (bwd, ok_l), (down, ok_d), (up, ok_u) = side(0, 1), side(0, -1), side(1, 0), side(-1, 0)
    n = _cross_channels(fwd.sub_(bwd), down.sub_(up))   # in place: where keeps no value of its own for backward
    norm2 = (n * n).sum(1, keepdim=True)
    ok = valid & (ok_r | ok_l) & (ok_d | ok_u) & (norm2 > 1e-20)
    m = ok.to(dtype)
    n = n / torch.sqrt(norm2 * m + (1 - m)) * m
    facing = (n * P).sum(1, keepdim=True) > 0
    return n * (1 - 2 * facing.to(dtype)), ok


def _cross_channels(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """torch.cross over the channels of (B, 3, H, W) images, each image taken as (3, H W): its kernel, the same
    values (it rounds once, by fma: products by hand would not), three times faster here than across the channel
    dimension of the 4-d images (3.4 against 9.9 ms at 1242 x 375)."""
    B, _, H, W = a.shape
    if B == 1:
        return torch.cross(a.reshape(3, H * W), b.reshape(3, H * W), dim=0).view(1, 3, H, W)
    return torch.stack([torch.cross(x.reshape(3, H * W), y.reshape(3, H * W), dim=0) for x, y in zip(a, b)]).view(
        B, 3, H, W)


def _unit_normals(tx: torch.Tensor, ty: torch.Tensor, ok: torch.Tensor,
                  points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Unit normals from the tangents along rows and columns (their cross product), turned to face the camera;
    zero where ``ok`` is false or the tangents are parallel. Shape: tx, ty, points (..., 3), ok (...) ->
    (normals (..., 3), ok (...))."""
    n = torch.cross(tx, ty, dim=-1)
    norm2 = (n * n).sum(-1, keepdim=True)
    ok = ok & (norm2[..., 0] > 1e-20)
    n = torch.where(ok[..., None], n / torch.sqrt(torch.where(ok[..., None], norm2, torch.ones_like(norm2))),
                    torch.zeros_like(n))
    return torch.where(((n * points).sum(-1, keepdim=True) > 0), -n, n), ok


def vertex_normals(vertex: torch.Tensor, valid: torch.Tensor | None = None, search: int = 1,
                   max_relative_gap: float = 0.1) -> tuple[torch.Tensor, torch.Tensor]:
    """Unit normals of a vertex map (camera frame), facing the camera.

    Neighbours are the nearest valid pixels along the row and along the column (scan lines), found by sorting the
    valid pixels only: the cost follows the number of measurements, not the image size or ``search``.

    Args:
        vertex: camera-frame points per pixel (see :func:`dcslam.geometry.camera.backproject`).
        valid: pixels with a point (finite there); default ``vertex z > 0``.
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
    if search == 1 and H > 1 and W > 1:
        return _grid_normals(vertex, valid, max_relative_gap)
    return _scan_line_normals(vertex, valid, search, max_relative_gap)


def _scan_line_normals(vertex: torch.Tensor, valid: torch.Tensor, search: int,
                       max_relative_gap: float) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`vertex_normals` by sorting the valid pixels into scan lines (any ``search``; checked inputs)."""
    B, _, H, W = vertex.shape
    idx = torch.nonzero(valid.reshape(-1)).squeeze(1)                 # (b, v, u) raster order
    if idx.numel() == 0:
        return torch.zeros_like(vertex), torch.zeros_like(valid)
    points = vertex.permute(0, 2, 3, 1).reshape(-1, 3)[idx]
    n, ok = point_normals(points, idx, (B, H, W), search, max_relative_gap)
    normals = torch.zeros(B * H * W, 3, dtype=vertex.dtype, device=vertex.device).index_put((idx,), n)
    mask = torch.zeros(B * H * W, dtype=torch.bool, device=vertex.device).index_put((idx,), ok)
    return normals.view(B, H, W, 3).permute(0, 3, 1, 2), mask.view(B, 1, H, W)


def point_normals(points: torch.Tensor, idx: torch.Tensor, shape: tuple[int, int, int], search: int,
                  max_relative_gap: float) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`vertex_normals` of the valid pixels alone, given as their points and flat indices: the values at those
    pixels, bit for bit (the work follows the number of points, never the image size).

    Shape: points (N, 3) camera frame, idx (N,) int64 flat indices into (B, H, W) in increasing (raster) order,
    shape (B, H, W) -> (normals (N, 3), ok (N,) bool)."""
    B, H, W = shape
    if idx.numel() == 0:
        return points.new_zeros(0, 3), torch.zeros(0, dtype=torch.bool, device=points.device)
    from dcslam.native import point_normals as native_point_normals

    native = native_point_normals(points, idx, shape, search, max_relative_gap)   # the same values, where it applies
    if native is not None:
        return native
    b, rem = torch.div(idx, H * W, rounding_mode="floor"), idx % (H * W)
    v, u = torch.div(rem, W, rounding_mode="floor"), rem % W
    # Rows: the raster order of idx is already scan-line order. Columns: sorted by (b, u, v); every key is unique,
    # so the order is the same however it is found: for dense depth, by transposing the mask (linear in the image
    # size), for sparse depth by sorting the few valid pixels' keys.
    tx, ok_x = _tangent(points, None, b * H + v, u, search, max_relative_gap)
    if 8 * idx.numel() < B * H * W:
        order = torch.argsort((b * W + u) * H + v)
    else:
        rank = torch.empty(B * H * W, dtype=torch.int64, device=idx.device).index_put_(
            (idx,), torch.arange(idx.numel(), device=idx.device))
        mask = torch.zeros(B * H * W, dtype=torch.bool, device=idx.device).index_fill_(0, idx, True)
        raster = torch.arange(B * H * W, device=idx.device).view(B, H, W).transpose(1, 2)
        order = rank[raster[mask.view(B, H, W).transpose(1, 2)]]
    ty, ok_y = _tangent(points, order, (b * W + u).index_select(0, order), v.index_select(0, order), search,
                        max_relative_gap)
    return _unit_normals(tx, ty, ok_x & ok_y, points)
