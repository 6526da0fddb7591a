"""The ``dcslam`` command line: one module per command, registered on one Typer app."""
from dcslam.cli.app import INTERRUPTED, app
from dcslam.cli import synth, prepare, train, predict, filter as filter_, slam, score, reproduce, demo_icl  # noqa: F401,E501

__all__ = ["app", "main"]


def main() -> None:
    """The ``dcslam`` command: exit 0, 1 (a known error), 2 (a usage error) or 130 (interrupted by Ctrl-C)."""
    from dcslam import interrupt

    interrupt.install()
    try:
        app()
    except SystemExit as done:
        if done.code != 130 and interrupt.received():  # a Ctrl-C that a finalizer swallowed
            _interrupted()
        raise
    if interrupt.received():
        _interrupted()


def _interrupted() -> None:
    import sys

    sys.stderr.write(f"{INTERRUPTED}\n")
    sys.exit(130)
