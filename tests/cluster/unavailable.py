"""What the cluster tests do when their Slurm cannot start: fail under CI (``CI=true``), skip elsewhere, always
with the reason."""
from __future__ import annotations

import os

import pytest


def unavailable(reason: str):
    """Fail under CI, skip elsewhere, with ``reason``."""
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail(f"the Slurm cluster of the cluster tests is unavailable: {reason}", pytrace=False)
    pytest.skip(f"the Slurm cluster of the cluster tests is unavailable: {reason}")
