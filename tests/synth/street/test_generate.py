"""A whole synthetic drive at full KITTI size: layout, file formats, densities, see-through errors, edges."""
import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.io.kitti import read_depth_png, read_image, read_timestamps, read_velodyne
from dcslam.synth import generate, make_drive
from dcslam.synth.raycast import CameraGrid
from dcslam.synth.street.generate import street_calibration
from dcslam.synth.street.sensors import GroundTexture, render_camera

FRAMES = 11  # the fewest with a depth frame (frame 5)


@pytest.fixture(scope="module")
def kitti(tmp_path_factory):
    root = tmp_path_factory.mktemp("kitti")
    reports = generate(root, drives=1, frames=FRAMES, seed=3)
    return root, reports


@pytest.fixture(scope="module")
def frame5():
    """True depth and image of frame 5 of the fixture drive, rendered again."""
    rig = street_calibration()
    truth, rng = make_drive(3, 0, FRAMES, rig)
    T_world_cam = truth.T_world_imu[5] @ np.linalg.inv(rig.T_cam2_imu)
    scene = truth.scene
    t = truth.timestamps[5] - truth.timestamps[0]
    return render_camera(scene, GroundTexture(scene), CameraGrid(rig.K_cam2, *rig.size_rect_02), T_world_cam,
                         float(t), rng)


def _drive(root):
    return root / "raw" / "2011_09_26" / "2011_09_26_drive_1000_sync", \
        root / "depth_completion" / "train" / "2011_09_26_drive_1000_sync" / "proj_depth"


def test_layout_and_formats(kitti):
    root, reports = kitti
    raw, depth = _drive(root)
    assert [r.name for r in reports] == ["2011_09_26_drive_1000_sync"]
    assert "seed 3" in (root / "SYNTHETIC").read_text()
    assert (root / "synth_config.json").exists()
    for name in ("calib_cam_to_cam.txt", "calib_velo_to_cam.txt", "calib_imu_to_velo.txt"):
        assert (root / "raw" / "2011_09_26" / name).exists()
    frames = [f"{k:010d}" for k in range(FRAMES)]
    assert sorted(p.stem for p in (raw / "image_02" / "data").iterdir()) == frames
    assert sorted(p.stem for p in (raw / "velodyne_points" / "data").iterdir()) == frames
    assert sorted(p.stem for p in (raw / "oxts" / "data").iterdir()) == frames
    for sensor in ("image_02", "oxts", "velodyne_points"):
        assert len(read_timestamps(raw / sensor / "timestamps.txt")) == FRAMES
    assert (raw / "oxts" / "dataformat.txt").read_text().startswith("lat:")
    assert len((raw / "oxts" / "data" / "0000000003.txt").read_text().split()) == 30
    image = read_image(raw / "image_02" / "data" / "0000000004.png")
    assert image.shape == (375, 1242, 3) and image.dtype == np.uint8
    scan = read_velodyne(raw / "velodyne_points" / "data" / "0000000005.bin")
    assert 90_000 < len(scan) < 150_000  # real KITTI frame 5: 121,948 points
    assert np.abs(scan[:, :3]).max() < 121 and scan[:, 3].min() >= 0 and scan[:, 3].max() < 1
    for kind in ("velodyne_raw", "groundtruth"):
        assert [p.name for p in (depth / kind / "image_02").iterdir()] == ["0000000005.png"]  # frames 5 … N − 6
        assert read_depth_png(depth / kind / "image_02" / "0000000005.png").shape == (375, 1242)
    assert not list(root.rglob(".*tmp*"))


def test_densities_are_near_real_kitti(kitti):
    root, reports = kitti
    _, depth = _drive(root)
    sparse = read_depth_png(depth / "velodyne_raw" / "image_02" / "0000000005.png")
    dense = read_depth_png(depth / "groundtruth" / "image_02" / "0000000005.png")
    # real KITTI drive 0001 frame 5: 4.1 % and 19.5 %
    assert 0.03 < np.mean(sparse > 0) < 0.06
    assert 0.13 < np.mean(dense > 0) < 0.26
    assert reports[0].sparse_density == pytest.approx(np.mean(sparse > 0), abs=1e-3)
    both = (sparse > 0) & (dense > 0)
    assert np.median(np.abs(sparse[both] - dense[both])) < 0.05


