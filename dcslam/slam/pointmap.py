"""The global point map shared by the mappers, its voxel keys, and rendering it into a camera (z-buffer).

A :class:`PointMap` is a set of surfels in the world frame. Its tensors may carry an autograd graph back to the
depth (and colour) images that made them; the bookkeeping tensors (``last_seen``, ``voxel_key``) never do.
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace

import torch

from dcslam.errors import DcslamError
from dcslam.geometry.camera import check_K, project
from dcslam.geometry.se3 import inverse, transform_points
from dcslam.native import first_of_each, merge_averages, voxel_lookup, zbuffer_window
from dcslam.native import voxel_keys as native_voxel_keys
from dcslam.slam.archive import MapArchive

_KEY_BITS = 21
_KEY_OFFSET = 1 << (_KEY_BITS - 1)


@dataclass
class PointMap:
    """A surfel map in the world frame.

    Shape: points (P, 3) metres, normals (P, 3) unit, colors (P, 3) in [0, 1], confidence (P,), radius (P,) metres,
    last_seen (P,) int64 frame index of the last update, observations (P,) int64 number of frames that updated the
    point, voxel_key (P,) int64 (see :func:`voxel_keys`).
    """

    points: torch.Tensor
    normals: torch.Tensor
    colors: torch.Tensor
    confidence: torch.Tensor
    radius: torch.Tensor
    last_seen: torch.Tensor
    observations: torch.Tensor
    voxel_key: torch.Tensor

    @classmethod
    def empty(cls, dtype: torch.dtype = torch.float32, device: torch.device | str | None = None) -> "PointMap":
        z3 = torch.zeros(0, 3, dtype=dtype, device=device)
        z1 = torch.zeros(0, dtype=dtype, device=device)
        zi = torch.zeros(0, dtype=torch.int64, device=device)
        return cls(z3, z3.clone(), z3.clone(), z1, z1.clone(), zi, zi.clone(), zi.clone())

    def __len__(self) -> int:
        return self.points.shape[0]

    def select(self, index: torch.Tensor) -> "PointMap":
        """The points at ``index`` (a (P,) bool mask or (Q,) int64 indices)."""
        if index.dtype == torch.bool:                  # one nonzero for the eight fields
            index = torch.nonzero(index).squeeze(1)
        return PointMap(*(getattr(self, f.name).index_select(0, index) for f in fields(self)))

    def detach(self) -> "PointMap":
        return PointMap(*(getattr(self, f.name).detach() for f in fields(self)))

    def to(self, device: torch.device | str) -> "PointMap":
        return PointMap(*(getattr(self, f.name).to(device) for f in fields(self)))

    def nbytes(self) -> int:
        return sum(getattr(self, f.name).element_size() * getattr(self, f.name).nelement() for f in fields(self))

    def cat(self, other: "PointMap") -> "PointMap":
        return PointMap(*(torch.cat([getattr(self, f.name), getattr(other, f.name)]) for f in fields(self)))

    def with_(self, **changes) -> "PointMap":
        return replace(self, **changes)


def voxel_keys(points: torch.Tensor, voxel_size: float) -> torch.Tensor:
    """One int64 per point naming its voxel (21 bits per axis: +-2^20 voxels, e.g. +-52 km at 5 cm).

    Shape: points (P, 3) -> (P,) int64.
    """
    if voxel_size <= 0:
        raise DcslamError(f"voxel_size must be > 0, got {voxel_size}")
    native = native_voxel_keys(points, voxel_size)     # the same keys in one pass (dcslam.native), where it applies
    if native is not None:
        return native
    # in place where the values allow: each new (P, 3) tensor costs page faults as well as its writes (1.6 x faster
    # on a full frame's 466k points than a new tensor per operation; the same keys)
    ijk = torch.div(points.detach(), voxel_size).floor_().to(torch.int64)
    ijk = ijk.add_(_KEY_OFFSET).clamp_(0, (1 << _KEY_BITS) - 1).t()
    return (ijk[0] << (2 * _KEY_BITS)).bitwise_or_(ijk[1] << _KEY_BITS).bitwise_or_(ijk[2])


def voxel_representatives(points: torch.Tensor, voxel_size: float) -> torch.Tensor:
    """Indices of one point per occupied voxel (the first in input order), sorted. Shape: (P, 3) -> (Q,) int64."""
    keys = voxel_keys(points, voxel_size)
    if keys.numel() == 0:
        return torch.zeros(0, dtype=torch.int64, device=points.device)
    native = first_of_each(keys)       # the same indices by a hash of the keys (dcslam.native), where it applies
    if native is not None:
        return native
    # a stable sort by voxel: the first entry of each run of equal keys is the voxel's first point in input order
    sorted_keys, order = torch.sort(keys, stable=True)
    starts = torch.ones_like(sorted_keys, dtype=torch.bool)
    starts[1:] = sorted_keys[1:] != sorted_keys[:-1]
    return torch.sort(order[starts]).values


@dataclass
class ModelView:
    """A point map rendered into a camera: per pixel the map point nearest to the camera.

    Shape: index (H, W) int64 into ``points`` and ``normals`` (-1 = empty); points (Q, 3) and normals (Q, 3) in the
    world frame (a map's points, or a frame's pixels); valid (H, W) bool (index >= 0); T_world_cam (4, 4) and
    K (3, 3) of the rendering camera. :attr:`vertex` and :attr:`normal` are the (H, W, 3) images, made on demand:
    ICP gathers its targets through ``index`` and never needs them (making them cost a SLAM step about a tenth of
    its time).
    """

    index: torch.Tensor
    points: torch.Tensor
    normals: torch.Tensor
    valid: torch.Tensor
    T_world_cam: torch.Tensor
    K: torch.Tensor

    def _image(self, values: torch.Tensor) -> torch.Tensor:
        """(H, W, 3): ``values`` at each pixel's index, zero where empty."""
        H, W = self.index.shape
        flat = self.index.reshape(-1)
        pix = torch.nonzero(flat >= 0).squeeze(1)
        image = torch.zeros(H * W, 3, dtype=values.dtype, device=values.device)
        return image.index_copy(0, pix, values.index_select(0, flat.index_select(0, pix))).view(H, W, 3)

    @property
    def vertex(self) -> torch.Tensor:
        """The point at each pixel, (H, W, 3) world frame (zero where empty)."""
        return self._image(self.points)

    @property
    def normal(self) -> torch.Tensor:
        """The normal at each pixel, (H, W, 3) world frame (zero where empty)."""
        return self._image(self.normals)


