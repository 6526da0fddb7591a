"""The reproduction pipeline: stage skipping (unit) and the whole experiment at the smoke profile (end to end),
every stage run in this process."""
import json
import os

import pytest
from typer.testing import CliRunner

from dcslam.cli import app
from dcslam.errors import DcslamError
from dcslam import __version__
from dcslam.stages.config import code_version
from dcslam.stages.reproduce import PROFILES, Pipeline, Stage, reproduce
from dcslam.stages.slam import SlamStageConfig
from dcslam.workspace import Workspace

runner = CliRunner()


def _fake_stage(calls, outputs):
    """Stand-in for a stage's run(): records the call and writes the stage's outputs."""
    def run(ws, config, *, force=False):
        calls.append((config, force))
        for path in outputs:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text("made")
        return "result"
    return run


def test_stage_runs_once_then_is_skipped_until_its_inputs_config_or_code_change(tmp_path, monkeypatch):
    ws = Workspace(tmp_path)
    source, made = tmp_path / "in.txt", tmp_path / "out" / "made.txt"
    source.write_text("input")
    os.utime(source, (1_000_000, 1_000_000))
    calls = []
    pipe = Pipeline(ws, log=lambda line: None)
    fake = _fake_stage(calls, [made])
    stage = Stage("demo", fake, SlamStageConfig(frames=3), outputs=lambda: [made], inputs=lambda: [source])

    assert pipe.run(stage) == "result"
    assert calls == [(SlamStageConfig(frames=3), True)]  # in this process, with force
    stamp = json.loads((tmp_path / ".reproduce" / "demo.json").read_text())
    assert stamp["config"]["frames"] == 3 and stamp["dcslam"] == code_version()
    assert pipe.run(stage) is None
    assert len(calls) == 1  # up to date: skipped

    os.utime(source, None)  # the input changed after the output was made
    os.utime(made, (1_000_000, 1_000_000))
    pipe.run(stage)
    assert len(calls) == 2

    pipe.run(Stage("demo", fake, SlamStageConfig(frames=4), outputs=lambda: [made], inputs=lambda: [source]))
    assert len(calls) == 3  # another configuration: rerun

    monkeypatch.setattr("dcslam.stages.reproduce.code_version", lambda: "0.0.0+other")
    pipe.run(Stage("demo", fake, SlamStageConfig(frames=4), outputs=lambda: [made], inputs=lambda: [source]))
    assert len(calls) == 4  # other dcslam code: rerun
    monkeypatch.undo()

    made.unlink()
    pipe.run(stage)
    assert len(calls) == 5  # output missing: rerun


def test_code_version_changes_with_the_sources(tmp_path, monkeypatch):
    import dcslam.stages.config as config

    before = code_version()
    assert before.startswith(__version__ + "+")
    fake_root = tmp_path / "dcslam"
    (fake_root / "stages").mkdir(parents=True)
    (fake_root / "a.py").write_text("x = 1\n")
    monkeypatch.setattr(config, "__file__", str(fake_root / "stages" / "config.py"))
    first = code_version()
    (fake_root / "a.py").write_text("x = 2\n")
    assert code_version() != first != before


def test_failed_stage_stops_the_pipeline_with_one_line(tmp_path, monkeypatch):
    def fail(ws, config, *, force=False):
        raise DcslamError("no luck")

    monkeypatch.setattr("dcslam.stages.synth.run", fail)
    with pytest.raises(DcslamError, match="stage synth failed \\(no luck\\)"):
        reproduce(Workspace(tmp_path), PROFILES["smoke"], log=lambda line: None)
    stamp = tmp_path / ".reproduce" / "synth.json"
    assert json.loads(stamp.read_text())["complete"] is False  # claims nothing: the next run redoes it


def test_unknown_profile_and_table_fail_with_exit_code(tmp_path):
    result = runner.invoke(app, ["reproduce", "--profile", "huge", "--workspace", str(tmp_path)])
    assert result.exit_code == 2 and "huge" in result.stderr  # a usage error, like every unknown choice
    result = runner.invoke(app, ["reproduce", "--table", "9.9", "--workspace", str(tmp_path)])
    assert result.exit_code == 2 and "9.9" in result.stderr
    result = runner.invoke(app, ["reproduce", "--kitti", str(tmp_path / "nowhere"), "--workspace", str(tmp_path)])
    assert result.exit_code == 1 and "does not exist" in result.stderr


def test_smoke_profile_runs_every_stage_and_writes_the_tables(tmp_path):
    """The whole experiment on a few tiny generated drives: every stage, then a rerun that skips them all."""
    result = runner.invoke(app, ["reproduce", "--profile", "smoke", "--workspace", str(tmp_path)])
    assert result.exit_code == 0, result.output
    results = tmp_path / "results"
    for name in ("table_5_1.md", "table_5_1.csv", "table_5_2.md", "table_5_2.csv", "depth_examples.png"):
        assert (results / name).stat().st_size > 0, name
    assert list(results.glob("trajectories_*.png"))
    table = (results / "table_5_2.md").read_text()
    assert "Table 5.2" in result.stdout
    for layer in ("chamfer-1", "chamfer-8", "mse-sparse", "mse-dense", "sparse", "dense", "ip-basic-fast",
                  "mse-dense+edges"):
        assert f"| {layer} |" in table, layer
        assert list((tmp_path / "slam" / layer).glob("*.txt")), layer
    rows = [line for line in table.splitlines() if line.startswith("| ") and not line.startswith(("| method", "| ---"))]
    assert len(rows) == 11 and all(row.rstrip(" |").endswith("—") for row in rows)  # no row lacks its inputs

    again = runner.invoke(app, ["reproduce", "--profile", "smoke", "--workspace", str(tmp_path)])
    assert again.exit_code == 0, again.output
    assert "[run]" not in again.stderr and again.stderr.count("[skip]") >= 20
