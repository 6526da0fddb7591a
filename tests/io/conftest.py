"""Fixtures of KITTI roots for the io tests (builders in tests/fixtures/kitti.py)."""
from pathlib import Path

import pytest

from tests.fixtures import kitti as fixtures


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
