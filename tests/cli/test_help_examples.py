"""Every command's --help ends with examples, and every example is a command line that parses."""
import shlex

import pytest
import typer

from dcslam.cli import app


def _commands():
    root = typer.main.get_command(app)
    for name, command in root.commands.items():
        if hasattr(command, "commands"):
            yield from ((f"{name} {sub}", c) for sub, c in command.commands.items())
        else:
            yield name, command


COMMANDS = dict(_commands())


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_help_has_examples_that_parse(cli, name, tmp_path):
    text = COMMANDS[name].help
    assert "Examples:" in text, name
    examples = [line.strip() for line in text.split("Examples:")[1].splitlines() if line.strip().startswith("dcslam")]
    assert 1 <= len(examples) <= 3, name
    for example in examples:
        words = shlex.split(example.split("#")[0])
        assert " ".join(words[1:]).startswith(name), example
        result = cli(*words[1:], "--print-config", "-w", tmp_path / "ws")
        assert result.exit_code == 0, (example, result.output)
