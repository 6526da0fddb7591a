"""One name for the output option of every command (--out); the older spellings still work, unshown in --help."""
import re

import pytest
from typer.testing import CliRunner

from dcslam.cli import app
from tests.cli.test_filter import make_workspace

runner = CliRunner()

COMMANDS = [("synth",), ("prepare-kitti",), ("slam",), ("predict",), ("filter",), ("score", "depth"),
            ("score", "trajectory"), ("score", "tables")]


def _help(*command):
    result = runner.invoke(app, [*command, "--help"], terminal_width=200)
    assert result.exit_code == 0, result.output
    return re.sub(r"\x1b\[[0-9;]*m", "", result.output)


@pytest.mark.parametrize("command", COMMANDS, ids=" ".join)
def test_every_command_names_its_output_out(command):
    text = _help(*command)
    assert re.search(r"--out\b(?!-)", text), text
    assert "--out-dir" not in text and "--output" not in text


@pytest.mark.parametrize("alias, command, extra", [
    ("--output", "predict", ("--model", "ip-basic-fast")),
    ("--out-dir", "filter", ("--run", "mse-dense", "--filter", "range")),
])
def test_the_old_spellings_still_work(tmp_path, alias, command, extra):
    ws = make_workspace(tmp_path / "ws")
    out = tmp_path / "here"
    result = runner.invoke(app, [command, "-w", str(ws), *extra, alias, str(out)])
    assert result.exit_code == 0, result.output
    assert any(p.suffix == ".h5" for p in out.iterdir())
    both = runner.invoke(app, [command, "-w", str(ws), *extra, alias, str(out), "--out", str(out)])
    assert both.exit_code == 2 and "give --out once" in both.output
