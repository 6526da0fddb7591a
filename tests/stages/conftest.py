"""Shared builders of the stage tests: a tiny workspace (drives a, b train; c val; d test; 32 × 64, 6 frames)."""
import pytest

from tests.fixtures import depth as depth_fixtures


@pytest.fixture
def ws(tmp_path):
    from dcslam.workspace import Workspace

    return Workspace(depth_fixtures.write_workspace(tmp_path / "ws", n=4))
