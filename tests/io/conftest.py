"""Fixtures of KITTI roots for the io tests (builders in kitti_fixtures.py)."""
import importlib.util
from pathlib import Path

import pytest

_spec = importlib.util.spec_from_file_location("kitti_fixtures", Path(__file__).with_name("kitti_fixtures.py"))
fixtures = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fixtures)


@pytest.fixture
def real_root(tmp_path) -> Path:
    """A KITTI root with the real drive 2011_09_26_drive_0001_sync made complete by links."""
    return fixtures.link_real_drive(tmp_path / "kitti")


@pytest.fixture
def tiny_root(tmp_path) -> Path:
    """A KITTI root with one small drive 2011_09_26_drive_0002_sync (14 frames of 32x48, depth for 5..8)."""
    root = tmp_path / "tiny"
    fixtures.write_tiny_drive(root)
    return root