def test_velodyne_raw_has_see_through_errors_and_groundtruth_has_none(kitti, frame5):
    root, _ = kitti
    _, depth = _drive(root)
    true_depth, _ = frame5
    sparse = read_depth_png(depth / "velodyne_raw" / "image_02" / "0000000005.png")
    dense = read_depth_png(depth / "groundtruth" / "image_02" / "0000000005.png")
    seen = (sparse > 0) & (true_depth > 0)
    see_through = seen & (sparse > true_depth + 1.0)
    assert see_through.sum() >= 5
    assert see_through.sum() < 0.05 * seen.sum()
    agree = np.abs(sparse - true_depth) <= 0.2 + 0.02 * true_depth
    assert np.mean(agree[seen]) > 0.97  # the rest: edges of thin or near objects the pixel centre just misses
    ok = (dense > 0) & (true_depth > 0)
    assert np.all(dense[true_depth == 0] == 0)
    # a kept point lies within half a pixel of the pixel centre: on the road far ahead that is metres of depth
    far_off = np.abs(dense[ok] - true_depth[ok]) > np.maximum(1.0, 0.1 * true_depth[ok])
    assert np.mean(far_off) < 0.005


def test_rgb_edges_fall_on_depth_edges(frame5):
    depth, rgb = frame5
    grey = rgb.astype(np.float32).mean(2)
    z = np.where(depth > 0, depth, 1e4)
    ratio = np.maximum(z[:, 1:], z[:, :-1]) / np.minimum(z[:, 1:], z[:, :-1])
    depth_edge = ratio > 1.3
    colour_step = np.abs(grey[:, 1:] - grey[:, :-1])
    assert depth_edge.sum() > 200
    # at depth edges colour changes clearly, and much more than elsewhere
    assert np.mean(colour_step[depth_edge] > 6) > 0.75
    assert np.median(colour_step[depth_edge]) > 4 * np.median(colour_step[~depth_edge])


def test_refuses_to_overwrite_without_force(kitti):
    root, _ = kitti
    with pytest.raises(DcslamError, match="--force"):
        generate(root, drives=1, frames=2, seed=3)


def test_an_interrupted_run_leaves_no_partial_drive(tmp_path):
    calls = []

    def interrupt():
        calls.append(1)
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        generate(tmp_path, drives=1, frames=3, seed=0, on_frame=interrupt)
    assert calls == [1]
    assert not list((tmp_path / "raw" / "2011_09_26").glob("*drive*"))
    assert not list((tmp_path / "depth_completion" / "train").glob("*drive*"))


def test_same_seed_same_drive_other_seed_other_drive():
    rig = street_calibration()
    a, b, c = make_drive(4, 0, 20, rig)[0], make_drive(4, 0, 20, rig)[0], make_drive(5, 0, 20, rig)[0]
    np.testing.assert_array_equal(a.oxts, b.oxts)
    np.testing.assert_array_equal(a.timestamps, b.timestamps)
    assert len(a.scene.shapes) == len(b.scene.shapes)
    np.testing.assert_array_equal(a.scene.centers, b.scene.centers)
    assert not np.allclose(a.T_world_cam2[-1], c.T_world_cam2[-1])


def test_bad_arguments():
    with pytest.raises(DcslamError, match="--frames"):
        generate("unused", drives=1, frames=0)
    with pytest.raises(DcslamError, match="--drives"):
        generate("unused", drives=0, frames=5)


