"""Real KITTI from a path: the chain of examples/generated_end_to_end.py on KITTI raw + depth-completion folders.

    prepare-kitti --kitti PATH → train one recipe (IP-Basic when the split has no training drive) → predict
        → slam on sparse, dense and predicted depth (drives of 2+ frames) → score depth and trajectory → table

PATH holds raw/<date>/calib_*.txt, raw/<date>/<drive>/{image_02,oxts}/ and
depth_completion/{train,val}/<drive>/proj_depth/{velodyne_raw,groundtruth}/image_02/; prepare-kitti keeps the drives
of the thesis's split unless --splits names others. A folder without one complete drive, such as the one-frame
sample in tests/data/kitti-sample/, can neither be prepared nor give a trajectory: the script then completes each
depth-benchmark frame it finds with IP-Basic, scores it against the annotated depth, and says so.

Usage:
    python examples/real_kitti.py --kitti /data/kitti --max-drive-frames 50
    python examples/real_kitti.py --kitti /data/kitti --splits my_splits.json --recipe chamfer-8 --workspace /tmp/ws
    python examples/real_kitti.py --kitti tests/data/kitti-sample --workspace /tmp/ws-sample   # depth scores only
"""
import argparse
import sys
from pathlib import Path

from generated_end_to_end import RECIPES, complete_slam_score, dcslam, options  # same folder

from dcslam.depth.predict import ip_basic_predictor
from dcslam.errors import DcslamError
from dcslam.eval.depth import depth_errors, mean_errors
from dcslam.report.tables import Column, Table
from dcslam.io.drive import DriveFile, read_splits
from dcslam.io.kitti import find_drives, index_drive, read_depth_png
from dcslam.io.atomic import write_text_atomic


def complete_frames_only(a, reason: str) -> None:
    """IP-Basic on every depth-benchmark frame under ``a.kitti``, scored like `dcslam score depth`."""
    print(f"no complete drive under {a.kitti} ({reason}):\nno drive files and no SLAM (a trajectory needs 2+ "
          "frames); IP-Basic on each depth-benchmark frame instead, scored against the annotated depth\n")
    out = a.workspace / "results" / "kitti_frames_ip-basic-fast.csv"
    if out.exists() and not a.force:
        sys.exit(f"error: {out} exists; pass --force to overwrite it")
    complete = ip_basic_predictor("ip-basic-fast").completer
    table = Table("IP-Basic (fast) on the KITTI depth frames", [Column("frame", "frame")] + [
        Column(k, h, "{:.2f}") for k, h in (("mae_mm", "MAE (mm)"), ("rmse_mm", "RMSE (mm)"),
                                            ("imae_per_km", "iMAE (1/km)"), ("irmse_per_km", "iRMSE (1/km)"))])
    scored = {}
    for drive in (d for d in find_drives(a.kitti) if d.depth_dir is not None):
        for sparse in sorted((drive.depth_dir / "proj_depth" / "velodyne_raw" / "image_02").glob("*.png")):
            gt = drive.depth_path("groundtruth", int(sparse.stem))
            if gt.exists():
                pred = complete(read_depth_png(sparse))
                scored[f"{drive.name}/{sparse.stem}"] = depth_errors(pred, read_depth_png(gt))
    if not scored:
        sys.exit(f"stopped: no velodyne_raw + groundtruth frame under {a.kitti}/depth_completion")
    scored["mean"] = mean_errors(scored.values())
    table.rows = [{"frame": frame, **errors.as_dict()} for frame, errors in scored.items()]
    write_text_atomic(out, table.to_csv(), force=True)
    print(table.to_markdown())


def main() -> None:
    parser = options(argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter))
    parser.add_argument("--kitti", type=Path, required=True, help="KITTI root (raw/ and depth_completion/)")
    parser.add_argument("--splits", type=Path, help="a splits.json-style file (default: the thesis's split)")
    parser.add_argument("--max-drive-frames", type=int, help="keep at most this many frames per drive")
    a = parser.parse_args()
    reasons = []
    for drive in (d for d in find_drives(a.kitti) if d.has_raw and d.depth_dir is not None):
        try:
            index_drive(drive)  # what prepare-kitti checks: images, OXTS and timestamps of every frame
        except DcslamError as exc:
            reasons.append(str(exc))
        else:
            break
    else:
        return complete_frames_only(a, reasons[0] if reasons else "no raw + depth_completion drive folders")

    extra = (["--splits", a.splits] if a.splits else []) + (["--max-frames", a.max_drive_frames]
                                                           if a.max_drive_frames else [])
    dcslam(a, "prepare-kitti", "--kitti", a.kitti.resolve(), *extra)
    splits = read_splits(a.workspace / "drives" / "splits.json")
    if a.recipe in RECIPES and not splits["train"]:
        print(f"\nno training drive in the split: IP-Basic instead of training {a.recipe}")
        a.recipe = "ip-basic-fast"
    frames = []
    for name in splits["test"]:
        with DriveFile(a.workspace / "drives" / f"{name}.h5") as drive:
            frames.append(len(drive))
    if min(frames, default=0) < 2:
        print(f"\ntest drives of {frames} frame(s): too few for SLAM, depth scores only")
    complete_slam_score(a, slam=min(frames, default=0) >= 2)


if __name__ == "__main__":
    main()
