"""Shared test settings: no progress bars, and the path of the committed KITTI sample."""
import os
from pathlib import Path

import pytest

os.environ.setdefault("DCSLAM_PROGRESS", "0")

DATA = Path(__file__).parent / "data"


@pytest.fixture
def data_dir() -> Path:
    return DATA
