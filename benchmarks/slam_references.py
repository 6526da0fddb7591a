"""Reference odometries for the SLAM benchmark, run on the same generated drives as dcslam (not benchmarks
themselves: no ``bench_`` prefix).

- KISS-ICP (Vizzo et al., RA-L 2023; the optional extra ``bench``: ``pip install kiss-icp``) on the full 360 degree
  Velodyne ``.bin`` scans that ``dcslam synth`` writes under ``kitti/raw``, with its default configuration (deskew
  off: the generated scans are taken at one instant). Its Velodyne poses are moved into camera 2 with the drive's
  calibration, ``T_cam2_cam2' = T_cam2_velo T_velo_velo' T_velo_cam2``.
- Open3D's point-to-plane ``registration_icp`` frame to frame on the same back-projected depth images that dcslam
  aligns (normals from Open3D's KD-tree search), with a constant-velocity initial guess and a 1 m gate.

Both read their input frame by frame as they use it, and their times count that reading, as dcslam's do.
"""
from __future__ import annotations

import contextlib
import time
from pathlib import Path

import numpy as np

from slam_drives import DriveScore, score


def kiss_icp_available() -> bool:
    try:
        import kiss_icp  # noqa: F401
    except ImportError:
        return False
    return True


def run_kiss_icp(kitti_root: Path, drive_path: Path, frames: int | None = None, threads: int = 0) -> DriveScore:
    """KISS-ICP over the Velodyne scans of the frames of one prepared drive file; ``threads``: its registration's
    (0: its own choice, every core). The time counts reading the scans."""
    from kiss_icp.config import load_config
    from kiss_icp.kiss_icp import KissICP

    from dcslam.io.drive import DriveFile
    from dcslam.io.kitti import read_calibration, read_velodyne

    with DriveFile(drive_path) as drive:
        n = len(drive) if not frames else min(frames, len(drive))
        frame_ids, T_gt, name = np.asarray(drive.frame_ids[:n]), drive.poses[:n], drive.name
    date_dir = kitti_root / "raw" / name[:10]
    T_cam_velo = np.asarray(read_calibration(date_dir).T_cam2_velo)
    config = load_config(None)
    config.data.deskew = False
    config.registration.max_num_threads = threads
    odometry = KissICP(config)
    poses = []
    start, cpu_start = time.perf_counter(), time.process_time()
    for i in frame_ids:
        scan = read_velodyne(date_dir / name / "velodyne_points" / "data" / f"{int(i):010d}.bin")[:, :3]
        odometry.register_frame(scan.astype(np.float64), np.zeros(len(scan)))
        poses.append(odometry.last_pose.copy())
    seconds, cpu_seconds = time.perf_counter() - start, time.process_time() - cpu_start
    T_velo0_velo = np.stack(poses)
    T_est = T_gt[0] @ T_cam_velo @ T_velo0_velo @ np.linalg.inv(T_cam_velo)
    return score(name, "velodyne 360", T_gt, T_est, seconds, cpu_seconds=cpu_seconds)


def run_open3d(drive_path: Path, depth: str | Path, frames: int | None = None, gate: float = 1.0,
               iterations: int = 30) -> DriveScore:
    """Open3D point-to-plane ICP, frame to frame, on back-projected depth images of one drive file (``depth``: a
    depth kind of the drive or a layer file), each frame read as it is used; the time counts the reading."""
    import open3d as o3d

    from dcslam.io.drive import DriveFile
    from dcslam.io.drive_frames import layer_frames

    reg = o3d.pipelines.registration
    start, cpu_start = time.perf_counter(), time.process_time()
    with DriveFile(drive_path) as drive, contextlib.ExitStack() as stack:
        n = len(drive) if not frames else min(frames, len(drive))
        K, T_gt, name = np.asarray(drive.K), drive.poses[:n], drive.name
        if isinstance(depth, Path):
            depth_at = stack.enter_context(layer_frames(drive, depth))[0]
        else:
            depth_at = lambda i: drive.depth(depth, i)  # noqa: E731
        H, W = drive.shape[1:]
        v, u = np.mgrid[0:H, 0:W]
        rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones((H, W))], -1)
        poses, delta, previous = [T_gt[0]], np.eye(4), None
        for i in range(n):
            d = np.asarray(depth_at(i))
            ok = (d > 0.1) & (d < 80)
            cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(rays[ok] * d[ok][:, None]))
            cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=1.0, max_nn=20))
            if previous is not None:
                result = reg.registration_icp(cloud, previous, gate, delta,
                                              reg.TransformationEstimationPointToPlane(),
                                              reg.ICPConvergenceCriteria(1e-6, 1e-6, iterations))
                delta = np.asarray(result.transformation)          # T_prev_cur, also the next prediction
                poses.append(poses[-1] @ delta)
            previous = cloud
    seconds, cpu_seconds = time.perf_counter() - start, time.process_time() - cpu_start
    return score(name, f"{depth} (Open3D)", T_gt, np.stack(poses), seconds, cpu_seconds=cpu_seconds)
