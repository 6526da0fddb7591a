"""The examples of docs/extending.md, run as written: a completer, a filter, a dataset and an experiment, one module
each, registered by one line each, then used through the stages."""
import re
import sys
from pathlib import Path

import numpy as np
import pytest

PAGE = Path(__file__).parents[1] / "docs" / "extending.md"


def _blocks() -> dict[str, str]:
    """The Python blocks of the page, by their first line (``# mypkg/<file>.py`` or ``# register``)."""
    blocks = re.findall(r"```python\n(.*?)```", PAGE.read_text(), re.S)
    return {block.splitlines()[0].lstrip("# ").strip(): block for block in blocks}


@pytest.fixture
def registered(tmp_path, monkeypatch):
    """The example modules written under tmp_path/mypkg, importable, and the page's registration run."""
    from dcslam.depth.models import CLASSICAL
    from dcslam.filters import FILTERS
    from dcslam.stages.datasets import DATASETS

    blocks = _blocks()
    (tmp_path / "mypkg").mkdir()
    (tmp_path / "mypkg" / "__init__.py").write_text("")
    for name, code in blocks.items():
        if name.startswith("mypkg/"):
            (tmp_path / name).write_text(code)
    monkeypatch.syspath_prepend(str(tmp_path))
    saved = [(registry, dict(registry)) for registry in (CLASSICAL, FILTERS, DATASETS)]
    exec(compile(blocks["register"], "docs/extending.md register block", "exec"), {})
    yield
    for registry, before in saved:  # the registries as they were
        registry.clear()
        registry.update(before)
    for module in [m for m in sys.modules if m == "mypkg" or m.startswith("mypkg.")]:
        del sys.modules[module]


def _write_npz_sequence(root: Path, n: int = 3, h: int = 24, w: int = 32) -> None:
    folder = root / "seq0"
    folder.mkdir(parents=True)
    np.savetxt(folder / "K.txt", [[30.0, 0, w / 2], [0, 30.0, h / 2], [0, 0, 1]])
    rng = np.random.default_rng(0)
    for i in range(n):
        T = np.eye(4)
        T[2, 3] = 0.1 * i
        np.savez(folder / f"frame_{i}.npz", rgb=np.zeros((h, w, 3), np.uint8),
                 depth_m=rng.uniform(2, 50, (h, w)).astype(np.float32), T_world_cam=T)


def test_the_three_examples_work_through_the_stages(registered, tmp_path):
    from dcslam.io.drive import DriveFile, read_layer
    from dcslam.stages.datasets import dataset
    from dcslam.stages.filter import FilterConfig, run as run_filter
    from dcslam.stages.predict import PredictConfig, run as run_predict
    from dcslam.workspace import Workspace

    ws = Workspace(tmp_path / "ws")
    _write_npz_sequence(tmp_path / "npz")
    npz = dataset("npz")
    prepared = npz.run(ws, npz.CONFIG(src=tmp_path / "npz"))
    assert [(d.name, d.frames) for d in prepared.drives] == [("seq0", 3)]
    with DriveFile(ws.drives / "seq0.h5") as drive:
        sparse, dense = drive.depth("sparse", 0), drive.depth("dense", 0)
    assert (sparse > 0).sum() == 6 * 8 and np.array_equal(sparse[::4, ::4], dense[::4, ::4])

    predicted = run_predict(ws, PredictConfig(model="nearest-fill"))
    assert predicted.out_dir == ws.predictions / "nearest-fill"
    filled = read_layer(predicted.layers[0]).depth[0]
    assert (filled > 0).all() and np.array_equal(filled[::4, ::4], dense[::4, ::4])  # measured pixels kept

    result = run_filter(ws, FilterConfig(filters=["far:max_m=30"], depth="predicted", run="nearest-fill"))
    assert result.out_dir == ws.filtered / "nearest-fill+far"
    far = read_layer(result.layers[0]).depth[0]
    assert far.max() <= 30 and np.array_equal(far[filled <= 30], filled[filled <= 30])


def test_the_experiment_example_runs_skips_and_rebuilds_its_table(registered, tmp_path, monkeypatch):
    """The page's experiment through ``reproduce`` (synth and prepare-kitti replaced by the tiny drives of the stage
    tests), a rerun that skips every stage, and ``score tables --table fill``."""
    from dcslam.stages.experiments import EXPERIMENTS, experiment
    from dcslam.workspace import Workspace
    from tests.fixtures import depth as depth_fixtures

    def synth(ws, config, *, force=False):
        ws.kitti.mkdir(parents=True, exist_ok=True)
        (ws.kitti / "SYNTHETIC").write_text("tiny drives of the extending test\n")

    monkeypatch.setattr("dcslam.stages.synth.run", synth)
    monkeypatch.setattr("dcslam.stages.prepare.run",
                        lambda ws, config, *, force=False: depth_fixtures.write_workspace(ws.root, n=6))
    saved = dict(EXPERIMENTS)
    exec(compile(_blocks()["register an experiment"], "docs/extending.md experiment block", "exec"), {})
    try:
        _run_the_experiment(Workspace(tmp_path / "ws"), experiment("fill").profile("smoke"))
    finally:  # the registry as it was
        EXPERIMENTS.clear()
        EXPERIMENTS.update(saved)


def _run_the_experiment(ws, profile) -> None:
    from dcslam.stages.reproduce import reproduce
    from dcslam.stages.score import ScoreTablesConfig, run_tables

    lines = []
    table = reproduce(ws, profile, table="fill", log=lines.append)
    assert table == ws.results / "table_fill.md"
    text = table.read_text()
    assert "ip-basic-fast" in text and "nearest-fill" in text and "MAE (mm)" in text
    assert (ws.predictions / "nearest-fill" / "drive_d.h5").exists()
    assert any(line.startswith("[run]  score-fill") for line in lines)
    lines.clear()
    reproduce(ws, profile, table="fill", log=lines.append)
    assert lines and all(line.startswith("[skip]") for line in lines), lines
    table.unlink()
    report = run_tables(ws, ScoreTablesConfig(table="fill"))
    assert report.written == [table] and table.read_text() == text
