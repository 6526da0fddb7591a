"""Filters applied in order (a chain), over the frames of a layer and over drives, writing new layers."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.filters.base import check_depth


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

    @property
    def needs_confidence(self) -> bool:
        return any(getattr(f, "needs_confidence", False) for f in self.filters)

    def apply(self, depth_m: np.ndarray, K: np.ndarray, confidence: np.ndarray | None = None) -> np.ndarray:
        """(H, W), K (3, 3) [, confidence (H, W) for the filters that use it] → (H, W) float32; the input is not
        modified."""
        out = check_depth(depth_m)
        for f in self.filters:
            out = f.apply(out, K, confidence=confidence) if getattr(f, "needs_confidence", False) else f.apply(out, K)
        return out

    def describe(self) -> list[dict]:
        return [f.describe() for f in self.filters]


def filter_frames(depth_m: np.ndarray, K: np.ndarray, chain: FilterChain, description: str = "filter",
                  confidence: np.ndarray | None = None) -> np.ndarray:
    """Filter every frame of a layer. Shapes: depth_m (N, H, W), K (3, 3), confidence None or (N, H, W) →
    (N, H, W) float32."""
    from dcslam.progress import track

    depth_m = np.asarray(depth_m)
    if depth_m.ndim != 3:
        raise DcslamError(f"depth has shape {depth_m.shape}, expected (N, H, W)")
    if confidence is not None and np.shape(confidence) != depth_m.shape:
        raise DcslamError(f"confidence has shape {np.shape(confidence)}, expected {depth_m.shape} like its depth")
    frames = track(range(len(depth_m)), description)
    return np.stack([chain.apply(depth_m[i], K, None if confidence is None else confidence[i]) for i in frames])


def filter_drives(jobs: Sequence[tuple[Path, str | Path, Path]], chain: FilterChain, made_by: str,
                  settings: dict, force: bool = False) -> list[Path]:
    """Filter depth layers and write them as new layers.

    ``jobs``: (drive file, depth source — ``sparse``, ``dense`` or a layer file —, output layer file). All outputs
    are checked before anything is written, so an existing output (without ``force``) or a missing input fails
    the whole call with nothing overwritten. Each layer's ``config`` records the source, the chain
    (``describe()`` of each filter) and ``settings``.
    """
    from dcslam.io.atomic import AtomicSet
    from dcslam.io.drive import DriveFile, Layer, is_depth_kind, load_depth, read_layer, write_layer

    jobs = [(Path(d), s, Path(o)) for d, s, o in jobs]
    if not jobs:
        raise DcslamError("no drives to filter")
    for drive_path, source, out_path in jobs:
        if out_path.exists() and not force:
            raise DcslamError(f"{out_path} exists; pass --force to overwrite it")
        if not drive_path.exists():
            raise DcslamError(f"drive file {drive_path} not found; run `dcslam prepare-kitti` first")
        if (isinstance(source, Path) or not is_depth_kind(str(source))) and not Path(source).exists():
            raise DcslamError(f"layer file {source} not found; run `dcslam predict` or `dcslam filter` first")
    written = []
    with AtomicSet() as files:  # the layers appear together: a bad input or Ctrl-C leaves none of them
        for drive_path, source, out_path in jobs:
            with DriveFile(drive_path) as drive:
                depth = load_depth(drive, source)
                from_file = isinstance(source, Path) or not is_depth_kind(str(source))
                confidence = read_layer(source).confidence if from_file else None
                if chain.needs_confidence and confidence is None:
                    raise DcslamError(f"{source} holds no confidence; the confidence filter needs a layer predicted "
                                      f"by a confidence-aware model (e.g. `dcslam train --model nconv`, then "
                                      f"`dcslam predict`)")
                filtered = filter_frames(depth, drive.K, chain, f"{made_by} {drive.name}", confidence)
                config = {"source": str(source), "drive_file": str(drive_path), "filters": chain.describe(),
                          **settings}
                kept = None if confidence is None else np.where(filtered > 0, confidence, 0).astype(np.float32)
                out_path.parent.mkdir(parents=True, exist_ok=True)
                write_layer(files.stage(out_path), Layer(depth=filtered, drive=drive.name, frame_ids=drive.frame_ids,
                                                         made_by=made_by,
                                                         config=config, confidence=kept), force=True)
            written.append(out_path)
    return written
