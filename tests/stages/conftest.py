"""Shared builders of the stage tests: a tiny workspace (drives a, b train; c val; d test; 32 × 64, 6 frames)."""
import importlib.util
from pathlib import Path

import pytest

_spec = importlib.util.spec_from_file_location("depth_fixtures",
                                               Path(__file__).parents[1] / "depth" / "depth_fixtures.py")
depth_fixtures = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(depth_fixtures)


@pytest.fixture
def ws(tmp_path):
    from dcslam.workspace import Workspace

    return Workspace(depth_fixtures.write_workspace(tmp_path / "ws", n=4))
