"""Shared test settings: no progress bars, the path of the committed KITTI sample, and the device and dtype
fixtures of the torch op tests (cpu always, cuda when this machine has a GPU; float32 and float64)."""
import os
from pathlib import Path

import pytest

os.environ.setdefault("DCSLAM_PROGRESS", "0")

DATA = Path(__file__).parent / "data"


def _devices() -> list[str]:
    import torch

    return ["cpu", "cuda"] if torch.cuda.is_available() else ["cpu"]


@pytest.fixture
def data_dir() -> Path:
    return DATA


@pytest.fixture(params=_devices())
def device(request):
    """``torch.device("cpu")``, and ``torch.device("cuda")`` when a GPU is available."""
    import torch

    return torch.device(request.param)


@pytest.fixture(params=["float32", "float64"])
def dtype(request):
    """``torch.float32`` and ``torch.float64``."""
    import torch

    return getattr(torch, request.param)
