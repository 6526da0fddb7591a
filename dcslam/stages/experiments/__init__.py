"""The experiments of ``dcslam reproduce`` behind one registry: each is a module holding a
:class:`dcslam.stages.pipeline.Experiment` (its profiles, the composition of its stages, its tables).

``EXPERIMENTS`` maps the name ``dcslam reproduce --table`` and ``dcslam score tables --table`` take to the
``"module:attribute"`` of its :class:`~dcslam.stages.pipeline.Experiment`; the modules are imported when asked for.
Adding an experiment is one module plus one line here.
"""
from __future__ import annotations

import importlib

from dcslam.errors import DcslamError

EXPERIMENTS = {
    "5.2": "dcslam.stages.experiments.table_5_2:TABLE_5_2",    # the thesis's Table 5.2: depth completion in SLAM
    "5.1": "dcslam.stages.experiments.table_5_2:TABLE_5_1",    # its Table 5.1: the recipes' validation (training)
    "beams": "dcslam.stages.experiments.beams:BEAMS",           # every input at 64/32/16/8 LiDAR beams
}


def experiment(name: str):
    """The :class:`~dcslam.stages.pipeline.Experiment` registered as ``name``."""
    if name not in EXPERIMENTS:
        raise DcslamError(f"unknown table {name!r}; expected one of {', '.join(EXPERIMENTS)}")
    module, _, attribute = EXPERIMENTS[name].partition(":")
    return getattr(importlib.import_module(module), attribute)
