"""`dcslam synth`: generate KITTI-format drives from procedural street scenes."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from dcslam.cli.app import ForceOption, WorkspaceOption, app, known_errors, summary


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


@app.command("synth", help=HELP)
@known_errors
def synth_command(
    workspace: WorkspaceOption = None,
    out: Annotated[Optional[Path], typer.Option(
        "--out", "-o", help="KITTI root to write into (raw/ and depth_completion/); with --indoor, the folder of "
                            "the sequences.", show_default="<workspace>/kitti, with --indoor <workspace>/tum")] = None,
    drives: Annotated[int, typer.Option("--drives", "-n", min=1,
                                        help="Number of drives (with --indoor: sequences) to generate.")] = 6,
    frames: Annotated[int, typer.Option(
        "--frames", "-f", min=1,
        help="Raw frames per drive (10 Hz). Like KITTI, only frames 5 … N−6 get depth maps, so N ≥ 11.")] = 60,
    seed: Annotated[int, typer.Option("--seed", "-s", help="Random seed; each drive's scene and path follow "
                                                            "from (seed, drive index).")] = 0,
    azimuth_step: Annotated[float, typer.Option(
        "--lidar-azimuth-step", help="LiDAR azimuth step in degrees across the 64 beams (each laser fires every "
                                     "second step, as the HDL-64E).")] = 0.08,
    indoor: Annotated[bool, typer.Option(
        "--indoor", help="Write indoor sequences in the ICL-NUIM layout instead of KITTI drives.")] = False,
    scale: Annotated[float, typer.Option(
        "--scale", min=0.05, max=4.0, help="With --indoor: image size as a fraction of 640 × 480 (intrinsics "
                                           "scaled to match).")] = 1.0,
    force: ForceOption = False,
) -> None:
    from dcslam.progress import Bar
    from dcslam.workspace import Workspace

    if indoor:
        from dcslam.synth.indoor import generate_indoor

        root = out if out is not None else Workspace.resolve(workspace).root / "tum"
        with Bar("synth --indoor", total=drives * frames) as bar:
            result = generate_indoor(root, sequences=drives, frames=frames, seed=seed, force=force,
                                     on_frame=bar.advance, scale=scale)
        n = sum(s.frames for s in result.sequences)
        seconds = sum(s.seconds for s in result.sequences)
        density = sum(s.depth_density for s in result.sequences) / len(result.sequences)
        summary(f"wrote {len(result.sequences)} indoor sequence(s) ({n} frames, {seconds / max(n, 1):.2f} s/frame, "
                f"depth on {100 * density:.1f} % of pixels) to {root}")
        return
    from dcslam.synth import generate

    root = out if out is not None else Workspace.resolve(workspace).kitti
    if frames < 11:
        typer.echo(f"note: with --frames {frames} < 11 no frame gets depth maps (KITTI skips 5 at each end)",
                   err=True)
    with Bar("synth", total=drives * frames) as bar:
        reports = generate(root, drives=drives, frames=frames, seed=seed, force=force,
                           lidar_azimuth_step_deg=azimuth_step, on_frame=bar.advance)
    total_frames = sum(r.frames for r in reports)
    seconds = sum(r.seconds for r in reports)
    depth = [r for r in reports if r.depth_frames]
    densities = (f"; sparse {100 * sum(r.sparse_density for r in depth) / len(depth):.1f} %, ground truth "
                 f"{100 * sum(r.groundtruth_density for r in depth) / len(depth):.1f} % of pixels") if depth else ""
    summary(f"wrote {len(reports)} drives ({total_frames} frames, {seconds / max(total_frames, 1):.2f} s/frame) "
            f"to {root}{densities}")
