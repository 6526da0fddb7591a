"""One input frame made ready for odometry and mapping: vertex map, normals, validity, colours."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import torch

from dcslam.constants import MIN_DEPTH_M
from dcslam.errors import DcslamError
from dcslam.geometry.camera import backproject, backproject_pixels, check_depth, check_K
from dcslam.geometry.normals import choose, point_normals, vertex_normals
from dcslam.native import depth_range


#: Normal search (pixels) for sparse depth: far enough to reach the next LiDAR scan line at 64 beams (a shorter
#: search fails there; measurements in docs/slam.md, "Normals"). Normals are found by sorting the valid pixels, so a
#: longer search costs nothing more.
SPARSE_NORMAL_SEARCH = 32
#: Valid-pixel fraction down to which :data:`SPARSE_NORMAL_SEARCH` reaches the next scan line (16 of 64 beams, about
#: 1 % of a KITTI frame). Sparser depth searches proportionally further, as its scan lines are proportionally
#: further apart.
SPARSE_REFERENCE_FRACTION = 0.01


#: Valid-pixel fraction above which depth counts as dense (completed or exact depth: the adjacent pixels are the
#: normal neighbours, :func:`normal_search_for`). It lies between LiDAR-like depth (a few per cent of the pixels,
#: annotated depth about a fifth) and completed depth (all of them); densities in docs/slam.md.
DENSE_FRACTION = 0.3


def normal_search_for(fraction: float) -> int:
    """Pixels to search for normal neighbours in depth of which ``fraction`` of the pixels are valid: 1 for dense
    depth (above :data:`DENSE_FRACTION`), :data:`SPARSE_NORMAL_SEARCH` down to :data:`SPARSE_REFERENCE_FRACTION`,
    proportionally more below it (at most 256)."""
    if fraction > DENSE_FRACTION:
        return 1
    if fraction <= 0:
        return SPARSE_NORMAL_SEARCH
    return min(256, max(SPARSE_NORMAL_SEARCH, round(SPARSE_NORMAL_SEARCH * SPARSE_REFERENCE_FRACTION / fraction)))


@dataclass(frozen=True)
class FrameSettings:
    """How a depth image becomes surfels.

    normal_search: pixels searched for the nearest valid neighbour when taking normals (1 for dense depth; 0 means
        choose from the fraction of valid pixels, :func:`normal_search_for`: LiDAR-like sparse depth has scan lines a
        few pixels apart near the car and tens of pixels far away, further the fewer the beams).
    max_relative_gap: neighbours beyond this relative depth difference are across an edge (not used for normals).
    min_depth, max_depth: measurements outside [min_depth, max_depth] metres are ignored.
    """

    normal_search: int = 0
    max_relative_gap: float = 0.1
    min_depth: float = MIN_DEPTH_M
    max_depth: float = 80.0


class Deferred:
    """A frame's (H, W, C) image not made yet (:class:`Frame`): ``make()`` makes it; ``at(pixels)``, when given,
    gives its rows at flat pixel indices (F,) without making it -> (F, C)."""

    def __init__(self, make: Callable[[], torch.Tensor], at: Callable[[torch.Tensor], torch.Tensor] | None = None):
        self.make, self.at = make, at


class _Image:
    """A :class:`Frame` field holding an image or a :class:`Deferred` one, made on first access and then kept. A
    required field: it has no default (dataclasses take a descriptor's class access, which raises, for none)."""

    def __set_name__(self, owner, name: str) -> None:
        self.slot = "_" + name

    def __get__(self, frame, owner=None):
        if frame is None:
            raise AttributeError(self.slot[1:])
        value = frame.__dict__[self.slot]
        if isinstance(value, Deferred):
            value = frame.__dict__[self.slot] = value.make()
        return value

    def __set__(self, frame, value) -> None:
        frame.__dict__[self.slot] = value


@dataclass
class Frame:
    """A depth frame in its camera.

    Shape: depth (1, 1, H, W) metres; vertex (H, W, 3) and normal (H, W, 3) in the camera frame; valid (H, W) bool
    (depth in range, a normal, and a weight above 0); rgb (H, W, 3) in [0, 1] or None; K (3, 3); weight (H, W) in
    [0, 1] or None (every pixel counts fully): how much each pixel's point is trusted, e.g. a completer's confidence.
    ICP multiplies its residuals' robust weights by it and fusion its surfel confidences; a pixel of weight 0 is
    invalid (neither aligned, nor counted as evidence, nor fused). ``cache``: what odometry and mapping computed
    from the frame alone (its sources, its camera-frame surfels), keyed by what else it depends on; they fill it
    ahead of time on another thread (:meth:`dcslam.slam.pipeline.SLAM.precompute`) or when first needed.

    ``vertex``, ``normal`` and ``rgb`` may be given as :class:`Deferred` images, made on first access: the SLAM reads
    a frame at its valid pixels only (:func:`valid_points`, :func:`valid_normals`, :func:`valid_colors`), so a
    sparse frame's images are never made in a SLAM step (allocating them cost it about a tenth of its time).
    """

    depth: torch.Tensor
    vertex: torch.Tensor = _Image()
    normal: torch.Tensor = _Image()
    valid: torch.Tensor
    rgb: torch.Tensor | None = _Image()
    K: torch.Tensor
    weight: torch.Tensor | None = None
    cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)   # fresh on replace()

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.depth.shape[-2:])