def test_exact_depth_and_fewer_beams_reach_the_drive_file(kitti, frame5, tmp_path):
    from dcslam.geometry.lidar_beams import laser_ids
    from dcslam.io.drive import DriveFile
    from dcslam.stages.prepare import prepare_kitti

    root, _ = kitti
    true_depth, _ = frame5
    exact_png = root / "depth_completion" / "train" / "2011_09_26_drive_1000_sync" / "dcslam_exact_synthetic" / \
        "image_02" / "0000000005.png"
    exact = read_depth_png(exact_png)
    assert np.abs(exact - true_depth).max() <= 0.5 / 256 + 1e-6  # the PNG's 1/256 m steps, nothing else
    assert np.mean(exact > 0) > 0.9  # every pixel but the sky
    prepare_kitti(root, tmp_path / "drives", beams=(16,), include_unsplit=True)
    scan = read_velodyne(_drive(root)[0] / "velodyne_points" / "data" / "0000000005.bin")
    assert len(np.unique(laser_ids(scan))) == 64  # generated scans: lasers told apart by elevation
    with DriveFile(tmp_path / "drives" / "2011_09_26_drive_1000_sync.h5") as drive:
        assert set(drive.kinds) == {"sparse", "dense", "sparse@16", "exact"}
        assert np.array_equal(drive.depth("exact", 0), exact)
        sparse, sixteen = drive.depth("sparse", 0), drive.depth("sparse@16", 0)
        assert 0.2 < (sixteen > 0).sum() / (sparse > 0).sum() < 0.3
        both = (sixteen > 0) & (exact > 0)
        assert np.median(np.abs(sixteen[both] - exact[both])) < 0.05


def _drives(root):
    return sorted(p.name for p in (root / "raw" / "2011_09_26").glob("*_drive_*"))


def test_force_with_fewer_drives_removes_the_earlier_drives_and_leftovers(tmp_path):
    generate(tmp_path, drives=2, frames=1, seed=0)
    leftover = tmp_path / "depth_completion" / "train" / ".2011_09_26_drive_1003_sync.tmp-99999"
    leftover.mkdir()
    (leftover / "half.png").write_bytes(b"x")
    with pytest.raises(DcslamError, match="--force"):
        generate(tmp_path, drives=1, frames=1, seed=5)
    generate(tmp_path, drives=1, frames=1, seed=5, force=True)
    assert _drives(tmp_path) == ["2011_09_26_drive_1000_sync"]
    assert sorted(p.name for p in (tmp_path / "depth_completion" / "train").iterdir()) == [
        "2011_09_26_drive_1000_sync"]  # the old 1001 and the temporary folder are gone
    assert "seed 5, 1 drives" in (tmp_path / "SYNTHETIC").read_text()


def test_an_interrupted_run_claims_no_drive_in_its_marker(tmp_path):
    generate(tmp_path, drives=1, frames=1, seed=0)
    calls = []

    def interrupt_second_drive():
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        generate(tmp_path, drives=2, frames=1, seed=7, force=True, on_frame=interrupt_second_drive)
    assert not (tmp_path / "SYNTHETIC").exists() and not (tmp_path / "synth_config.json").exists()
    assert not list(tmp_path.rglob("*.tmp-*"))
    generate(tmp_path, drives=2, frames=1, seed=7, force=True)  # the rerun completes
    assert _drives(tmp_path) == ["2011_09_26_drive_1000_sync", "2011_09_26_drive_1001_sync"]
    assert "seed 7, 2 drives" in (tmp_path / "SYNTHETIC").read_text()


def test_drives_written_in_worker_processes_are_the_same_files(tmp_path):
    frames = []
    generate(tmp_path / "one", drives=2, frames=2, seed=4)
    generate(tmp_path / "two", drives=2, frames=2, seed=4, jobs=2, on_frame=lambda: frames.append(1))
    assert len(frames) == 4  # every frame counted, as its drive completes

    def files(root):
        return {p.relative_to(root): p.read_bytes() for p in sorted(root.rglob("*"))
                if p.is_file() and p.name != "synth_config.json"}  # which names its own --out

    one, two = files(tmp_path / "one"), files(tmp_path / "two")
    assert len(one) > 10 and one.keys() == two.keys()
    assert [name for name in one if one[name] != two[name]] == []
