"""Help at 80 and 120 columns stays readable: click's plain layout within the width, flags listed bare (not as
taking a <bool> value), values named by type (FLOAT, not <float range>), help beside the option."""
import re

import pytest
from typer.testing import CliRunner

from dcslam.cli import app


@pytest.mark.parametrize("columns", [80, 120])
@pytest.mark.parametrize("command", [["slam"], ["train"], ["score", "trajectory"], ["view"], []])
def test_help_fits_the_terminal_and_lists_flags_bare(command, columns):
    result = CliRunner().invoke(app, [*command, "--help"], env={"COLUMNS": str(columns)})
    assert result.exit_code == 0
    # example command lines are left unwrapped on purpose, so that they can be copied whole
    lines = [line for line in result.output.splitlines() if not line.startswith("    dcslam ")]
    assert max(len(line) for line in lines) <= columns, [line for line in lines if len(line) > columns]
    assert "<bool>" not in result.output and "│" not in result.output  # no Rich table
    assert re.search(r"^  -h, --help +Show this message and exit\.$", result.output, re.M)


def test_options_name_their_value_type_and_keep_their_help_beside_them():
    output = CliRunner().invoke(app, ["slam", "--help"], env={"COLUMNS": "80"}).output
    assert re.search(r"^  --max-distance FLOAT +ICP outlier gate, metres\.", output, re.M)
    assert re.search(r"^  --record +Also write a Rerun recording", output, re.M)
    assert re.search(r"^  -w, --workspace PATH +Workspace folder", output, re.M)


@pytest.mark.parametrize("command", [[], ["score"]])
def test_every_command_summary_shows_whole_at_80_columns(command):
    output = CliRunner().invoke(app, [*command, "--help"], env={"COLUMNS": "80"}).output
    listed = output.split("Commands:\n", 1)[1].splitlines()
    assert len(listed) >= 6 and all(line.startswith("  ") for line in listed if line)
    assert not [line for line in listed if line.endswith("...")]  # click cuts a summary too long for the width
