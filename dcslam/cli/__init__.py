"""The ``dcslam`` command line: one module per command, registered on one Typer app."""
from dcslam.cli.app import app
from dcslam.cli import synth, prepare, train, predict, filter as filter_, slam, score, reproduce, demo_icl  # noqa: F401,E501

__all__ = ["app", "main"]


def main() -> None:
    app()
