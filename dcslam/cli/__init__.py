"""The ``dcslam`` command line: one module per command, registered on one Typer app."""
from dcslam import interrupt
from dcslam.cli.app import app
from dcslam.cli import synth, prepare, train, predict, filter as filter_, slam, score, reproduce, demo_icl  # noqa: F401,E501
from dcslam.cli import import_devkit, export_devkit, view  # noqa: F401

__all__ = ["app", "main"]


def main() -> None:
    """The ``dcslam`` command: exit 0, 1 (a known error), 2 (a usage error), 130 (interrupted by Ctrl-C) or 143
    (by SIGTERM)."""
    try:
        interrupt.install()
        app()
    except interrupt.CAUGHT as error:  # before Typer's own handler runs
        if not interrupt.is_interrupt(error):
            raise
        _interrupted()
    except SystemExit as done:
        # Typer turns a Ctrl-C outside the command (while it parses options) into a silent exit 130, and click or a
        # finalizer may swallow one: every way out after a Ctrl-C says so and exits 130 (143: SIGTERM)
        if done.code == 130 or interrupt.received():
            _interrupted()
        raise
    finally:
        # the outcome is decided and written: a Ctrl-C or SIGTERM while Python shuts down (which can take a second
        # with torch loaded) changes nothing, and must neither print "Exception ignored" nor kill the process
        interrupt.ignore()
    if interrupt.received():
        _interrupted()


def _interrupted() -> None:
    import sys

    interrupt.tell(lambda line: sys.stderr.write(line + "\n"))
    sys.exit(interrupt.exit_code())
