"""`dcslam prepare-tum`: TUM RGB-D / ICL-NUIM sequences (real or generated) → drive files + splits.json
(options: dcslam.stages.prepare_tum)."""
from __future__ import annotations

from dcslam.cli.app import app
from dcslam.cli.options import stage_command
from dcslam.cli.prepare import report_prepared
from dcslam.stages import prepare_tum

HELP = (
    "Convert TUM RGB-D or ICL-NUIM sequences (real, or from `dcslam synth --indoor`) into one HDF5 drive file each "
    "plus splits.json, the format `dcslam slam`, `train` and `score` read.\n\n"
    "A sequence folder holds associations.txt (ICL-NUIM: 't depth/N.png t rgb/N.png') or rgb.txt and depth.txt "
    "(TUM: associated by nearest timestamp, at most 0.02 s apart), 16-bit depth PNGs (5000 = 1 m) and a TUM "
    "trajectory (groundtruth.txt or *.gt.freiburg, also looked for in the parent folder). Poses are interpolated "
    "at each depth timestamp; frames without one are dropped.\n\n"
    "Intrinsics: --intrinsics, else the folder's intrinsics.txt, else TUM's ROS default (525, 525, 319.5, 239.5) or "
    "ICL-NUIM's (481.2, -480, 319.5, 239.5): its negative fy is real (the camera's y axis points up) and is kept.\n\n"
    "depth/dense is the sensor depth; depth/sparse keeps every --sparse-stride-th row and column of it "
    "(LiDAR-like, 4 % of pixels at 5)."
)


def report(result) -> None:
    report_prepared(result, source_line=False)


prepare_tum_command = stage_command(app, "prepare-tum", prepare_tum.PrepareTumConfig, prepare_tum.run, report,
                                    help=HELP)
