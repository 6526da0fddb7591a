"""The Typer application and what every command shares: the workspace option and error handling.

Each command lives in its own module of this package, is a thin wrapper that turns options into a library call,
and never holds logic of its own. Heavy imports (torch, open3d, h5py) stay inside command bodies so that
``dcslam --help`` answers fast.
"""
from __future__ import annotations

import functools
import sys
from pathlib import Path
from typing import Annotated, Optional

import typer

app = typer.Typer(
    name="dcslam",
    help="Depth completion trained through a differentiable dense SLAM: generate or read KITTI, train, predict, "
         "filter, run SLAM and score (reproduces Tables 5.1 and 5.2 of 'Machine Learning for Robotic Exploration').",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    # click's plain help: Rich's option tables squeeze the help into ~15-character columns at 80 columns and show
    # flags as if they took a <bool> value; the plain layout wraps help beside the options and lists flags bare
    rich_markup_mode=None,
    context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 120},
)

WorkspaceOption = Annotated[Optional[Path], typer.Option(
    "--workspace", "-w", envvar="DCSLAM_WORKSPACE", show_default="./workspace", metavar="PATH",
    help="Workspace folder holding kitti/, drives/, runs/, predictions/, slam/, results/.")]
ForceOption = Annotated[bool, typer.Option("--force", help="Overwrite outputs that exist.")]


def fail(message: str) -> None:
    """Print one line on stderr and exit with code 1."""
    typer.echo(f"error: {message}", err=True)
    raise typer.Exit(1)


def known_errors(command):
    """Turn :class:`~dcslam.errors.DcslamError` (and a write the machine refused: a full disk, a read-only
    filesystem; a worker process that died) into one line on stderr and exit code 1, Ctrl-C into exit 130 (SIGTERM
    into 143), with a line saying what the command kept and how to go on (:func:`dcslam.interrupt.keep`)."""

    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        from concurrent.futures import BrokenExecutor

        from dcslam import interrupt
        from dcslam.errors import DcslamError

        interrupt.keep(None)  # what an interrupt leaves is said by the command that runs now
        try:
            return command(*args, **kwargs)
        except DcslamError as error:
            fail(str(error))
        except (FileExistsError, NotADirectoryError, IsADirectoryError, PermissionError) as error:
            # a path that is the wrong kind of thing, or not ours to write: the user's to fix, not a bug
            fail(f"{error.filename}: {error.strerror}; check the paths given (--workspace, --out, ...)")
        except OSError as error:
            # a write the machine refused (a full disk, a read-only or failing filesystem) that no stage named
            from dcslam.errors import write_error

            known = write_error(error, error.filename or "a file")
            if known is None:
                raise
            fail(f"{known}; free space or choose a writable --workspace, then rerun the command")
        except BrokenExecutor:
            # a pool worker the system killed (most often for memory) or that crashed in native code
            fail("a worker process of this command died (killed by the system, most often for want of memory, or a "
                 "crash); rerun it with fewer --jobs or more memory")
        except interrupt.CAUGHT as error:
            if not interrupt.is_interrupt(error):    # a SystemError or ImportError of its own: with its traceback
                raise
            interrupt.tell(lambda line: typer.echo(line, err=True))
            raise typer.Exit(interrupt.exit_code()) from None

    return wrapper


def summary(text: str) -> None:
    """A short result summary on stdout."""
    sys.stdout.write(text.rstrip("\n") + "\n")
