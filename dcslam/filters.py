"""Filters on depth images, composed into chains that turn one depth layer into another.

Every filter is a small frozen object with ``apply(depth_m, K) -> depth_m`` on one (H, W) float32 image in metres
(0 = no value) and ``describe() -> dict`` (recorded in the layer file it produces). Filters only ever *remove* depth
(set pixels to 0) or, for the bilateral filter, smooth the depth of pixels that have one; none of them fills holes.

The thesis's code filtered with a depth range of 5–15 m and ``cv2.bilateralFilter(d=5, sigmaColor=80,
sigmaSpace=80)``; these are the presets ``thesis-range`` and ``thesis-bilateral`` (:data:`PRESETS`). Statistical
outlier removal, hidden-point removal (both on the back-projected points, with Open3D) and removal of pixels at depth
discontinuities go beyond the thesis, which named outlier filtering as future work.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError


def _check_depth(depth_m: np.ndarray) -> np.ndarray:
    depth_m = np.asarray(depth_m)
    if depth_m.ndim != 2:
        raise DcslamError(f"depth has shape {depth_m.shape}, expected (H, W)")
    return depth_m.astype(np.float32, copy=False)


def backproject(depth_m: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points of the valid pixels in the camera frame.

    Shapes: depth_m (H, W), K (3, 3) → points (M, 3) float64 (x right, y down, z forward) and their flat pixel
    indices (M,) into ``depth_m.ravel()``.
    """
    depth_m = _check_depth(depth_m)
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3):
        raise DcslamError(f"K has shape {K.shape}, expected (3, 3)")
    index = np.flatnonzero(depth_m.ravel() > 0)
    v, u = np.divmod(index, depth_m.shape[1])
    z = depth_m.ravel()[index].astype(np.float64)
    x = (u - K[0, 2]) * z / K[0, 0]
    y = (v - K[1, 2]) * z / K[1, 1]
    return np.stack([x, y, z], axis=1), index