def valid_points(frame: Frame) -> tuple[torch.Tensor, torch.Tensor]:
    """(flat indices of the valid pixels (F,), their camera-frame points (F, 3)), gathered once per frame (kept in
    :attr:`Frame.cache`) for both the ICP sources and the surfels."""
    if "valid-points" not in frame.cache:
        pixels = torch.nonzero(frame.valid.reshape(-1)).squeeze(1)
        frame.cache["valid-points"] = (pixels, _rows(frame, "vertex", pixels))
    return frame.cache["valid-points"]


def valid_normals(frame: Frame) -> torch.Tensor:
    """The camera-frame normals (F, 3) at the valid pixels of :func:`valid_points`, gathered once per frame."""
    if "valid-normals" not in frame.cache:
        frame.cache["valid-normals"] = _rows(frame, "normal", valid_points(frame)[0])
    return frame.cache["valid-normals"]


def valid_colors(frame: Frame) -> torch.Tensor | None:
    """The colours (F, 3) in [0, 1] at the valid pixels of :func:`valid_points` (None without an image), gathered
    once per frame."""
    if "valid-colors" not in frame.cache:
        none = frame.__dict__["_rgb"] is None
        frame.cache["valid-colors"] = None if none else _rows(frame, "rgb", valid_points(frame)[0])
    return frame.cache["valid-colors"]


def _rows(frame: Frame, name: str, pixels: torch.Tensor) -> torch.Tensor:
    """An image field's rows at flat pixel indices, without making a :class:`Deferred` image that can give them."""
    value = frame.__dict__["_" + name]
    if isinstance(value, Deferred) and value.at is not None:
        return value.at(pixels)
    image = getattr(frame, name)
    return image.reshape(-1, image.shape[-1]).index_select(0, pixels)


def prepare_frame(depth: torch.Tensor, K: torch.Tensor, rgb: torch.Tensor | None = None,
                  settings: FrameSettings = FrameSettings(), weight: torch.Tensor | None = None) -> Frame:
    """Back-project one depth image and take its normals.

    Normals come from the depth alone (a pixel of weight 0 still serves as its neighbours' normal neighbour); the
    weight only decides how much each pixel counts (see :class:`Frame`). Gradients flow to ``depth`` and
    ``weight``.

    Shape: depth (1, 1, H, W) or (H, W) metres, K (3, 3), rgb (1, 3, H, W) or (3, H, W): floating point in [0, 1],
    or uint8 (divided by 255 in float32 where it is read: a drive's image is read at the valid pixels only), weight
    (1, 1, H, W) or (H, W) in [0, 1] or None -> :class:`Frame`.
    """
    if isinstance(depth, torch.Tensor) and depth.ndim == 2:
        depth = depth[None, None]
    B, H, W = check_depth(depth)
    if B != 1:
        raise DcslamError(f"one frame at a time: depth has batch {B}")
    K = check_K(K)[0].to(depth.dtype)
    gated = depth_range(depth, settings.min_depth, settings.max_depth)    # the same in one pass, where it applies
    if gated is None:
        in_range = (depth >= settings.min_depth) & (depth <= settings.max_depth)
        depth = choose(in_range, depth, torch.zeros((), dtype=depth.dtype, device=depth.device))
        count = None
    else:
        in_range, depth, count = gated
    search = settings.normal_search
    if search <= 0:
        # the float32 mean of the mask, as an exact count divided once: no float image of it
        count = int(in_range.sum()) if count is None else count
        search = normal_search_for(float(torch.tensor(count, dtype=torch.float32) / in_range.numel()))
    pixels = None
    if search == 1 and H > 1 and W > 1:   # dense: one pass over the pixel grid
        vertex, normal, ok = _grid_surfels(depth, in_range, K, settings.max_relative_gap)
    else:
        vertex, normal, ok, pixels, points, normals = _pixel_surfels(depth, in_range, K, search,
                                                                     settings.max_relative_gap)
    valid = ok
    if weight is not None:
        weight = _check_weight(weight, H, W).to(depth.dtype)
        valid = valid & (weight.detach() > 0)
    frame = Frame(depth, vertex, normal, valid, None if rgb is None else _colour_image(rgb, H, W, depth.dtype), K,
                  weight)
    if pixels is not None:   # the valid pixels' points and normals are at hand: no search of the images
        keep = torch.nonzero(valid.reshape(-1).index_select(0, pixels)).squeeze(1)
        frame.cache["valid-points"] = (pixels.index_select(0, keep), points.index_select(0, keep))
        frame.cache["valid-normals"] = normals.index_select(0, keep)
    return frame


