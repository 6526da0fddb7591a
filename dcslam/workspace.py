"""Workspace layout, atomic writes and stage configuration files.

Every command reads and writes plain files under one folder (default ``./workspace``, or ``--workspace``, or the
``DCSLAM_WORKSPACE`` environment variable)::

    kitti/                 KITTI-format raw + depth folders (real, or from ``dcslam synth``)
    drives/                one HDF5 drive file per drive + splits.json (``dcslam prepare-kitti``)
    runs/<run>/            one training run (``dcslam train``)
    predictions/<run>/     depth layers written by ``dcslam predict``
    filtered/<name>/       depth layers written by ``dcslam filter``
    slam/<layer>/          trajectories, maps and summaries written by ``dcslam slam``
    results/               tables and plots written by ``dcslam score``

Nothing is overwritten without ``force``; every file is written under a temporary name in its final folder and
renamed when complete, so an interrupted stage leaves no half-written file.
"""
from __future__ import annotations

import os
import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from dcslam import __version__
from dcslam.errors import DcslamError
from dcslam.io.atomic import atomic_output, write_json_atomic, write_text_atomic  # noqa: F401 (moved to io/)

ENV_VAR = "DCSLAM_WORKSPACE"


@dataclass(frozen=True)
class Workspace:
    """The default folders of one workspace."""

    root: Path

    @classmethod
    def resolve(cls, root: Path | str | None = None) -> "Workspace":
        """``root`` if given, else ``$DCSLAM_WORKSPACE``, else ``./workspace``."""
        if root is None:
            root = os.environ.get(ENV_VAR) or "workspace"
        return cls(Path(root))

    @property
    def kitti(self) -> Path:
        return self.root / "kitti"

    @property
    def drives(self) -> Path:
        return self.root / "drives"

    @property
    def splits(self) -> Path:
        return self.drives / "splits.json"

    @property
    def runs(self) -> Path:
        return self.root / "runs"

    @property
    def predictions(self) -> Path:
        return self.root / "predictions"

    @property
    def filtered(self) -> Path:
        return self.root / "filtered"

    @property
    def slam(self) -> Path:
        return self.root / "slam"

    @property
    def results(self) -> Path:
        return self.root / "results"


def stage_config(stage: str, settings: dict) -> dict:
    """The record every stage writes beside its outputs: stage name, settings, dcslam version and time."""
    return {"stage": stage, "dcslam_version": __version__,
            "written": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "settings": settings}


def is_up_to_date(outputs: Iterable[Path], inputs: Iterable[Path]) -> bool:
    """True when every output exists and is newer than every input (used to skip finished pipeline stages)."""
    outputs, inputs = list(outputs), list(inputs)
    if not outputs or not all(p.exists() for p in outputs):
        return False
    newest_input = max((p.stat().st_mtime for p in inputs if p.exists()), default=0.0)
    return min(p.stat().st_mtime for p in outputs) >= newest_input


def require(path: Path, made_by: str) -> Path:
    """Return ``path`` if it exists, else fail naming the command that makes it."""
    if not Path(path).exists():
        raise DcslamError(f"{path} not found; run `{made_by}` first")
    return Path(path)
