"""`dcslam synth`: generate KITTI-format drives from procedural street scenes (options: dcslam.stages.synth)."""
from __future__ import annotations

import typer

from dcslam.cli.app import app, summary
from dcslam.cli.options import stage_command
from dcslam.stages import synth

HELP = (
    "Generate synthetic drives in the KITTI raw + depth-completion layout, so that everything downstream runs "
    "without downloading KITTI.\n\n"
    "Each drive 2011_09_26_drive_<1000+i>_sync is a procedural street (façades with recesses and setbacks, "
    "sidewalks with curbs, parked and moving cars, poles, trees, hedges, open stretches) on gentle slopes, driven "
    "at KITTI-like speeds (0.5–1.5 m per frame). It is seen by camera 2 with the real 2011-09-26 calibration "
    "(1242 × 375 RGB), a simulated 64-beam Velodyne 1.73 m above the road (.bin scans) and OXTS packets whose poses "
    "match the true trajectory.\n\n"
    "proj_depth/velodyne_raw is the scan projected into camera 2 (with KITTI's see-through errors); "
    "proj_depth/groundtruth accumulates the scans of ±5 frames, kept where they agree with the view. "
    "Read the result with `dcslam prepare-kitti`. About a second per frame on two cores.\n\n"
    "--indoor writes indoor sequences instead, in the ICL-NUIM TUM-compatible layout (default out "
    "<workspace>/tum): living_room_traj<i>_frei_png/ with rgb/<k>.png, depth/<k>.png (16-bit, 5000 = 1 m), "
    "associations.txt, livingRoom<i>.gt.freiburg and intrinsics.txt. A furnished room (walls, floor, ceiling, "
    "shelves with books, sideboards, sofas, tables and chairs, plants, pictures, a door, a window) seen by "
    "ICL-NUIM's 640 × 480 camera (fx 481.2, fy −480: its y axis points up) along a smooth hand-held path (at most "
    "3 cm and about 1° per frame). --drives is then the number of sequences, --scale resizes the images. Read the "
    "result with `dcslam prepare-tum`."
)


def report(result: synth.SynthResult) -> None:
    for note in result.notes:
        typer.echo(f"note: {note}", err=True)
    if result.indoor:
        sequences = result.reports
        n = sum(s.frames for s in sequences)
        seconds = sum(s.seconds for s in sequences)
        density = sum(s.depth_density for s in sequences) / len(sequences)
        summary(f"wrote {len(sequences)} indoor sequence(s) ({n} frames, {seconds / max(n, 1):.2f} s/frame, "
                f"depth on {100 * density:.1f} % of pixels) to {result.root}")
        return
    reports = result.reports
    total_frames = sum(r.frames for r in reports)
    seconds = sum(r.seconds for r in reports)
    depth = [r for r in reports if r.depth_frames]
    densities = (f"; sparse {100 * sum(r.sparse_density for r in depth) / len(depth):.1f} %, ground truth "
                 f"{100 * sum(r.groundtruth_density for r in depth) / len(depth):.1f} % of pixels") if depth else ""
    summary(f"wrote {len(reports)} drives ({total_frames} frames, {seconds / max(total_frames, 1):.2f} s/frame) "
            f"to {result.root}{densities}")


synth_command = stage_command(app, "synth", synth.SynthConfig, synth.run, report, help=HELP,
                              examples=("dcslam synth --drives 6 --frames 60 --seed 0",
                                        "dcslam synth --indoor --drives 1 --frames 60 -w indoor"))
