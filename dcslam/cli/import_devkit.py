"""`dcslam import`: another method's KITTI devkit PNGs → a prediction layer (options: dcslam.stages.import_devkit)."""
from __future__ import annotations

from dcslam.cli.app import app, summary
from dcslam.cli.options import stage_command
from dcslam.stages import import_devkit

HELP = ("Bring another method's predictions, saved as KITTI devkit PNGs (uint16, metres × 256, 0 = no depth), into "
        "the workspace as the layer predictions/<name>/<drive>.h5, every file checked against its drive; slam, "
        "score and filter then take it like any other layer.")


def report(result: import_devkit.ImportResult) -> None:
    summary(f"imported {result.frames} frame(s) of {len(result.layers)} drive(s) as layer {result.name} in "
            f"{result.out_dir}")


import_command = stage_command(app, "import", import_devkit.ImportConfig, import_devkit.run, report, help=HELP,
                               examples=("dcslam import --src penet-val --name penet",
                                         "dcslam import --src cformer --layout index --list test_list.txt "
                                         "--crop 100,0"))
