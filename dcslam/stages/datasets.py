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
    """The stage module of dataset ``name``: :data:`DATASETS`'s, else an installed package's (an entry point of
    ``dcslam.datasets``, :mod:`dcslam.plugins`), imported here and checked to hold ``CONFIG``, ``HELP`` and
    ``run``."""
    from dcslam import plugins

    if name in DATASETS:
        return importlib.import_module(DATASETS[name])
    if plugins.find(plugins.DATASETS, name) is None:
        known = [*DATASETS, *plugins.targets(plugins.DATASETS, DATASETS)]
        raise DcslamError(f"unknown dataset {name!r}; expected one of {', '.join(known)}")
    module = plugins.load(plugins.DATASETS, name)
    missing = [attr for attr in ("CONFIG", "HELP", "run") if not hasattr(module, attr)]
    if missing:
        raise plugins.refuse(plugins.DATASETS, name, f"lacks {', '.join(missing)} (a dataset module holds CONFIG, "
                             "HELP and run)")
    return module


def installed() -> tuple[str, ...]:
    """The datasets of installed packages (entry points of ``dcslam.datasets``) whose names dcslam's own lack."""
    from dcslam import plugins

    return tuple(plugins.targets(plugins.DATASETS, DATASETS))
