"""One depth completer through SLAM with each depth filter: localisation accuracy and depth scores per filter.

    test drives → IP-Basic (default) or a trained run → each filter → SLAM (PointFusion + ICP) → scores

Written against the library, so that your own filter, completer or SLAM parts can be swapped in. Needs drive files
(`dcslam synth && dcslam prepare-kitti`, or examples/generated_end_to_end.py); writes predictions/<model>/,
filtered/<model>+<filter>/, slam/<layer>/ and results/filters_<model>.{csv,md} in the workspace.

Usage:
    python examples/filters_through_slam.py --workspace workspace-example
    python examples/filters_through_slam.py --model mse-dense --frames 30 --filter edges --filter thesis-range+edges
"""
import argparse
from pathlib import Path

from dcslam.depth.models import classical_name
from dcslam.depth.predict import classical_predictor
from dcslam.stages.predict import predict_drive, run_predictor
from dcslam.errors import DcslamError
from dcslam.eval.depth import mean_errors, score_drive
from dcslam.report.tables import Column, Table
from dcslam.eval.trajectory import score_trajectory
from dcslam.filters import FilterChain, filter_drives, parse_filter
from dcslam.io.drive import read_splits
from dcslam.io.drive_frames import drive_frames
from dcslam.slam.drive import run_drive
from dcslam.slam.fusion import PointFusion
from dcslam.slam.odometry import ICPOdometry
from dcslam.slam.pipeline import SLAM
from dcslam.stages.slam import write_outputs
from dcslam.io.atomic import write_text_atomic
from dcslam.workspace import Workspace, require

FILTERS = ["range:min=1,max=60", "bilateral:sigma_color=2", "outlier", "hidden", "edges", "thesis-range",
           "thesis-bilateral"]


def chain_of(spec: str) -> FilterChain:
    """The command line's filter syntax (NAME, NAME:key=value,... or a preset), chained with +."""
    return FilterChain(tuple(parse_filter(part) for part in spec.split("+")))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--workspace", type=Path, default=Path("workspace-example"))
    parser.add_argument("--model", default="ip-basic-fast", help="ip-basic-fast, ip-basic-multiscale or a run name")
    parser.add_argument("--filter", action="append", dest="filters", metavar="SPEC", help="as `dcslam filter "
                        "--filter`, chained with + (repeatable; default: each filter and preset once)")
    parser.add_argument("--frames", type=int, default=0, help="frames of each test drive fed to SLAM (0 = all)")
    parser.add_argument("--icp-iterations", type=int, default=20, help="ICP iterations per gate stage")
    parser.add_argument("--force", action="store_true", help="overwrite what an earlier run wrote")
    a = parser.parse_args()
    ws = Workspace.resolve(a.workspace)
    chains = {spec: chain_of(spec) for spec in a.filters or FILTERS}
    drives = [require(ws.drives / f"{d}.h5", "dcslam prepare-kitti") for d in read_splits(ws.splits)["test"]]
    # one output name per spec, e.g. filtered/ip-basic-fast+range-min1-max60/ (`dcslam filter` names by filter kind,
    # <model>+range, which would put range:min=1,max=60 and thesis-range in the same folder)
    names = {spec: f"{a.model}+" + spec.replace(":", "-").replace(",", "-").replace("=", "") for spec in chains}
    layers = {"(none)": {d.stem: ws.predictions / a.model / d.name for d in drives}}  # filter → {drive: layer file}
    layers.update({spec: {d.stem: ws.filtered / name / d.name for d in drives} for spec, name in names.items()})
    outputs = [ws.results / f"filters_{a.model}.{ext}" for ext in ("csv", "md")] + [
        ws.slam / p.parent.name / f"{p.stem}.{ext}" for paths in layers.values() for p in paths.values()
        for ext in ("txt", "ply", "json")] + [p for spec in chains for p in layers[spec].values()]
    if not a.force and any(p.exists() for p in outputs):  # fail before any work, as the dcslam commands do
        raise DcslamError(f"{next(p for p in outputs if p.exists())} exists; pass --force to overwrite it")

    # 1. the completer's layers (a trained run is loaded with the scale it trained at), then each filter chain's
    predicted = layers["(none)"]
    predictor = classical_predictor(a.model) if classical_name(a.model) else run_predictor(
        require(ws.runs / a.model, "dcslam train"), "cpu")
    for drive in drives:
        if a.force or not predicted[drive.stem].exists():  # else reuse what `dcslam predict` wrote
            predict_drive(predictor, drive, predicted[drive.stem], force=a.force)
    for spec, chain in chains.items():
        filter_drives([(d, predicted[d.stem], layers[spec][d.stem]) for d in drives], chain, made_by=names[spec],
                      settings={"source_layer": a.model}, force=a.force)

    # 2. the same SLAM on every layer, a fresh map per drive; depth scores over all frames of the test drives
    table = Table(f"{a.model} through SLAM with each filter", [Column("filter", "filter")] + [
        Column(key, header, fmt) for key, header, fmt in (
            ("localisation", "localisation", "{:.4f}"), ("ate_rmse", "ATE RMSE (m)", "{:.3f}"),
            ("mae_mm", "MAE (mm)", "{:.1f}"), ("rmse_mm", "RMSE (mm)", "{:.1f}"),
            ("irmse_per_km", "iRMSE (1/km)", "{:.2f}"), ("coverage", "coverage", "{:.3f}"))])
    for spec, paths in layers.items():
        scores = []
        for drive in drives:
            slam = SLAM(ICPOdometry(iterations=a.icp_iterations), PointFusion())
            with drive_frames(drive, paths[drive.stem], a.frames or None) as frames:  # read as SLAM uses them
                run = run_drive(frames, slam)
            write_outputs(run, ws.slam / paths[drive.stem].parent.name, force=a.force)
            scores.append(score_trajectory(run.T_gt, run.T_world_cam))
        depth = mean_errors(e for d in drives for e in score_drive(d, paths[d.stem]))
        table.rows.append({"filter": spec, "localisation": sum(s.localisation for s in scores) / len(scores),
                           "ate_rmse": sum(s.ate.rmse for s in scores) / len(scores), **depth.as_dict()})
    table.notes.append("localisation: the thesis's accuracy (m + rad, lower is better) and ATE (unaligned), means "
                       "over the test drives; depth: KITTI devkit errors, coverage = share of ground truth scored")
    for ext, text in (("csv", table.to_csv()), ("md", table.to_markdown())):
        write_text_atomic(ws.results / f"filters_{a.model}.{ext}", text, force=a.force)
    print(table.to_markdown())


if __name__ == "__main__":
    try:
        main()
    except DcslamError as exc:
        raise SystemExit(f"error: {exc}") from None
