"""Shared test settings: no progress bars, the path of the committed KITTI sample, the in-process command line
(``cli``), one smoke reproduction on tiny drives shared by the session (``tiny_smoke``), and the device and dtype
fixtures of the torch op tests (cpu always, cuda on a machine with a GPU and reported as skipped elsewhere; float32
and float64)."""
import os
from pathlib import Path

import pytest

os.environ.setdefault("DCSLAM_PROGRESS", "0")

DATA = Path(__file__).parent / "data"


def _devices() -> list:
    import torch

    no_gpu = pytest.mark.skipif(not torch.cuda.is_available(), reason="cuda: no GPU on this machine")
    return ["cpu", pytest.param("cuda", marks=no_gpu)]


@pytest.fixture
def data_dir() -> Path:
    return DATA


@pytest.fixture(scope="session")
def tiny_smoke(tmp_path_factory):
    """``reproduce --profile smoke`` on three tiny drives, made once for every pytest-xdist worker of the session
    (tests.fixtures.smoke): read it only."""
    from tests.fixtures.smoke import tiny_smoke

    base = tmp_path_factory.getbasetemp()
    return tiny_smoke(base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base)


@pytest.fixture(scope="session")
def cli():
    """``dcslam`` in this process: ``cli("slam", "-w", ws, "--frames", 2)`` runs ``dcslam slam -w WS --frames 2``
    and returns click's ``Result`` (``exit_code``, ``stdout``, ``stderr``, ``output``). Arguments are passed
    through ``str``. An exception that escapes the command (a crash, not a known error with its exit code 1) fails
    the test with its traceback; ``catch_exceptions=True`` turns it into ``result.exception`` instead. Session-wide,
    so module-wide fixtures may run commands too."""
    from typer.testing import CliRunner

    from dcslam.cli import app

    runner = CliRunner()

    def invoke(*args, catch_exceptions: bool = False):
        return runner.invoke(app, [str(a) for a in args], catch_exceptions=catch_exceptions)

    return invoke


@pytest.fixture(params=_devices())
def device(request):
    """``torch.device("cpu")``, and ``torch.device("cuda")`` (skipped on a machine without a GPU)."""
    import torch

    return torch.device(request.param)


@pytest.fixture(params=["float32", "float64"])
def dtype(request):
    """``torch.float32`` and ``torch.float64``."""
    import torch

    return getattr(torch, request.param)


def pytest_collection_modifyitems(config, items):
    """The files of the long runs first (the Slurm runs, then the slow end-to-end ones), each file's tests in their
    order: `make test` hands whole files to its workers in this order (``--no-loadscope-reorder``), so the longest
    start at once instead of ending the run on one worker while the other waits."""
    rank = {}
    for item in items:
        path = str(item.path)
        here = 0 if item.get_closest_marker("cluster") else 1 if item.get_closest_marker("slow") else 2
        rank[path] = min(rank.get(path, 2), here)
    items.sort(key=lambda item: rank[str(item.path)])  # stable: the order within a rank is the collection's
