"""`dcslam export`: a depth layer → KITTI devkit PNGs (options: dcslam.stages.export_devkit)."""
from __future__ import annotations

from dcslam.cli.app import app, summary
from dcslam.cli.options import stage_command
from dcslam.stages import export_devkit

HELP = ("Write a depth layer (sparse, dense, a prediction, a filtered layer) as KITTI devkit PNGs (uint16, metres "
        "× 256, 0 = no depth) in the benchmark's per-drive layout, or named by index with their ordered list.")


def report(result: export_devkit.ExportResult) -> None:
    listed = f" and {result.list_file}" if result.list_file else ""
    summary(f"{len(result.files)} PNG(s) of layer {result.layer} in {result.out_dir}{listed}")


export_command = stage_command(app, "export", export_devkit.ExportConfig, export_devkit.run, report, help=HELP,
                               examples=("dcslam export --depth predicted/ip-basic-fast --out ip-basic-devkit",
                                         "dcslam export --depth sparse --out test-input --layout index"))