def render(pm: PointMap, T_world_cam: torch.Tensor, K: torch.Tensor, height: int, width: int,
           splat: int = 0) -> ModelView:
    """Render a map into a camera with a z-buffer; each point covers a (2 splat + 1)^2 pixel square.

    A pixel shows the nearest point whose square covers it; of equally near ones, the one whose own pixel (the
    square's centre) comes first in raster order, and of those the one with the highest index. Done as one z-buffer
    pass over the points at their own pixels (an image ``splat`` pixels wider on each side, as a square may reach
    in from outside) and a (2 splat + 1)^2 minimum filter in image space: the map's size costs one scatter, not
    one per pixel of the square.

    Shape: T_world_cam (4, 4), K (3, 3) -> :class:`ModelView` of (H, W) whose points are the map's.
    """
    if T_world_cam.shape != (4, 4):
        raise DcslamError(f"T_world_cam has shape {tuple(T_world_cam.shape)}, expected (4, 4)")
    K = check_K(K)[0]
    device, dtype = pm.points.device, pm.points.dtype
    index = torch.full((height * width,), -1, dtype=torch.int64, device=device)
    if len(pm):                                   # the index at the covered pixels only (few for a sparse map)
        pix, hit = _zbuffer(pm, T_world_cam, K, height, width, splat)
        index.index_copy_(0, pix, hit)
    index = index.view(height, width)
    return ModelView(index, pm.points, pm.normals, index >= 0, T_world_cam.to(dtype), K.to(dtype))


