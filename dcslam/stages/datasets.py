"""Dataset readers behind one registry: each is a stage module that converts a dataset into drive files.

``DATASETS`` maps a dataset's name to its module; ``dcslam prepare-<name>`` is generated from it. A module holds
``CONFIG`` (its configuration dataclass), ``HELP`` (the command's help) and ``run(workspace, config, *, force)``
returning a :class:`dcslam.stages.prepare.PrepareResult`. Adding a dataset is one module plus one line here.
"""
from __future__ import annotations

import importlib
from types import ModuleType

from dcslam.errors import DcslamError

DATASETS = {
    "kitti": "dcslam.stages.prepare",       # KITTI raw + depth completion (real, or from `dcslam synth`)
    "tum": "dcslam.stages.prepare_tum",     # TUM RGB-D / ICL-NUIM (real, or from `dcslam synth --indoor`)
}


def dataset(name: str) -> ModuleType:
    """The stage module of dataset ``name``."""
    if name not in DATASETS:
        raise DcslamError(f"unknown dataset {name!r}; expected one of {', '.join(DATASETS)}")
    return importlib.import_module(DATASETS[name])
