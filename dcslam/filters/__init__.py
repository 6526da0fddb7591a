"""Filters on depth images, composed into chains that turn one depth layer into another.

One module per filter (``range``, ``bilateral``, ``outlier``, ``hidden``, ``edges``, ``confidence``), registered by
name in :data:`FILTERS`; adding a filter is one module plus one line there. Every filter is a small frozen object
with ``apply(depth_m, K) -> depth_m`` on one (H, W) float32 image in metres (a filter with ``needs_confidence``
also takes the layer's ``confidence=`` (H, W)) (0 = no value) and ``describe() -> dict`` (recorded in the layer
file it produces). Filters only ever *remove* depth (set pixels to 0) or, for the bilateral filter, smooth the depth
of pixels that have one; none of them fills holes.

The thesis's code filtered with a depth range of 5–15 m and ``cv2.bilateralFilter(d=5, sigmaColor=80,
sigmaSpace=80)``; these are the presets ``thesis-range`` and ``thesis-bilateral`` (:data:`PRESETS`). Statistical
outlier removal, hidden-point removal (both on the back-projected points, with Open3D) and removal of pixels at depth
discontinuities go beyond the thesis, which named outlier filtering as future work.
"""
from __future__ import annotations

from dcslam.errors import DcslamError
from dcslam.filters.base import backproject
from dcslam.filters.bilateral import BilateralFilter
from dcslam.filters.chain import FilterChain, filter_drives, filter_frames
from dcslam.filters.confidence import ConfidenceFilter
from dcslam.filters.edges import DiscontinuityFilter
from dcslam.filters.hidden import HiddenPointFilter
from dcslam.filters.outlier import StatisticalOutlierFilter
from dcslam.filters.range import RangeFilter

__all__ = ["FILTERS", "PRESETS", "BilateralFilter", "ConfidenceFilter", "DiscontinuityFilter", "FilterChain",
           "HiddenPointFilter", "RangeFilter", "StatisticalOutlierFilter", "backproject", "filter_drives",
           "filter_class", "filter_frames", "filter_help", "parse_filter"]

#: Filter names (of the command line and configuration files) → filter classes: the one place they are mapped.
FILTERS = {"range": RangeFilter, "bilateral": BilateralFilter, "outlier": StatisticalOutlierFilter,
           "hidden": HiddenPointFilter, "edges": DiscontinuityFilter, "confidence": ConfidenceFilter}
#: Short keys accepted in a filter spec.
KEY_ALIASES = {"min": "min_m", "max": "max_m"}

#: Named filters: the thesis's own settings.
PRESETS = {
    "thesis-range": RangeFilter(min_m=5.0, max_m=15.0),
    "thesis-bilateral": BilateralFilter(d=5, sigma_color=80.0, sigma_space=80.0),
}


def filter_help() -> str:
    """The help of a filter spec, generated from :data:`FILTERS` and :data:`PRESETS`."""
    import dataclasses

    shown = {v: k for k, v in KEY_ALIASES.items()}
    names = ", ".join(f"{name} ({', '.join(shown.get(f.name, f.name) for f in dataclasses.fields(cls))})"
                      for name, cls in FILTERS.items())
    presets = ", ".join(f"{name} ({', '.join(f'{k}={v}' for k, v in list(p.describe().items())[1:])})"
                        for name, p in PRESETS.items())
    from dcslam import plugins

    installed = ", ".join(plugins.targets(plugins.FILTERS, FILTERS))  # names only: a plugin is imported when used
    return (f"A filter, repeatable and applied in order: NAME or NAME:key=value,... with NAME one of {names}"
            + (f", from installed packages {installed}" if installed else "") + f", or a preset: {presets}. "
            "Example: --filter range:min=1,max=60 --filter bilateral:d=5,sigma_color=2")


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


def filter_class(name: str):
    """The filter class called ``name``: :data:`FILTERS`'s, else an installed package's (an entry point of
    ``dcslam.filters``, :mod:`dcslam.plugins`), imported here and checked to be a filter."""
    import dataclasses

    from dcslam import plugins

    if name in FILTERS:
        return FILTERS[name]
    if plugins.find(plugins.FILTERS, name) is None:
        known = [*FILTERS, *PRESETS, *plugins.targets(plugins.FILTERS, FILTERS)]
        raise DcslamError(f"unknown filter {name!r}; expected one of {', '.join(known)}")
    cls = plugins.load(plugins.FILTERS, name)
    if not (isinstance(cls, type) and dataclasses.is_dataclass(cls) and callable(getattr(cls, "apply", None))
            and callable(getattr(cls, "describe", None))):
        raise plugins.refuse(plugins.FILTERS, name, "is not a filter (a dataclass with apply(depth_m, K) and "
                             "describe())")
    return cls


def parse_filter(spec: str):
    """``NAME`` or ``NAME:key=value,...`` (or a preset name) → a filter object. Raises :class:`DcslamError`."""
    import dataclasses

    if spec in PRESETS:
        return PRESETS[spec]
    name, _, args = spec.partition(":")
    cls = filter_class(name)
    fields = {f.name: f.default for f in dataclasses.fields(cls)}
    kwargs = {}
    for item in filter(None, args.split(",")):
        key, eq, value = item.partition("=")
        key = key.strip() if key.strip() in fields else KEY_ALIASES.get(key.strip(), key.strip())
        if not eq or key not in fields:
            raise DcslamError(f"{spec!r}: expected key=value with key one of {', '.join(fields)}")
        try:
            kwargs[key] = _convert(value.strip(), fields[key])
        except ValueError as exc:
            raise DcslamError(f"{spec!r}: {key}: {exc}") from None
    try:
        return cls(**kwargs)
    except DcslamError as exc:
        raise DcslamError(f"{spec!r}: {exc}") from None