def _zbuffer(pm: PointMap, T_world_cam: torch.Tensor, K: torch.Tensor, height: int, width: int,
             splat: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The pixels :func:`render` covers and the point it shows at each. Shape: -> (pixels (C,) flat indices into
    H W, in raster order; points (C,) int64)."""
    device, dtype = pm.points.device, pm.points.dtype
    p_cam = transform_points(inverse(T_world_cam.to(dtype)), pm.points.detach())
    ids = torch.nonzero(p_cam[:, 2] > 0).squeeze(1)        # only points in front of the camera ...
    uv, z = project(p_cam.index_select(0, ids), K.to(dtype))
    px = torch.round(uv).to(torch.int64)
    seen = (px[:, 0] >= -splat) & (px[:, 0] < width + splat) & (px[:, 1] >= -splat) & (px[:, 1] < height + splat)
    seen = torch.nonzero(seen).squeeze(1)
    ids, px, z = ids.index_select(0, seen), px.index_select(0, seen), z.index_select(0, seen)  # ... within reach
    if ids.numel() == 0:
        return ids, ids
    # the window of the image the squares reach (rows r0.., columns c0..): outside it no pixel is covered, and
    # inside it the same centres compete, so the z-buffer and the filter below work on it alone (a street map
    # leaves the sky empty)
    (c0, r0), (c1, r1) = px.amin(0).tolist(), px.amax(0).tolist()
    c0, r0, c1, r1 = max(0, c0 - splat), max(0, r0 - splat), min(width - 1, c1 + splat), min(height - 1, r1 + splat)
    pix, hit = _zbuffer_window(ids, px - torch.tensor([c0, r0], device=device), z, r1 - r0 + 1, c1 - c0 + 1, splat,
                               (height + 2 * splat) * (width + 2 * splat))
    w = c1 - c0 + 1
    return (torch.div(pix, w, rounding_mode="floor") + r0) * width + pix % w + c0, hit


def _zbuffer_window(ids: torch.Tensor, px: torch.Tensor, z: torch.Tensor, height: int, width: int,
                    splat: int, capacity: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`_zbuffer` in a window of (height, width) pixels holding every pixel the points' squares reach.
    ``capacity``: the padded pixels of the whole image, which the native kernel holds from its first call (0:
    unknown). Shape: ids (N,) the points' indices, px (N, 2) int64 their pixels (u, v) in the window, z (N,) their
    depths -> (pixels (C,) flat indices into the window, in raster order; points (C,) int64)."""
    native = zbuffer_window(ids, px, z, height, width, splat, capacity)    # the same pixels and points in one pass
    if native is not None:
        return native
    device, dtype = z.device, z.dtype
    # the z-buffer at the points' own pixels, in an image padded by splat: (Hp, Wp)
    Hp, Wp = height + 2 * splat, width + 2 * splat
    centre = (px[:, 1] + splat) * Wp + (px[:, 0] + splat)
    zbuf = torch.full((Hp * Wp,), float("inf"), dtype=dtype, device=device)
    zbuf.scatter_reduce_(0, centre, z, reduce="amin")
    front = torch.nonzero(z <= zbuf.index_select(0, centre)).squeeze(1)
    owner = torch.full((Hp * Wp,), -1, dtype=torch.int64, device=device)
    owner.scatter_reduce_(0, centre.index_select(0, front), ids.index_select(0, front), reduce="amax")
    # the minimum filter, separable: along rows, then along columns. Pixel (v, u) sees the centre (v - dy, u - dx)
    # through the offset (dy, dx); of equal depths the largest dy, then the largest dx wins (the centre first in
    # raster order), so each pass keeps the largest offset that reaches its minimum
    zbuf, side = zbuf.view(Hp, Wp), 2 * splat + 1
    small = torch.uint8 if side < 256 else torch.int64     # offsets' indices: a quarter of the memory traffic

    def pass_(shifted: list[torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        """(minimum, the largest k with shifted[k] at the minimum) of same-shape images, in place after the first
        image of each (every new image costs page faults as well as its writes)."""
        low = torch.minimum(shifted[0], shifted[1]) if side > 1 else shifted[0].clone()
        for zk in shifted[2:]:
            torch.minimum(low, zk, out=low)
        k = torch.zeros(low.shape, dtype=small, device=device)
        for j, zk in enumerate(shifted[1:], 1):      # (masked_fill_ with the comparison: 2x slower on the CPU)
            torch.maximum(k, (zk == low).to(small) * j, out=k)
        return low, k

    # k = offset + splat; the centre of pixel (v, u) through offset k is (v - ky + splat, u - kx + splat) in the
    # image, (v - ky + 2 splat, u - kx + 2 splat) in the padded z-buffer
    row_low, kx = pass_([zbuf[:, 2 * splat - k:2 * splat - k + width] for k in range(side)])   # (Hp, W)
    low, ky = pass_([row_low[2 * splat - k:2 * splat - k + height] for k in range(side)])        # (H, W)
    pix = torch.nonzero(torch.isfinite(low).reshape(-1)).squeeze(1)     # covered: a centre with a point in reach
    v, u = torch.div(pix, width, rounding_mode="floor"), pix % width
    r = v + 2 * splat - ky.reshape(-1).index_select(0, pix).to(torch.int64)   # the centre's row, padded image
    c = u + 2 * splat - kx.reshape(-1).index_select(0, r * width + u).to(torch.int64)
    return pix, owner.index_select(0, r * Wp + c)


def assign_voxels(pm: PointMap, keys: torch.Tensor, target: torch.Tensor,
                  voxel_size: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Give every frame point without a target (-1) the map point of its voxel, or a new slot per new voxel.

    Shape: keys (F,) int64, target (F,) int64 (-1 = unassigned) -> (target (F,) all >= 0, new voxel keys (Q,)),
    where slots ``len(pm) ... len(pm) + Q - 1`` are new points.
    """
    n = len(pm)
    looked = voxel_lookup(pm.voxel_key, keys, target) if voxel_size > 0 else None   # by hashes (dcslam.native)
    if looked is not None:
        free, voxel_of, voxels, slot = looked
        fresh = torch.nonzero(slot < 0).squeeze(1)
        new_keys, rank = torch.sort(voxels.index_select(0, fresh))       # distinct keys: one order
        slot = slot.index_copy(0, fresh.index_select(0, rank), n + torch.arange(fresh.numel()))
        return target.index_copy(0, free, slot.index_select(0, voxel_of)), new_keys
    free = torch.nonzero(target < 0).squeeze(1)           # only these are looked up (few where projective
    target = target.clone()                                # association matched most of the frame)
    if voxel_size <= 0:
        target[free] = n + torch.arange(free.numel(), device=target.device)
        return target, keys.index_select(0, free)
    # the frame's distinct voxels, looked up once each: sorting the frame's keys and searching the distinct ones in
    # the sorted map keys is several times faster than a binary search per frame point
    voxels, voxel_of = torch.unique(keys.index_select(0, free), return_inverse=True)
    slot = torch.full_like(voxels, -1)
    if n and voxels.numel():
        sorted_keys, order = torch.sort(pm.voxel_key)
        pos = torch.searchsorted(sorted_keys, voxels).clamp_max(n - 1)
        slot = torch.where(sorted_keys.index_select(0, pos) == voxels, order.index_select(0, pos), slot)
    new = slot < 0                                         # new voxels: slots n, n + 1, ... in the order of keys
    slot = torch.where(new, n + torch.cumsum(new, 0) - 1, slot)
    target[free] = slot.index_select(0, voxel_of)
    return target, voxels[new]


def merge(pm: PointMap, target: torch.Tensor, new_keys: torch.Tensor, points: torch.Tensor, normals: torch.Tensor,
          colors: torch.Tensor, radius: torch.Tensor, weight: torch.Tensor, frame_index: int) -> PointMap:
    """Confidence-weighted averaging of frame surfels into their target map points (new slots start empty).

    A point updated by weights w_i becomes (c p + sum w_i p_i) / (c + sum w_i), its confidence c + sum w_i; normals
    are averaged the same way and renormalised. Differentiable with respect to every float input.

    Shape: target (F,) int64 in [0, P + Q), new_keys (Q,), points / normals / colors (F, 3) world frame,
    radius (F,), weight (F,) -> PointMap of P + Q points.
    """
    P, Q = len(pm), new_keys.shape[0]
    size = P + Q
    dtype, device = points.dtype, points.device
    native = merge_averages(pm, target, Q, points, normals, colors, radius, weight)   # one pass, where it applies
    if native is not None:
        p, n, col, rad, total, observed, square = native
        return PointMap(
            points=p, normals=n / torch.sqrt(square)[:, None], colors=col, confidence=total, radius=rad,
            last_seen=torch.where(observed > 0, frame_index,
                                  torch.cat([pm.last_seen, torch.zeros(Q, dtype=torch.int64, device=device)])),
            observations=torch.cat([pm.observations, torch.zeros(Q, dtype=torch.int64, device=device)])
            + (observed > 0).to(torch.int64),
            voxel_key=torch.cat([pm.voxel_key, new_keys]))
    pad3 = torch.zeros(Q, 3, dtype=dtype, device=device)
    pad1 = torch.zeros(Q, dtype=dtype, device=device)
    c = torch.cat([pm.confidence, pad1])
    w_sum = torch.zeros(size, dtype=dtype, device=device).index_add(0, target, weight)
    touched = w_sum > 0
    total = c + w_sum
    safe_total = torch.where(touched, total, torch.ones_like(total))

    def average(old: torch.Tensor, new: torch.Tensor) -> torch.Tensor:
        old = torch.cat([old, pad3 if old.ndim == 2 else pad1])
        w = weight[:, None] if new.ndim == 2 else weight
        s = torch.zeros_like(old).index_add(0, target, w * new)
        cc = c[:, None] if old.ndim == 2 else c
        tt = touched[:, None] if old.ndim == 2 else touched
        st = safe_total[:, None] if old.ndim == 2 else safe_total
        return torch.where(tt, (cc * old + s) / st, old)

    n = average(pm.normals, normals)
    n_norm2 = (n * n).sum(1, keepdim=True)
    n = n / torch.sqrt(torch.where(n_norm2 > 1e-20, n_norm2, torch.ones_like(n_norm2)))
    observed = torch.zeros(size, dtype=torch.int64, device=device).index_add(
        0, target, torch.ones_like(target))
    return PointMap(
        points=average(pm.points, points), normals=n, colors=average(pm.colors, colors),
        confidence=total, radius=average(pm.radius, radius),
        last_seen=torch.where(observed > 0, torch.full_like(observed, frame_index),
                              torch.cat([pm.last_seen, torch.zeros(Q, dtype=torch.int64, device=device)])),
        observations=torch.cat([pm.observations, torch.zeros(Q, dtype=torch.int64, device=device)])
        + (observed > 0).to(torch.int64),
        voxel_key=torch.cat([pm.voxel_key, new_keys]),
    )


class MapperBase:
    """What PointFusion and ICP-SLAM share (the parts of :class:`dcslam.slam.parts.Mapper` that do not depend on
    how frames are fused): the current :attr:`map` (None until the first frame), the frame count, and the map
    rendered into a camera for frame-to-model odometry. Subclasses set ``splat`` and ``voxel_size`` and implement
    ``integrate(frame, T_world_cam, scale=1.0) -> PointMap`` (at the voxel size ``voxel_size * scale``), ending with
    ``self.map = self._slide(pm)``.

    A local map (``window`` > 0 frames) keeps only points updated in the last ``window`` frames for odometry and
    fusion, so that memory and time per frame stay flat however far the car drives; older points move, detached,
    to a :class:`~dcslam.slam.archive.MapArchive` in a temporary file (``archive=True``, so :meth:`global_map`
    can still be written at the end, at the cost of reading it back then) or are dropped (``archive=False``).
    """

    splat: int = 1
    voxel_size: float = 0.0
    window: int = 0
    archive: bool = True

    def reset(self) -> None:
        self.map: PointMap | None = None
        self.frames = 0
        if getattr(self, "archived", None) is not None:
            self.archived.clear()
        self.archived = MapArchive()

    def _slide(self, pm: PointMap) -> PointMap:
        if self.window <= 0:
            return pm
        old = pm.last_seen < self.frames - self.window
        if not bool(old.any()):
            return pm
        if self.archive:
            self.archived.append(pm.select(old))
        return pm.select(~old)

    def precompute(self, frame) -> None:
        """Nothing depends on the frame alone (subclasses that have such work override this)."""

    def effective_settings(self, scale: float) -> dict:
        """``voxel_size`` (metres) at the scene scale ``scale``."""
        return {"voxel_size": self.voxel_size * scale}

    def global_map(self) -> PointMap | None:
        """The archived points and the local map (detached, on the CPU); the map itself without a window."""
        if self.map is None or len(self.archived) == 0:
            return self.map
        return self.archived.read(then=self.map)

    def model(self, T_world_cam: torch.Tensor, K: torch.Tensor, height: int, width: int) -> ModelView | None:
        """The map rendered into a camera (what frame-to-model odometry aligns to); None while the map is empty."""
        if self.map is None or len(self.map) == 0:
            return None
        return render(self.map, T_world_cam, K, height, width, splat=self.splat)
