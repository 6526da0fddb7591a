import json

import numpy as np
import torch

from dcslam.io.drive import DriveFrame, DriveWriter
from dcslam.slam.config import SlamSettings, build_slam
from dcslam.slam.scene import kitti_K, lidar_mask, street_trajectory, StreetScene
from dcslam.stages.slam import run_drive_file, write_outputs
from tests.fixtures.street import write_analytic_street

H, W, N = 48, 160, 4


def _write_drive(path, frames=N):
    return write_analytic_street(path, frames, H, W)


def test_prefetched_frames_give_the_poses_of_a_plain_loop(tmp_path, monkeypatch):
    """run_drive_file prepares the next frame on a second thread: the poses, the map and the step reports are those of
    SLAM.step over the same frames, bit for bit."""
    from dcslam.io.drive import DriveFile, load_depth
    from dcslam.slam import drive as slam_drive
    from dcslam.workers import SHARED_CORES

    monkeypatch.delenv(SHARED_CORES, raising=False)  # as a command run on its own: with the prefetch thread
    threads = []
    prefetcher = slam_drive.prefetcher
    monkeypatch.setattr(slam_drive, "prefetcher", lambda enabled: threads.append(enabled) or prefetcher(enabled))

    path = tmp_path / "street.h5"
    K, poses = _write_drive(path, frames=5)
    for depth in ("sparse", "dense"):
        run = run_drive_file(path, depth, build_slam(SlamSettings()))
        slam = build_slam(SlamSettings())
        slam.T_world_cam0 = poses[0].float()
        slam.reset()
        with DriveFile(path) as drive:
            frames = load_depth(drive, depth)
            for i in range(len(drive)):
                rgb = torch.from_numpy(drive.rgb(i)).permute(2, 0, 1)[None].float() / 255
                slam.step(torch.from_numpy(np.ascontiguousarray(frames[i]))[None, None], K.float(), rgb,
                          torch.from_numpy(drive.poses[i]).float())
        expected = slam.trajectory().double().numpy()
        assert len(run.reports) == 5
        assert np.array_equal(run.T_world_cam[:, :3, 3], expected[:, :3, 3]), depth
        assert [r.iterations for r in run.reports] == [r.iterations for r in slam.reports]
        assert len(run.map) == len(slam.mapper.global_map())
    assert threads == [True, True]


def test_a_run_without_colour_has_the_poses_and_geometry_of_one_with_it(tmp_path):
    """The companion runs without colour images: its poses, steps and map geometry are those of the run with them,
    bit for bit; only the map's colours differ (grey)."""
    from dcslam.stages.slam import SlamStageConfig, companion_run

    path = tmp_path / "street.h5"
    _write_drive(path, frames=5)
    for depth in ("sparse", "dense"):
        coloured = run_drive_file(path, depth, build_slam(SlamSettings()))
        grey = run_drive_file(path, depth, build_slam(SlamSettings()), colour=False)
        assert np.array_equal(coloured.T_world_cam, grey.T_world_cam), depth
        assert [r.iterations for r in coloured.reports] == [r.iterations for r in grey.reports]
        assert torch.equal(coloured.map.points, grey.map.points) and torch.equal(coloured.map.normals, grey.map.normals)
        assert torch.all(grey.map.colors == 0.5) and not torch.all(coloured.map.colors == 0.5)
    companion = companion_run(path, "sparse", SlamStageConfig(), 1, "companion", progress=True)
    assert companion.map is None
    assert np.array_equal(companion.T_world_cam, run_drive_file(path, "sparse", build_slam(SlamSettings())).T_world_cam)


def test_prefetch_errors_reach_the_caller():
    import threading

    import pytest

    from dcslam.errors import DcslamError
    from dcslam.slam.drive import prefetcher

    def fail():
        raise DcslamError("frame 3 unreadable")

    for enabled in (True, False):
        with prefetcher(enabled) as submit:
            with pytest.raises(DcslamError, match="frame 3"):
                submit(fail).result()
            assert submit(torch.get_num_threads).result() == torch.get_num_threads()
            on_caller = submit(threading.current_thread).result() is threading.current_thread()
            assert on_caller is not enabled


