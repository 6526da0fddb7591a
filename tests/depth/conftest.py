"""Fixtures of small analytic drive files for the depth tests (builders in tests/fixtures/depth.py)."""
from pathlib import Path

import pytest

from tests.fixtures import depth as fixtures


@pytest.fixture
def drive_path(tmp_path) -> Path:
    return fixtures.write_drive(tmp_path / "drive.h5")


@pytest.fixture
def workspace(tmp_path) -> Path:
    return fixtures.write_workspace(tmp_path / "ws")
