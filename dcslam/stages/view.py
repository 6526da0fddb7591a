"""``dcslam view``: open a SLAM recording (``dcslam slam --record``, :mod:`dcslam.slam.record`) in the Rerun viewer,
or, where no viewer can open (no ``rerun`` on PATH, no display), say the exact command that opens it."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from dcslam.errors import DcslamError
from dcslam.settings import option
from dcslam.slam.record import INSTALL, SUFFIX
from dcslam.workspace import Workspace


@dataclass(frozen=True)
class ViewConfig:
    """Options of ``dcslam view``."""

    recording: Path = option(Path("."), argument=True, metavar="RUN",
                             help="A recording (.rrd), a `dcslam slam --record` output folder, or a layer name "
                                  "under the workspace's slam/ (e.g. dense).")
    drive: str | None = option(None, help="The drive whose recording to open, when the folder holds several.")


@dataclass
class ViewResult:
    """``path``: the recording; ``command``: the command line that opens it; ``web``: the one that serves it to a
    browser; ``opened``: whether a viewer was started, else ``why`` not."""

    path: Path
    command: list[str]
    web: list[str]
    opened: bool
    why: str = ""


def find_recording(ws: Workspace, where: Path, drive: str | None = None) -> Path:
    """The recording ``where`` names: a .rrd file, or the ``<drive>.rrd`` (the only one when ``drive`` is None) of a
    folder, the folder being ``where`` itself or, when no such path exists, ``<workspace>/slam/<where>``."""
    where = Path(where)
    if not where.exists() and (ws.slam / where).exists():
        where = ws.slam / where
    if where.is_file():
        if where.suffix != SUFFIX:
            raise DcslamError(f"{where} is not a Rerun recording ({SUFFIX}); record one with `dcslam slam --record`")
        return where
    if not where.is_dir():
        raise DcslamError(f"{where} not found (nor under {ws.slam}); record a run with `dcslam slam --record`")
    if drive is not None:
        path = where / f"{drive}{SUFFIX}"
        if not path.is_file():
            raise DcslamError(f"{path} not found; record it with `dcslam slam --record --drive {drive}`")
        return path
    found = sorted(where.glob(f"*{SUFFIX}"))
    if not found:
        raise DcslamError(f"no recordings ({SUFFIX}) in {where}; record a run with `dcslam slam --record`")
    if len(found) > 1:
        raise DcslamError(f"{where} holds {len(found)} recordings ({', '.join(p.stem for p in found)}); pass --drive")
    return found[0]


def has_display() -> bool:
    """Whether a native window can open here: a desktop OS, or X11 / Wayland named in the environment."""
    return sys.platform in ("darwin", "win32") or bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def run(ws: Workspace, config: ViewConfig) -> ViewResult:
    """Start the Rerun viewer on the recording ``config`` names, detached, when ``rerun`` is on PATH and a display
    is there; otherwise start nothing and say why, with the commands that open it."""
    path = find_recording(ws, config.recording, config.drive).absolute()
    command, web = ["rerun", str(path)], ["rerun", "--web-viewer", str(path)]
    executable = shutil.which("rerun")
    if executable is None:
        return ViewResult(path, command, web, False, f"rerun is not on PATH ({INSTALL})")
    if not has_display():
        return ViewResult(path, command, web, False, "no display here (neither DISPLAY nor WAYLAND_DISPLAY is set)")
    subprocess.Popen([executable, str(path)], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                     stderr=subprocess.DEVNULL, start_new_session=True)  # the viewer outlives this command
    return ViewResult(path, command, web, True)
