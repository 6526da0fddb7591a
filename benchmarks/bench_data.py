"""Data-layer speed: `dcslam synth` and `dcslam prepare-kitti` frames per second, side by side.

Run: ``python benchmarks/bench_data.py [--quick] [--drives N] [--frames N]``.

1. synth: full-size KITTI frames (1242 × 375 camera render, 144k-shot LiDAR scan, ±5-frame ground-truth
   accumulation, PNG / .bin / OXTS files), seconds per raw frame, and the time of each part on one frame.
2. prepare-kitti on the generated drives: frames per second into HDF5 drive files, and the largest pose error of
   the poses it read back from OXTS against the generator's truth.
3. reading one drive file's frames back: CPU per frame of h5py's ``dataset[i]`` beside dcslam's chunk reader.
Figures depend on the machine and on what else runs on it: read them next to the machine line.
"""
from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one drive of 11 frames")
    parser.add_argument("--drives", type=int, default=2)
    parser.add_argument("--frames", type=int, default=16)
    args, _ = parser.parse_known_args()
    drives, frames = (1, 11) if args.quick else (args.drives, args.frames)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
          f"{drives} drive(s) of {frames} frames", flush=True)

    from dcslam.synth import generate, make_drive
    from dcslam.synth.raycast import CameraGrid
    from dcslam.synth.street.generate import street_calibration
    from dcslam.synth.street.sensors import GroundTexture, make_lidar_grid, render_camera, scan_lidar

    rig = street_calibration()
    truth, rng = make_drive(0, 0, 11, rig)
    scene, t = truth.scene, float(truth.timestamps[5] - truth.timestamps[0])
    camera, lidar, ground = CameraGrid(rig.K_cam2, *rig.size_rect_02), make_lidar_grid(), GroundTexture(scene)
    T_world_cam = truth.T_world_imu[5] @ np.linalg.inv(rig.T_cam2_imu)
    T_world_velo = scene.drive.T_world_velo(np.array([t]))[0]
    start = time.perf_counter()
    render_camera(scene, ground, camera, T_world_cam, t, rng)
    camera_s = time.perf_counter() - start
    start = time.perf_counter()
    points = scan_lidar(scene, lidar, T_world_velo, t, rng)
    lidar_s = time.perf_counter() - start
    print(f"one frame: camera render {camera_s:.2f} s, LiDAR scan {lidar_s:.2f} s ({len(points)} points)")

    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "kitti"
        start = time.perf_counter()
        reports = generate(root, drives=drives, frames=frames, seed=0)
        synth_s = time.perf_counter() - start
        n = sum(r.frames for r in reports)
        depth = [r for r in reports if r.depth_frames]
        print(f"synth:         {n / synth_s:6.2f} frames/s  ({synth_s / n:.2f} s per full-size frame with its scan, "
              f"ground truth and files)")
        if depth:
            print(f"               densities: sparse {100 * np.mean([r.sparse_density for r in depth]):.1f} %, "
                  f"ground truth {100 * np.mean([r.groundtruth_density for r in depth]):.1f} % "
                  f"(real KITTI 0001/5: 4.1 %, 19.5 %)")
        try:
            from dcslam.stages.prepare import prepare_kitti
        except ImportError:
            print("prepare-kitti: not available")
            return
        start = time.perf_counter()
        result = prepare_kitti(root, Path(tmp) / "drives", include_unsplit=True)
        prepare_s = time.perf_counter() - start
        m = sum(d.frames for d in result.drives)
        print(f"prepare-kitti: {m / prepare_s:6.2f} frames/s  ({m} frames with depth into HDF5)")
        import h5py

        worst_t, worst_r = 0.0, 0.0
        for d in result.drives:
            index = int(d.name[17:21]) - 1000
            truth, _ = make_drive(0, index, frames, rig)
            with h5py.File(d.path, "r") as f:
                T_read, ids = f["T_world_cam"][:], f["frame_ids"][:]
            # the drive file's world is camera 2 at its first frame
            T_true = np.linalg.inv(truth.T_world_cam2[ids[0]]) @ truth.T_world_cam2[ids]
            worst_t = max(worst_t, float(np.abs(T_read[:, :3, 3] - T_true[:, :3, 3]).max()))
            R = np.transpose(T_read[:, :3, :3], (0, 2, 1)) @ T_true[:, :3, :3]
            worst_r = max(worst_r, float(np.arccos(np.clip((np.trace(R, axis1=1, axis2=2) - 1) / 2, -1, 1)).max()))
        print(f"               poses read back vs truth: {worst_t * 1000:.4f} mm, {worst_r:.2e} rad at most")
        read_frames(result.drives[0].path)


def read_frames(path: Path, repeats: int = 3) -> None:
    """CPU per frame of reading a drive file's frames once each, as SLAM reads them: h5py's ``dataset[i]`` beside
    dcslam's chunk reader (:class:`dcslam.io.chunks.FrameReader`, ISA-L's inflate), the same arrays."""
    import h5py

    from dcslam.io.chunks import FrameReader

    for name in ("rgb", "depth/sparse", "depth/dense"):
        (h5py_ms, n, _), (ours_ms, _, fast) = (_read_ms(path, name, ours, repeats) for ours in (False, True))
        with h5py.File(path, "r") as f:
            assert all(np.array_equal(FrameReader(f[name])(i), f[name][i]) for i in range(n))
        print(f"read {name:12s} h5py {h5py_ms:5.2f} ms/frame, dcslam {ours_ms:5.2f} ({h5py_ms / ours_ms:.1f} x; "
              f"{'chunk' if fast else 'h5py'} path; {n} frames)")


def _read_ms(path: Path, name: str, ours: bool, repeats: int) -> tuple[float, int, bool]:
    """(best CPU ms per frame over ``repeats`` passes, frames, whether the chunk path read them) of reading dataset
    ``name`` by dcslam's reader (``ours``) or h5py's; each pass on the file opened anew (h5py keeps the last chunks
    it inflated)."""
    import h5py

    from dcslam.io.chunks import FrameReader

    best = np.inf
    for _ in range(repeats):
        with h5py.File(path, "r") as f:
            read = FrameReader(f[name]) if ours else f[name].__getitem__
            n, cpu = f[name].shape[0], time.process_time()
            for i in range(n):
                read(i)
            best = min(best, (time.process_time() - cpu) / n * 1e3)
    return best, n, ours and read.fast


if __name__ == "__main__":
    main()
