"""`dcslam slam`: dense SLAM over drive files, writing a TUM trajectory, a PLY map and a JSON summary per drive."""
from __future__ import annotations

from enum import Enum
from pathlib import Path
from typing import Annotated, Optional

import typer

from dcslam.cli.app import ForceOption, WorkspaceOption, app, known_errors, summary


class OdometryChoice(str, Enum):
    gt = "gt"
    icp = "icp"
    gradicp = "gradicp"


class MapperChoice(str, Enum):
    pointfusion = "pointfusion"
    icpslam = "icpslam"


class SolverChoice(str, Enum):
    gn = "gn"
    lm = "lm"


class AssociationChoice(str, Enum):
    projective = "projective"
    nn = "nn"


def _resolve_depth(depth: str, ws, drive_name: str, run: str | None) -> tuple[str | Path, str]:
    """(depth source for load_depth, output layer name)."""
    from dcslam.errors import DcslamError
    from dcslam.io.drive import DEPTH_KINDS

    if depth in DEPTH_KINDS:
        return depth, depth
    if depth in ("predicted", "filtered"):
        root = ws.predictions if depth == "predicted" else ws.filtered
        maker = "dcslam predict" if depth == "predicted" else "dcslam filter"
        if run is None:
            runs = sorted((p for p in root.glob("*") if p.is_dir() and any(p.glob("*.h5"))),
                          key=lambda p: p.stat().st_mtime) if root.exists() else []
            if not runs:
                raise DcslamError(f"no layers in {root}; run `{maker}` first")
            run = runs[-1].name
        path = root / run / f"{drive_name}.h5"
        if not path.exists():
            raise DcslamError(f"{path} not found; run `{maker}` first")
        return path, run
    path = Path(depth)
    if not path.exists():
        raise DcslamError(f"depth layer {path} not found (--depth takes sparse, dense, predicted or a layer file)")
    return path, path.stem


@app.command("slam", help="Dense SLAM over drive files (all test drives by default): writes per drive a TUM "
                          "trajectory, a PLY map and a JSON summary under slam/<layer>/.")
@known_errors
def slam_command(
    depth: Annotated[str, typer.Option(help="Depth input: sparse, dense, predicted (a `dcslam predict` layer), "
                                            "filtered (a `dcslam filter` layer) or a layer file path.")] = "dense",
    drive: Annotated[Optional[list[str]], typer.Option(
        help="Drive name (in drives/) or .h5 path; repeatable. Default: the test drives of splits.json.")] = None,
    odometry: Annotated[OdometryChoice, typer.Option(help="gt: drive poses; icp: point-to-plane ICP; gradicp: "
                                                          "ICP with the differentiable LM.")] = OdometryChoice.icp,
    mapper: Annotated[MapperChoice, typer.Option(help="pointfusion or icpslam.")] = MapperChoice.pointfusion,
    solver: Annotated[SolverChoice, typer.Option(help="ICP solver: gn (Gauss-Newton) or lm.")] = SolverChoice.gn,
    association: Annotated[AssociationChoice, typer.Option(
        help="ICP association: projective or nn (KD-tree).")] = AssociationChoice.projective,
    frames: Annotated[int, typer.Option(help="First N frames of each drive (0 = all; the thesis scored 30).",
                                        min=0)] = 0,
    max_distance: Annotated[float, typer.Option(help="ICP outlier gate, metres.", min=0.0)] = 0.5,
    max_normal_angle: Annotated[float, typer.Option(help="ICP normal-angle gate, degrees.", min=0.0)] = 30.0,
    iterations: Annotated[int, typer.Option(help="ICP iterations per gate stage.", min=1)] = 20,
    voxel_size: Annotated[float, typer.Option(help="Map voxel size, metres.", min=0.0)] = 0.05,
    run: Annotated[Optional[str], typer.Option(help="Prediction run (or filter name) for --depth predicted "
                                                    "(filtered); default: the most recent.")] = None,
    out: Annotated[Optional[Path], typer.Option(help="Output folder (default: slam/<layer>/).")] = None,
    device: Annotated[str, typer.Option(help="torch device, e.g. cpu or cuda.")] = "cpu",
    workspace: WorkspaceOption = None,
    force: ForceOption = False,
) -> None:
    from dcslam.io.drive import read_splits
    from dcslam.slam.config import SlamSettings, build_slam
    from dcslam.slam.run import check_outputs, run_drive, write_outputs
    from dcslam.workspace import Workspace, require

    ws = Workspace.resolve(workspace)
    if drive:
        paths = [Path(d) if d.endswith(".h5") else ws.drives / f"{d}.h5" for d in drive]
    else:
        paths = [ws.drives / f"{name}.h5" for name in read_splits(ws.splits)["test"]]
    for path in paths:
        require(path, "dcslam prepare-kitti")
    settings = dict(depth=depth, odometry=odometry.value, mapper=mapper.value, solver=solver.value,
                    association=association.value, frames=frames, max_distance=max_distance,
                    max_normal_angle=max_normal_angle, iterations=iterations, voxel_size=voxel_size, device=device)
    slam_settings = SlamSettings(odometry=odometry.value, mapper=mapper.value, solver=solver.value,
                                 association=association.value, max_distance=max_distance,
                                 max_normal_angle=max_normal_angle, iterations=iterations, voxel_size=voxel_size)
    jobs = []
    for path in paths:
        source, layer = _resolve_depth(depth, ws, path.stem, run)
        out_dir = out if out is not None else ws.slam / layer
        check_outputs(out_dir, path.stem, force)
        jobs.append((path, source, out_dir))
    for path, source, out_dir in jobs:
        slam = build_slam(slam_settings)
        result = run_drive(path, source, slam, frames or None, device, settings={**settings, "source": str(source)})
        result.name = path.stem
        written = write_outputs(result, out_dir, force)
        s = result.summary()
        summary(f"{path.stem}: {s['frames']} frames, {s['points']} points, {s['seconds_per_frame']:.2f} s/frame, "
                f"final drift {s['translation_error_m']['final']:.3f} m, {len(s['rejected_steps'])} rejected "
                f"-> {written['trajectory'].parent}")