def _colour_image(rgb: torch.Tensor, H: int, W: int, dtype: torch.dtype) -> torch.Tensor | Deferred:
    """A frame's colour image (H, W, 3) in [0, 1] from (1, 3, H, W) or (3, H, W): a float image stored point by
    point, or, for uint8, a :class:`Deferred` one (its values: the float32 quotient by 255, as the whole image
    divided would have them)."""
    if rgb.ndim == 3:
        rgb = rgb[None]
    if rgb.shape != (1, 3, H, W):
        raise DcslamError(f"rgb has shape {tuple(rgb.shape)}, expected (1, 3, {H}, {W})")
    rgb = rgb[0].permute(1, 2, 0)
    if rgb.dtype != torch.uint8:
        return rgb.to(dtype).contiguous()
    return Deferred(lambda: (rgb.float() / 255).to(dtype).contiguous(),
                    lambda pixels: (rgb.reshape(-1, 3).index_select(0, pixels).float() / 255).to(dtype))


def _grid_surfels(depth: torch.Tensor, in_range: torch.Tensor, K: torch.Tensor,
                  max_relative_gap: float) -> tuple[Deferred, Deferred, torch.Tensor]:
    """Vertex and normal maps (H, W, 3), :class:`Deferred`, and the pixels with a normal (H, W) of dense depth
    (1, 1, H, W), in range at ``in_range`` (1, 1, H, W): back-projection and the normals of the pixel grid."""
    vertex = backproject(depth, K)
    normal, ok = vertex_normals(vertex, in_range, search=1, max_relative_gap=max_relative_gap)

    def image(grid: torch.Tensor) -> Deferred:
        # made: stored point by point, as odometry and fusion gather whole points; read at pixels: gathered from
        # each channel, then laid point by point (half the cost of laying out the whole image first)
        return Deferred(lambda: grid[0].permute(1, 2, 0).contiguous(),
                        lambda pixels: grid.reshape(3, -1).index_select(1, pixels).T.contiguous())

    return image(vertex), image(normal), ok[0, 0]


def _pixel_surfels(depth: torch.Tensor, in_range: torch.Tensor, K: torch.Tensor, search: int,
                   max_relative_gap: float) -> tuple:
    """As :func:`_grid_surfels` for sparse depth, the work done at the pixels in range only (a few per cent of a
    LiDAR frame's), with the values backproject and vertex_normals give there, bit for bit, the vertex and normal
    maps :class:`Deferred`; also those pixels (F,) flat indices, their points (F, 3) and normals (F, 3)."""
    H, W = depth.shape[-2:]
    pixels = torch.nonzero(in_range.reshape(-1)).squeeze(1)
    points = backproject_pixels(depth.reshape(-1).index_select(0, pixels), pixels, K, W)
    normals, ok = point_normals(points, pixels, (1, H, W), search, max_relative_gap)

    def image(rows: torch.Tensor) -> Deferred:
        # index_copy_: several times faster than index_put on the CPU
        return Deferred(lambda: rows.new_zeros(H * W, 3).index_copy_(0, pixels, rows).view(H, W, 3))

    valid = torch.zeros(H * W, dtype=torch.bool, device=depth.device).index_fill_(
        0, pixels.index_select(0, torch.nonzero(ok).squeeze(1)), True)
    return image(points), image(normals), valid.view(H, W), pixels, points, normals


def _check_weight(weight: torch.Tensor, H: int, W: int) -> torch.Tensor:
    """A per-pixel weight as (H, W), checked: the image's size, finite, in [0, 1]."""
    if not isinstance(weight, torch.Tensor):
        raise DcslamError(f"weight must be a torch tensor, got {type(weight).__name__}")
    if weight.ndim == 4 and weight.shape[:2] == (1, 1):
        weight = weight[0, 0]
    if weight.shape != (H, W):
        raise DcslamError(f"weight has shape {tuple(weight.shape)}, expected ({H}, {W}) or (1, 1, {H}, {W})")
    w = weight.detach()
    if not bool(torch.isfinite(w).all()) or bool((w < 0).any()) or bool((w > 1).any()):
        raise DcslamError("weight must be finite and in [0, 1] (e.g. a completer's confidence)")
    return weight