def _keep_only(depth_m: np.ndarray, index: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """A copy of ``depth_m`` in which the pixels ``index`` (flat) not marked in ``keep`` are set to 0."""
    out = depth_m.copy()
    out.ravel()[index[~keep]] = 0.0
    return out


@dataclass(frozen=True)
class RangeFilter:
    """Drop depth nearer than ``min_m`` or farther than ``max_m`` (both bounds kept)."""

    min_m: float = 0.0
    max_m: float = float("inf")
    name = "range"

    def __post_init__(self):
        if not (0 <= self.min_m < self.max_m):
            raise DcslamError(f"range filter needs 0 <= min < max, got min={self.min_m}, max={self.max_m}")

    def apply(self, depth_m: np.ndarray, K: np.ndarray | None = None) -> np.ndarray:
        """(H, W) → (H, W) float32."""
        depth_m = _check_depth(depth_m)
        return np.where((depth_m >= self.min_m) & (depth_m <= self.max_m), depth_m, np.float32(0))

    def describe(self) -> dict:
        return {"filter": self.name, **asdict(self)}


@dataclass(frozen=True)
class BilateralFilter:
    """Edge-preserving smoothing of depth, with OpenCV's bilateral kernel.

    Weights, as ``cv2.bilateralFilter`` defines them: over a disc of radius ``d // 2`` pixels,
    ``w = exp(-r² / (2 sigma_space²)) · exp(-(Δdepth)² / (2 sigma_color²))`` with Δdepth in metres, image borders
    reflected (OpenCV's ``BORDER_REFLECT_101``).

    Holes (depth 0): with ``ignore_holes=True`` (the default) a pixel without depth stays without depth, and holes
    take no part in the weighted mean of their neighbours, so no depth is smeared into holes and no valid depth is
    pulled towards 0. On an image without holes this equals ``cv2.bilateralFilter`` (up to OpenCV's lookup-table
    approximation of the colour weight). With ``ignore_holes=False`` it *is* ``cv2.bilateralFilter`` on the float32
    image, as the thesis called it: zeros count as depth 0 m, so holes get filled with a mixture of their
    neighbours and edges next to holes are pulled towards 0 (with sigma_color = 80 m the colour term barely
    discriminates). Pixels outside the image are never "holes".
    """

    d: int = 5
    sigma_color: float = 80.0
    sigma_space: float = 80.0
    ignore_holes: bool = True
    name = "bilateral"

    def __post_init__(self):
        if self.d < 1 or self.sigma_color <= 0 or self.sigma_space <= 0:
            raise DcslamError(f"bilateral filter needs d >= 1 and positive sigmas, got d={self.d}, "
                              f"sigma_color={self.sigma_color}, sigma_space={self.sigma_space}")

    def apply(self, depth_m: np.ndarray, K: np.ndarray | None = None) -> np.ndarray:
        """(H, W) → (H, W) float32."""
        depth_m = _check_depth(depth_m)
        if not self.ignore_holes:
            import cv2

            return cv2.bilateralFilter(depth_m, self.d, self.sigma_color, self.sigma_space)
        radius = self.d // 2
        height, width = depth_m.shape
        if radius == 0 or min(height, width) <= radius:
            return depth_m.copy()
        padded = np.pad(depth_m.astype(np.float64), radius, mode="reflect")  # = BORDER_REFLECT_101
        centre = depth_m.astype(np.float64)
        total = np.zeros_like(centre)
        weight_sum = np.zeros_like(centre)
        for dy in range(-radius, radius + 1):
            for dx in range(-radius, radius + 1):
                r2 = dx * dx + dy * dy
                if r2 > radius * radius:
                    continue
                shifted = padded[radius + dy:radius + dy + height, radius + dx:radius + dx + width]
                w = np.exp(-r2 / (2 * self.sigma_space ** 2)) * np.exp(-(shifted - centre) ** 2 /
                                                                       (2 * self.sigma_color ** 2))
                w = w * (shifted > 0)
                total += w * shifted
                weight_sum += w
        valid = centre > 0  # the centre's own weight is 1, so weight_sum > 0 wherever the centre is valid
        out = np.zeros_like(centre)
        np.divide(total, weight_sum, out=out, where=valid)
        return out.astype(np.float32)

    def describe(self) -> dict:
        return {"filter": self.name, **asdict(self)}


@dataclass(frozen=True)
class StatisticalOutlierFilter:
    """Drop pixels whose back-projected point is far from its neighbours (Open3D ``remove_statistical_outlier``):
    a point goes when its mean distance to its ``nb_neighbors`` nearest points exceeds the mean of that quantity
    over the image by more than ``std_ratio`` standard deviations."""

    nb_neighbors: int = 20
    std_ratio: float = 2.0
    name = "outlier"

    def __post_init__(self):
        if self.nb_neighbors < 1 or self.std_ratio <= 0:
            raise DcslamError("outlier filter needs nb_neighbors >= 1 and std_ratio > 0")

    def apply(self, depth_m: np.ndarray, K: np.ndarray) -> np.ndarray:
        """(H, W), K (3, 3) → (H, W) float32."""
        import open3d as o3d

        depth_m = _check_depth(depth_m)
        points, index = backproject(depth_m, K)
        if len(points) <= self.nb_neighbors:
            return depth_m.copy()
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        _, kept = cloud.remove_statistical_outlier(nb_neighbors=self.nb_neighbors, std_ratio=self.std_ratio)
        keep = np.zeros(len(points), bool)
        keep[np.asarray(kept, dtype=np.int64)] = True
        return _keep_only(depth_m, index, keep)

    def describe(self) -> dict:
        return {"filter": self.name, **asdict(self)}


@dataclass(frozen=True)
class HiddenPointFilter:
    """Drop pixels whose back-projected point is hidden from the camera by the surface through the other points
    (Katz et al. 2007, Open3D ``hidden_point_removal`` from the camera centre, radius = ``radius_factor`` × the
    diameter of the points' bounding box). Meant for LiDAR depth projected into the camera, where points seen by
    the LiDAR but occluded for the camera show through foreground objects."""

    radius_factor: float = 100.0
    name = "hidden"

    def __post_init__(self):
        if self.radius_factor <= 0:
            raise DcslamError("hidden-point filter needs radius_factor > 0")

    def apply(self, depth_m: np.ndarray, K: np.ndarray) -> np.ndarray:
        """(H, W), K (3, 3) → (H, W) float32."""
        import open3d as o3d

        depth_m = _check_depth(depth_m)
        points, index = backproject(depth_m, K)
        if len(points) < 4:
            return depth_m.copy()
        diameter = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
        if diameter == 0:
            return depth_m.copy()
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        try:
            _, visible = cloud.hidden_point_removal([0.0, 0.0, 0.0], self.radius_factor * diameter)
        except RuntimeError:  # qhull fails on degenerate (e.g. coplanar) point sets: nothing can be hidden there
            return depth_m.copy()
        keep = np.zeros(len(points), bool)
        keep[np.asarray(visible, dtype=np.int64)] = True
        return _keep_only(depth_m, index, keep)

    def describe(self) -> dict:
        return {"filter": self.name, **asdict(self)}


@dataclass(frozen=True)
class DiscontinuityFilter:
    """Drop pixels at depth discontinuities: a valid pixel goes when any valid 8-neighbour differs from it by more
    than ``max_jump_m`` metres, or by more than ``max_relative_jump`` × the nearer of the two depths. Both sides of
    an edge are dropped (mixed "flying" pixels sit on either side)."""

    max_jump_m: float | None = None
    max_relative_jump: float | None = 0.1
    name = "edges"

    def __post_init__(self):
        if self.max_jump_m is None and self.max_relative_jump is None:
            raise DcslamError("discontinuity filter needs max_jump_m or max_relative_jump")
        if any(v is not None and v <= 0 for v in (self.max_jump_m, self.max_relative_jump)):
            raise DcslamError("discontinuity filter thresholds must be positive")

    def apply(self, depth_m: np.ndarray, K: np.ndarray | None = None) -> np.ndarray:
        """(H, W) → (H, W) float32."""
        depth_m = _check_depth(depth_m)
        height, width = depth_m.shape
        padded = np.pad(depth_m, 1, mode="constant")  # outside the image counts as "no value"
        edge = np.zeros(depth_m.shape, bool)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                if dx == 0 and dy == 0:
                    continue
                other = padded[1 + dy:1 + dy + height, 1 + dx:1 + dx + width]
                both = (depth_m > 0) & (other > 0)
                jump = np.abs(depth_m - other)
                too_far = np.zeros_like(both)
                if self.max_jump_m is not None:
                    too_far |= jump > self.max_jump_m
                if self.max_relative_jump is not None:
                    too_far |= jump > self.max_relative_jump * np.minimum(depth_m, other)
                edge |= both & too_far
        return np.where(edge, np.float32(0), depth_m)

    def describe(self) -> dict:
        return {"filter": self.name, **asdict(self)}


#: Filter names (of the command line and configuration files) → filter classes: the one place they are mapped.
FILTERS = {"range": RangeFilter, "bilateral": BilateralFilter, "outlier": StatisticalOutlierFilter,
           "hidden": HiddenPointFilter, "edges": DiscontinuityFilter}
#: Short keys accepted in a filter spec.
KEY_ALIASES = {"min": "min_m", "max": "max_m"}

#: Named filters: the thesis's own settings.
PRESETS = {
    "thesis-range": RangeFilter(min_m=5.0, max_m=15.0),
    "thesis-bilateral": BilateralFilter(d=5, sigma_color=80.0, sigma_space=80.0),
}


@dataclass(frozen=True)
class FilterChain:
    """Filters applied in order."""

    filters: tuple

    def __post_init__(self):
        if not self.filters:
            raise DcslamError("a filter chain needs at least one filter")

    @property
    def name(self) -> str:
        """e.g. ``range+bilateral``."""
        return "+".join(f.name for f in self.filters)

    def apply(self, depth_m: np.ndarray, K: np.ndarray) -> np.ndarray:
        """(H, W), K (3, 3) → (H, W) float32; the input is not modified."""
        out = _check_depth(depth_m)
        for f in self.filters:
            out = f.apply(out, K)
        return out

    def describe(self) -> list[dict]:
        return [f.describe() for f in self.filters]


def filter_help() -> str:
    """The help of a filter spec, generated from :data:`FILTERS` and :data:`PRESETS`."""
    import dataclasses

    shown = {v: k for k, v in KEY_ALIASES.items()}
    names = ", ".join(f"{name} ({', '.join(shown.get(f.name, f.name) for f in dataclasses.fields(cls))})"
                      for name, cls in FILTERS.items())
    presets = ", ".join(f"{name} ({', '.join(f'{k}={v}' for k, v in list(p.describe().items())[1:])})"
                        for name, p in PRESETS.items())
    return (f"A filter, repeatable and applied in order: NAME or NAME:key=value,... with NAME one of {names}, or "
            f"a preset: {presets}. Example: --filter range:min=1,max=60 --filter bilateral:d=5,sigma_color=2")


def _convert(text: str, default):
    if isinstance(default, bool):
        if text.lower() in ("1", "true", "yes", "on"):
            return True
        if text.lower() in ("0", "false", "no", "off"):
            return False
        raise ValueError(f"expected true or false, got {text!r}")
    if text.lower() in ("none", "off") and not isinstance(default, int):
        return None
    return int(text) if isinstance(default, int) else float(text)


def parse_filter(spec: str):
    """``NAME`` or ``NAME:key=value,...`` (or a preset name) → a filter object. Raises :class:`DcslamError`."""
    import dataclasses

    if spec in PRESETS:
        return PRESETS[spec]
    name, _, args = spec.partition(":")
    if name not in FILTERS:
        raise DcslamError(f"unknown filter {name!r}; expected one of {', '.join([*FILTERS, *PRESETS])}")
    fields = {f.name: f.default for f in dataclasses.fields(FILTERS[name])}
    kwargs = {}
    for item in filter(None, args.split(",")):
        key, eq, value = item.partition("=")
        key = KEY_ALIASES.get(key.strip(), key.strip())
        if not eq or key not in fields:
            raise DcslamError(f"{spec!r}: expected key=value with key one of {', '.join(fields)}")
        try:
            kwargs[key] = _convert(value.strip(), fields[key])
        except ValueError as exc:
            raise DcslamError(f"{spec!r}: {key}: {exc}") from None
    try:
        return FILTERS[name](**kwargs)
    except DcslamError as exc:
        raise DcslamError(f"{spec!r}: {exc}") from None


def filter_frames(depth_m: np.ndarray, K: np.ndarray, chain: FilterChain, description: str = "filter") -> np.ndarray:
    """Filter every frame of a layer. Shapes: depth_m (N, H, W), K (3, 3) → (N, H, W) float32."""
    from dcslam.progress import track

    depth_m = np.asarray(depth_m)
    if depth_m.ndim != 3:
        raise DcslamError(f"depth has shape {depth_m.shape}, expected (N, H, W)")
    return np.stack([chain.apply(frame, K) for frame in track(depth_m, description)])


def filter_drives(jobs: Sequence[tuple[Path, str | Path, Path]], chain: FilterChain, made_by: str,
                  settings: dict, force: bool = False) -> list[Path]:
    """Filter depth layers and write them as new layers.

    ``jobs``: (drive file, depth source — ``sparse``, ``dense`` or a layer file —, output layer file). All outputs
    are checked before anything is written, so an existing output (without ``force``) or a missing input fails
    the whole call with nothing overwritten. Each layer's ``config`` records the source, the chain
    (``describe()`` of each filter) and ``settings``.
    """
    from dcslam.io.drive import DriveFile, Layer, load_depth, write_layer

    jobs = [(Path(d), s, Path(o)) for d, s, o in jobs]
    if not jobs:
        raise DcslamError("no drives to filter")
    for drive_path, source, out_path in jobs:
        if out_path.exists() and not force:
            raise DcslamError(f"{out_path} exists; pass --force to overwrite it")
        if not drive_path.exists():
            raise DcslamError(f"drive file {drive_path} not found; run `dcslam prepare-kitti` first")
        if str(source) not in ("sparse", "dense") and not Path(source).exists():
            raise DcslamError(f"layer file {source} not found; run `dcslam predict` or `dcslam filter` first")
    written = []
    for drive_path, source, out_path in jobs:
        with DriveFile(drive_path) as drive:
            depth = load_depth(drive, source)
            filtered = filter_frames(depth, drive.K, chain, f"{made_by} {drive.name}")
            config = {"source": str(source), "drive_file": str(drive_path), "filters": chain.describe(), **settings}
            write_layer(out_path, Layer(depth=filtered, drive=drive.name, made_by=made_by, config=config), force=force)
        written.append(out_path)
    return written
