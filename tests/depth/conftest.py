"""Fixtures of small analytic drive files for the depth tests (builders in depth_fixtures.py)."""
import importlib.util
from pathlib import Path

import pytest

_spec = importlib.util.spec_from_file_location("depth_fixtures", Path(__file__).with_name("depth_fixtures.py"))
fixtures = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fixtures)


@pytest.fixture
def drive_path(tmp_path) -> Path:
    return fixtures.write_drive(tmp_path / "drive.h5")


@pytest.fixture
def workspace(tmp_path) -> Path:
    return fixtures.write_workspace(tmp_path / "ws")