def test_pool_workers_do_not_prefetch(monkeypatch):
    """Workers of a pool of several processes share the cores: no second thread there (one worker: as usual)."""
    from dcslam.workers import SHARED_CORES, cores_shared, one_thread

    for name in (SHARED_CORES, "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        monkeypatch.delenv(name, raising=False)
    threads = torch.get_num_threads()
    try:
        one_thread(False)
        assert not cores_shared()
        one_thread(True)
        assert cores_shared()
    finally:
        torch.set_num_threads(threads)


def test_summary_carries_health_and_the_whole_map(tmp_path):
    scene, K = StreetScene(1), kitti_K(H, W)
    poses = street_trajectory(N, step=0.5)
    path = tmp_path / "street.h5"
    with DriveWriter(path, K.double().numpy(), H, W, source="synthetic", date="2011_09_26", drive="street",
                     split="test") as writer:
        for i in range(N):
            dense = scene.render(poses[i], K, H, W).float().numpy()
            writer.append(DriveFrame(np.zeros((H, W, 3), np.uint8), dense * lidar_mask(H, W).numpy(), dense,
                                poses[i].numpy(), 0.1 * i, i))
    slam = build_slam(SlamSettings(local_map_frames=1))
    run = run_drive_file(path, "dense", slam)
    assert len(run.map) > len(slam.map)                      # archived points are in the written map
    summary = run.summary()
    health = summary["health"]
    assert set(health) >= {"accepted", "degraded", "rejected", "suspect", "reasons", "flagged_steps"}
    assert health["accepted"] + health["degraded"] + health["rejected"] == N - 1
    written = write_outputs(run, tmp_path / "out")
    assert json.loads(written["summary"].read_text())["health"] == json.loads(json.dumps(health))
    assert torch.isfinite(torch.from_numpy(run.T_world_cam)).all()


def test_float32_drift_off_so3_is_projected_before_writing(tmp_path):
    """A trajectory whose rotations left SO(3) by 1e-4 (float32 composition over a drive) is written as the nearest
    rotations: the KITTI pose file, which checks orthonormality, accepts it."""
    from dcslam.io.kitti_poses import read_kitti_poses
    from dcslam.slam.pointmap import PointMap
    from dcslam.slam.drive import DriveRun

    T = street_trajectory(N, step=0.5).double().numpy()
    T[-1, :3, :3] *= 1.0001
    run = DriveRun("drifted", T, 0.1 * np.arange(N), T.copy(), PointMap.empty(), [], 1.0)
    written = write_outputs(run, tmp_path)
    back = read_kitti_poses(written["kitti_poses"])
    assert np.abs(back - street_trajectory(N, step=0.5).double().numpy()).max() < 1e-6


def test_non_increasing_timestamps_fail_before_anything_is_written(tmp_path):
    """Time association pairs a trajectory with its reference by timestamp: a drive whose stamps repeat or go back
    is an error naming the frame, not a trajectory silently restamped at 10 Hz."""
    import pytest

    from dcslam.errors import DcslamError
    from dcslam.slam.pointmap import PointMap
    from dcslam.slam.drive import DriveRun, check_timestamps

    T = street_trajectory(N, step=0.5).double().numpy()
    stamps = np.array([0.0, 0.1, 0.1, 0.3])
    run = DriveRun("repeated", T, stamps, T.copy(), PointMap.empty(), [], 1.0)
    with pytest.raises(DcslamError, match=r"repeated: timestamps are not strictly increasing \(frame 2 at 0.100000"):
        write_outputs(run, tmp_path / "out")
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())
    with pytest.raises(DcslamError, match="frame 1 is not finite"):
        check_timestamps(np.array([0.0, np.nan]), "x")
    assert check_timestamps(np.array([1, 2, 5]), "x").dtype == np.float64  # increasing stamps kept as they are

    path = tmp_path / "backwards.h5"
    K = kitti_K(H, W)
    with DriveWriter(path, K.double().numpy(), H, W, source="synthetic", date="2011_09_26", drive="backwards",
                     split="test") as writer:
        for i, t in enumerate([0.2, 0.1, 0.3]):
            writer.append(DriveFrame(np.zeros((H, W, 3), np.uint8), np.zeros((H, W), np.float32),
                                     np.ones((H, W), np.float32), T[i], t, i))
    with pytest.raises(DcslamError, match="backwards.h5: timestamps are not strictly increasing"):
        run_drive_file(path, "dense", build_slam(SlamSettings()))


def test_real_timestamps_are_written_to_the_tum_file(tmp_path):
    from dcslam.io.tum import read_tum
    from dcslam.slam.pointmap import PointMap
    from dcslam.slam.drive import DriveRun

    T = street_trajectory(N, step=0.5).double().numpy()
    stamps = 1317000000.0 + np.array([0.0, 0.103, 0.207, 0.31])  # KITTI-like: not exactly 10 Hz
    written = write_outputs(DriveRun("real", T, stamps, T.copy(), PointMap.empty(), [], 1.0), tmp_path)
    assert np.allclose(read_tum(written["trajectory"])[0], stamps, atol=1e-6, rtol=0)
