"""`dcslam view`: open a `dcslam slam --record` recording in the Rerun viewer, or print the command that opens it
(options: dcslam.stages.view)."""
from __future__ import annotations

import shlex

from dcslam.cli.app import app, summary
from dcslam.cli.options import stage_command
from dcslam.stages import view

HELP = ("Open a SLAM recording (dcslam slam --record) in the Rerun viewer; without a display or a rerun on PATH, "
        "print the command that opens it.")


def report(result: view.ViewResult) -> None:
    if result.opened:
        summary(f"opened {result.path} in the Rerun viewer")
        return
    summary(f"{result.why}; open the recording with\n  {shlex.join(result.command)}\n"
            f"or in a browser (it prints the address):\n  {shlex.join(result.web)}")


view_command = stage_command(app, "view", view.ViewConfig, view.run, report, help=HELP, force=False,
                             examples=("dcslam view dense --drive 2011_09_26_drive_0002_sync",
                                       "dcslam view workspace/slam/dense/2011_09_26_drive_0002_sync.rrd"))
