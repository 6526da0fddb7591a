"""How a setting is declared once: :func:`option` makes a dataclass field that carries its command-line help.

Library configurations (:mod:`dcslam.depth.config`, :mod:`dcslam.slam.config`) declare their settings with it and the
stage configurations extend them, so that each setting has one default, one help text and one validation; the
metadata keys are described in :mod:`dcslam.stages.config`. No heavy imports: ``dcslam --help`` reads these fields.
"""
from __future__ import annotations

import dataclasses

_MISSING = dataclasses.MISSING


def option(default=_MISSING, *, help: str, default_factory=_MISSING, **meta):
    """A configuration field with its help text (and ``choices``, ``min``, ``max``, ``flags``, ``show_default``,
    ``metavar``, ``validate``, ``internal``, ``aliases``: other spellings of the option, accepted but not shown in
    ``--help``; ``argument=True``: a positional argument on the command line)."""
    metadata = {"help": help, **meta}
    if default_factory is not _MISSING:
        return dataclasses.field(default_factory=default_factory, metadata=metadata)
    return dataclasses.field(default=default, metadata=metadata)
