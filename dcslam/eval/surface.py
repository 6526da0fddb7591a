"""The surface a depth image builds, scored against a reference depth of the same camera.

Per-pixel depth errors (MAE, RMSE) say little about what ICP sees: its residuals are point-to-plane distances,
gated by the agreement of normals, so a completion that is close in depth but tilted (terraces of a
piecewise-constant fill) or that puts points between the two sides of a depth edge (flying pixels) aligns worse
than its error suggests. These metrics measure those surfaces, per image, with ``D`` the scored depth, ``R`` the
reference (exact depth on generated drives, annotated dense depth otherwise), both in metres with 0 = none:

* **Points and normals** are those SLAM takes (:func:`dcslam.slam.frame.prepare_frame`): depths outside
  [``min_depth``, ``max_depth``] are none; each pixel's point is its back-projection with ``K``; its normal is
  :func:`dcslam.geometry.normals.vertex_normals` of the vertex map with ``search`` (scored) / ``reference_search``
  pixels and ``max_relative_gap``. The depth is scored as it is (no interpolation of holes): a sparse layer is
  scored at its own pixels only.
* **Normal angle error** (degrees): the angle between the scored and the reference normal, over the pixels where
  both have a normal; the image's mean and median.
* **Point-to-plane distance** (metres): ``n_R(p) . (P_D(p) - P_R(p))``, the distance of the scored point of pixel p
  from the reference surface there (the plane through the reference point of p with the reference normal of p),
  over the pixels with a scored point, a reference point and a reference normal; the image's mean of its absolute
  value and its root mean square.
* **Flying pixels**: a pixel is at a *reference depth edge* when a 4-neighbour has a reference depth that differs
  from its own by more than :data:`EDGE_RELATIVE_JUMP` times the smaller of the two; a pixel is *near an edge*
  when it lies within :data:`EDGE_RADIUS_PX` pixels (a (2r+1)-pixel square) of one. Of the pixels near an edge
  with a scored and a reference point, the flying share is the fraction whose scored point lies more than
  max(:data:`FLYING_MIN_M`, :data:`FLYING_RELATIVE` x R(p)) from every reference surface nearby: of each pixel
  within :data:`EDGE_RADIUS_PX` with a reference point, its plane (reference point and normal), or the point
  itself where it has no normal (a structure too thin for one). A point on either side of the edge, even one
  drawn a pixel off, is not flying; a depth mixed between the two sides is.

Over many images every image weighs the same (as the devkit's depth errors): each metric is the mean of the
per-image values over the images where it is defined (NaN where none is); the pixel counts are totals.
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import asdict, dataclass

import numpy as np
import torch
import torch.nn.functional as F

from dcslam.constants import MIN_DEPTH_M
from dcslam.errors import DcslamError
from dcslam.geometry.camera import backproject, check_depth, check_K
from dcslam.geometry.normals import vertex_normals

#: Relative depth jump between 4-neighbours that makes a reference depth edge (as the normals' default gap).
EDGE_RELATIVE_JUMP = 0.1
#: Pixels from a reference depth edge within which a pixel counts as near it, and within which the reference
#: surfaces a scored point may lie on are looked for.
EDGE_RADIUS_PX = 2
#: A point near an edge further than max(FLYING_MIN_M, FLYING_RELATIVE x reference depth) from every reference
#: surface nearby is flying: 0.1 m, or 2 % of the depth (about 0.6 m at 30 m) further out.
FLYING_MIN_M = 0.1
FLYING_RELATIVE = 0.02
#: Surface metrics reported beside the depth errors (per-image values, then the mean over images).
SURFACE_METRICS = ("normal_mean_deg", "normal_median_deg", "p2p_mean_m", "p2p_rmse_m", "flying_share")


@dataclass(frozen=True)
class SurfaceSettings:
    """How points, normals and flying pixels are found (the module docstring defines each).

    search, reference_search: pixels searched for normal neighbours in the scored and the reference depth (1 for
        dense depth; SLAM chooses from the valid fraction, :func:`dcslam.slam.frame.normal_search_for`).
    max_relative_gap, min_depth, max_depth: as :class:`dcslam.slam.frame.FrameSettings`.
    edge_jump, edge_radius_px, flying_min_m, flying_relative: the flying-pixel thresholds.
    """

    search: int = 1
    reference_search: int = 1
    max_relative_gap: float = 0.1
    min_depth: float = MIN_DEPTH_M
    max_depth: float = 80.0
    edge_jump: float = EDGE_RELATIVE_JUMP
    edge_radius_px: int = EDGE_RADIUS_PX
    flying_min_m: float = FLYING_MIN_M
    flying_relative: float = FLYING_RELATIVE

    def __post_init__(self) -> None:
        if self.search < 1 or self.reference_search < 1:
            raise DcslamError(f"normal searches must be >= 1 pixel, got {self.search} and {self.reference_search}")
        if self.edge_radius_px < 0 or not self.edge_jump > 0 or self.flying_min_m < 0 or self.flying_relative < 0:
            raise DcslamError(f"edge_radius_px, flying_min_m and flying_relative must be >= 0 and edge_jump > 0; got "
                              f"{self.edge_radius_px}, {self.flying_min_m}, {self.flying_relative}, {self.edge_jump}")


@dataclass(frozen=True)
class Surface:
    """Points and normals of a depth image, as SLAM takes them.

    Shape: points, normals (B, 3, H, W) in the camera frame (zero where none); has_point, has_normal (B, 1, H, W)
    bool.
    """

    points: torch.Tensor
    normals: torch.Tensor
    has_point: torch.Tensor
    has_normal: torch.Tensor


def depth_surface(depth: torch.Tensor, K: torch.Tensor, search: int = 1, max_relative_gap: float = 0.1,
                  min_depth: float = MIN_DEPTH_M, max_depth: float = 80.0) -> Surface:
    """Points and normals of a depth image the way :func:`dcslam.slam.frame.prepare_frame` takes them (depth out of
    range is none, back-projection, :func:`dcslam.geometry.normals.vertex_normals`). Gradients flow to ``depth``.

    Shape: depth (B, 1, H, W) metres, K (3, 3) or (B, 3, 3) -> :class:`Surface`.
    """
    check_depth(depth)
    has_point = (depth >= min_depth) & (depth <= max_depth)
    depth = torch.where(has_point, depth, torch.zeros((), dtype=depth.dtype, device=depth.device))
    points = backproject(depth, K)
    normals, has_normal = vertex_normals(points, has_point, search=search, max_relative_gap=max_relative_gap)
    return Surface(points, normals, has_point, has_normal)


def depth_edges(depth: torch.Tensor, has_point: torch.Tensor,
                relative_jump: float = EDGE_RELATIVE_JUMP) -> torch.Tensor:
    """Pixels at a depth edge: a 4-neighbour with a point whose depth differs from the pixel's by more than
    ``relative_jump`` times the smaller of the two (a hole is no edge).

    Shape: depth (B, 1, H, W), has_point (B, 1, H, W) bool -> (B, 1, H, W) bool.
    """
    d = depth.detach()
    edges = torch.zeros_like(has_point)
    for dim in (2, 3):
        n = d.shape[dim]
        if n < 2:
            continue
        a, b = d.narrow(dim, 0, n - 1), d.narrow(dim, 1, n - 1)
        both = has_point.narrow(dim, 0, n - 1) & has_point.narrow(dim, 1, n - 1)
        jump = both & ((a - b).abs() > relative_jump * torch.minimum(a, b))
        edges.narrow(dim, 0, n - 1).logical_or_(jump)
        edges.narrow(dim, 1, n - 1).logical_or_(jump)
    return edges


def near(mask: torch.Tensor, radius: int) -> torch.Tensor:
    """Pixels within ``radius`` pixels (a square) of a pixel of ``mask``. Shape: (B, 1, H, W) bool -> the same."""
    if radius == 0:
        return mask.clone()
    return F.max_pool2d(mask.to(torch.float32), 2 * radius + 1, stride=1, padding=radius) > 0


def nearest_surface_sq(points: torch.Tensor, reference: Surface, pixels: torch.Tensor, radius: int) -> torch.Tensor:
    """For each pixel of ``pixels``, the squared distance of its point to the nearest reference surface among the
    pixels within ``radius`` pixels (a square): the plane (reference point and normal) of a pixel with a normal,
    the reference point itself of a pixel with a point but no normal (a thin structure, a lone return); ``inf``
    where there is neither. Differentiable in ``points`` (towards the nearest surface; the reference is fixed).

    Shape: points (B, 3, H, W), reference of (B, ., H, W), pixels (B, 1, H, W) bool -> (M,) for the M pixels of
    ``pixels`` in raster order.
    """
    B, _, H, W = points.shape
    index = torch.nonzero(pixels.reshape(-1)).squeeze(1)
    p = points.permute(0, 2, 3, 1).reshape(-1, 3)[index]
    # the reference maps padded by ``radius`` pixels without a point, so that every neighbour lies at a fixed
    # offset from the pixel in the flattened padded image
    Hp, Wp = H + 2 * radius, W + 2 * radius

    def padded(x: torch.Tensor) -> torch.Tensor:
        return F.pad(x.detach().to(points.dtype), (radius,) * 4).permute(0, 2, 3, 1).reshape(B * Hp * Wp, -1)

    ref_p, ref_n = padded(reference.points), padded(reference.normals)
    has_point, has_normal = (padded(m)[:, 0] > 0 for m in (reference.has_point, reference.has_normal))
    b, v, u = index // (H * W), (index // W) % H, index % W
    centre = (b * Hp + v + radius) * Wp + u + radius
    best = torch.full((index.numel(),), math.inf, dtype=points.dtype, device=points.device)
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            q = centre + (dy * Wp + dx)
            offset = p - ref_p[q]
            plane = (ref_n[q] * offset).sum(1)
            sq = torch.where(has_normal[q], plane * plane, (offset * offset).sum(1))
            best = torch.minimum(best, torch.where(has_point[q], sq, torch.full_like(sq, math.inf)))
    return best


@dataclass(frozen=True)
class SurfaceErrors:
    """Surface errors of one image (or the mean over images; see the module docstring): degrees, metres, a share;
    NaN where no pixel was scored. ``*_pixels``: the pixels scored by each metric; ``flying_pixels`` of the
    ``edge_pixels`` near a reference edge."""

    normal_mean_deg: float
    normal_median_deg: float
    p2p_mean_m: float
    p2p_rmse_m: float
    flying_share: float
    normal_pixels: int
    p2p_pixels: int
    edge_pixels: int
    flying_pixels: int

    def as_dict(self) -> dict:
        return asdict(self)


def _image(x, name: str) -> torch.Tensor:
    t = torch.as_tensor(x)
    if t.ndim != 2 or not t.is_floating_point():
        raise DcslamError(f"{name} has shape {tuple(t.shape)} and dtype {t.dtype}, expected (H, W) floating point")
    return t


def surface_errors(depth_m, reference_m, K, settings: SurfaceSettings = SurfaceSettings()) -> SurfaceErrors | None:
    """Normal angle error, point-to-plane distance and flying-pixel share of one depth image against a reference
    (module docstring); ``None`` when the reference has no point at all. Computed in the inputs' precision (the
    wider of the two), summed in float64.

    Shape: depth_m (H, W), reference_m (H, W) metres, 0 = none (NumPy arrays or tensors, float32 or float64);
    K (3, 3).
    """
    depth, reference = _image(depth_m, "depth"), _image(reference_m, "reference depth")
    if depth.shape != reference.shape:
        raise DcslamError(f"depth {tuple(depth.shape)} and reference depth {tuple(reference.shape)} differ in shape")
    dtype = torch.promote_types(depth.dtype, reference.dtype)
    depth, reference = depth.to(dtype)[None, None], reference.to(dtype)[None, None]
    K = check_K(torch.as_tensor(K)).to(dtype=dtype, device=depth.device)
    s = settings
    with torch.no_grad():
        ref = depth_surface(reference, K, s.reference_search, s.max_relative_gap, s.min_depth, s.max_depth)
        if not bool(ref.has_point.any()):
            return None
        pred = depth_surface(depth, K, s.search, s.max_relative_gap, s.min_depth, s.max_depth)

        both = (pred.has_normal & ref.has_normal)[:, 0]
        n_d, n_r = (x.permute(0, 2, 3, 1)[both].double().cpu() for x in (pred.normals, ref.normals))
        angle = torch.rad2deg(torch.atan2(torch.linalg.cross(n_d, n_r).norm(dim=-1), (n_d * n_r).sum(-1))).numpy()

        scored = (pred.has_point & ref.has_point & ref.has_normal)[:, 0]
        offset = (pred.points - ref.points).double() * ref.normals.double()
        p2p = offset.sum(1)[scored].cpu().numpy()

        band = (near(depth_edges(reference, ref.has_point, s.edge_jump), s.edge_radius_px)
                & pred.has_point & ref.has_point)
        dist = nearest_surface_sq(pred.points, ref, band, s.edge_radius_px).double().sqrt()
        limit = torch.clamp(s.flying_relative * reference[band].double(), min=s.flying_min_m)
        flying, edge_pixels = int((dist > limit).sum()), int(band.sum())    # every band pixel has its own point

    nan = math.nan
    return SurfaceErrors(
        normal_mean_deg=float(angle.mean()) if angle.size else nan,
        normal_median_deg=float(np.median(angle)) if angle.size else nan,
        p2p_mean_m=float(np.abs(p2p).mean()) if p2p.size else nan,
        p2p_rmse_m=float(np.sqrt((p2p ** 2).mean())) if p2p.size else nan,
        flying_share=flying / edge_pixels if edge_pixels else nan,
        normal_pixels=int(angle.size), p2p_pixels=int(p2p.size), edge_pixels=edge_pixels, flying_pixels=flying)


def mean_surface_errors(errors: Iterable[SurfaceErrors | None]) -> SurfaceErrors:
    """Mean over images (images without a reference skipped; each metric over the images where it is defined, NaN
    if none is); pixel counts are totals."""
    errors = [e for e in errors if e is not None]
    if not errors:
        raise DcslamError("no image with reference depth to score")

    def mean(name: str) -> float:
        values = [getattr(e, name) for e in errors if not math.isnan(getattr(e, name))]
        return float(np.mean(values)) if values else math.nan

    counts = ("normal_pixels", "p2p_pixels", "edge_pixels", "flying_pixels")
    return SurfaceErrors(**{m: mean(m) for m in SURFACE_METRICS},
                         **{c: int(sum(getattr(e, c) for e in errors)) for c in counts})
