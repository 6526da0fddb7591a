import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.filters import (PRESETS, BilateralFilter, DiscontinuityFilter, FilterChain, HiddenPointFilter, RangeFilter,
                            StatisticalOutlierFilter, backproject, filter_drives, filter_frames)
from dcslam.io.drive import DriveFrame, DriveWriter, read_layer

K = np.array([[50.0, 0, 24], [0, 50.0, 16], [0, 0, 1]])


def plane(h=32, w=48, depth=10.0):
    return np.full((h, w), depth, np.float32)


class TestBackproject:
    def test_known_point(self):
        depth = np.zeros((32, 48), np.float32)
        depth[16, 34] = 5.0
        points, index = backproject(depth, K)
        np.testing.assert_allclose(points, [[(34 - 24) * 5 / 50, 0, 5]])
        assert index.tolist() == [16 * 48 + 34]


class TestRange:
    def test_keeps_bounds_inclusive(self):
        depth = np.array([[0, 4.9, 5, 10, 15, 15.1]], np.float32)
        np.testing.assert_array_equal(PRESETS["thesis-range"].apply(depth), [[0, 0, 5, 10, 15, 0]])

    def test_bad_bounds(self):
        with pytest.raises(DcslamError):
            RangeFilter(10, 5)


class TestBilateral:
    def test_equals_opencv_without_holes(self):
        import cv2

        rng = np.random.default_rng(0)
        depth = rng.uniform(2, 40, (24, 36)).astype(np.float32)
        for sigma_color in (80.0, 3.0):
            ours = BilateralFilter(5, sigma_color, 80.0).apply(depth)
            np.testing.assert_allclose(ours, cv2.bilateralFilter(depth, 5, sigma_color, 80.0), rtol=1e-4, atol=1e-4)

    def test_holes_stay_holes_and_do_not_pull_depth_down(self):
        depth = plane()
        depth[10:14, 10:14] = 0
        out = BilateralFilter(5, 80.0, 80.0).apply(depth)
        assert np.all(out[10:14, 10:14] == 0)
        np.testing.assert_allclose(out[depth > 0], 10.0, rtol=1e-6)
        thesis = BilateralFilter(5, 80.0, 80.0, ignore_holes=False).apply(depth)
        assert thesis[12, 12] > 0 and thesis[10, 9] < 10.0   # OpenCV as called by the thesis smears holes

    def test_preserves_edges_with_small_sigma_color(self):
        depth = plane()
        depth[:, 24:] = 30.0
        out = BilateralFilter(5, 0.5, 80.0).apply(depth)
        np.testing.assert_allclose(out, depth, atol=1e-3)

    def test_does_not_modify_input(self):
        depth = plane()
        depth[0, 0] = 0
        copy = depth.copy()
        BilateralFilter().apply(depth)
        np.testing.assert_array_equal(depth, copy)


class TestOutliers:
    def test_removes_isolated_point(self):
        depth = plane()
        depth[5, 5] = 40.0
        out = StatisticalOutlierFilter(nb_neighbors=8, std_ratio=2.0).apply(depth, K)
        assert out[5, 5] == 0
        assert (out > 0).sum() >= depth.size - 5

    def test_hidden_points_behind_a_foreground_surface(self):
        # a near wall (5 m) with far LiDAR points (30 m) showing through it, plus background around it
        rng = np.random.default_rng(0)
        depth = np.where(rng.random((32, 48)) < 0.5, 30.0, 0).astype(np.float32)
        depth[8:24, 12:36] = 5.0 + 0.01 * rng.random((16, 24))
        leaked = [(12, 20), (16, 24), (20, 30)]
        for v, u in leaked:
            depth[v, u] = 30.0
        out = HiddenPointFilter(radius_factor=100).apply(depth, K)
        assert all(out[v, u] == 0 for v, u in leaked)
        assert (out[8:24, 12:36] > 0).mean() > 0.9

    def test_too_few_points_unchanged(self):
        depth = np.zeros((8, 8), np.float32)
        depth[1, 1] = 3
        np.testing.assert_array_equal(HiddenPointFilter().apply(depth, K), depth)
        np.testing.assert_array_equal(StatisticalOutlierFilter().apply(depth, K), depth)


class TestDiscontinuity:
    def test_drops_both_sides_of_an_edge(self):
        depth = plane(4, 6)
        depth[:, 3:] = 20.0
        out = DiscontinuityFilter(max_jump_m=1.0, max_relative_jump=None).apply(depth)
        assert np.all(out[:, 2:4] == 0) and np.all(out[:, :2] == 10) and np.all(out[:, 4:] == 20)

    def test_relative_threshold_and_holes_are_not_edges(self):
        depth = plane(4, 6)
        depth[0, 0] = 0
        depth[3, 5] = 10.5
        out = DiscontinuityFilter(max_relative_jump=0.1).apply(depth)
        np.testing.assert_array_equal(out, depth)

    def test_needs_a_threshold(self):
        with pytest.raises(DcslamError):
            DiscontinuityFilter(max_jump_m=None, max_relative_jump=None)


class TestChain:
    def test_order_name_and_description(self):
        chain = FilterChain((PRESETS["thesis-range"], PRESETS["thesis-bilateral"]))
        assert chain.name == "range+bilateral"
        assert chain.describe()[0] == {"filter": "range", "min_m": 5.0, "max_m": 15.0}
        assert chain.describe()[1]["d"] == 5 and chain.describe()[1]["sigma_color"] == 80.0
        depth = plane()
        depth[:, :10] = 20.0
        out = chain.apply(depth, K)
        assert np.all(out[:, :10] == 0) and np.allclose(out[:, 10:], 10.0)

    def test_empty_chain_fails(self):
        with pytest.raises(DcslamError):
            FilterChain(())

    def test_frames(self):
        stack = np.stack([plane(), plane(depth=20.0)])
        out = filter_frames(stack, K, FilterChain((RangeFilter(5, 15),)))
        assert out.shape == stack.shape and np.all(out[1] == 0)
        with pytest.raises(DcslamError, match=r"\(N, H, W\)"):
            filter_frames(plane(), K, FilterChain((RangeFilter(5, 15),)))


def write_drive(path, n=3, h=8, w=12, seed=0):
    rng = np.random.default_rng(seed)
    with DriveWriter(path, K, h, w, source="synthetic", date="2011_09_26", drive=path.stem) as writer:
        for i in range(n):
            dense = rng.uniform(5, 20, (h, w)).astype(np.float32)
            sparse = np.where(rng.random((h, w)) < 0.3, dense, 0).astype(np.float32)
            writer.append(DriveFrame(rgb=np.zeros((h, w, 3), np.uint8), sparse=sparse, dense=dense,
                                     T_world_cam=np.eye(4), timestamp=0.1 * i, frame_id=i))
    return path


def test_filter_drives_writes_layers_and_refuses_to_overwrite(tmp_path):
    drive = write_drive(tmp_path / "d.h5")
    out = tmp_path / "out" / "d.h5"
    chain = FilterChain((RangeFilter(8, 12),))
    filter_drives([(drive, "dense", out)], chain, made_by="dense+range", settings={"name": "dense+range"})
    layer = read_layer(out, expect_frames=3)
    assert layer.made_by == "dense+range" and layer.config["filters"] == chain.describe()
    assert layer.config["source"] == "dense"
    valid = layer.depth[layer.depth > 0]
    assert valid.size and valid.min() >= 8 and valid.max() <= 12
    before = out.stat().st_mtime_ns
    with pytest.raises(DcslamError, match="exists"):
        filter_drives([(drive, "dense", out)], chain, made_by="x", settings={})
    assert out.stat().st_mtime_ns == before
    filter_drives([(drive, "sparse", out)], chain, made_by="x", settings={}, force=True)
    assert read_layer(out).made_by == "x"


def test_on_real_kitti_lidar(data_dir):
    """KITTI drive 0001, frame 5: LiDAR points seen through foreground objects disagree with the annotated depth;
    hidden-point removal drops most of them, and the thesis's range keeps 5–15 m only."""
    from dcslam.eval.depth import depth_errors
    from dcslam.io.kitti import read_depth_png

    base = data_dir / "kitti-sample/depth_completion/train/2011_09_26_drive_0001_sync/proj_depth"
    sparse = read_depth_png(base / "velodyne_raw/image_02/0000000005.png")
    gt = read_depth_png(base / "groundtruth/image_02/0000000005.png")
    K_cam2 = np.array([[721.5377, 0, 609.5593], [0, 721.5377, 172.854], [0, 0, 1]])

    def far_off(depth):  # fraction of scored pixels more than 1 m from the annotated depth
        both = (depth > 0) & (gt > 0)
        return float((np.abs(depth[both] - gt[both]) > 1.0).mean())

    visible = HiddenPointFilter().apply(sparse, K_cam2)
    assert (visible > 0).sum() > 0.5 * (sparse > 0).sum()
    assert far_off(visible) < far_off(sparse) / 5
    assert depth_errors(visible, gt, interpolate=False).mae_mm < depth_errors(sparse, gt, interpolate=False).mae_mm
    ranged = PRESETS["thesis-range"].apply(sparse)
    assert ranged[ranged > 0].min() >= 5 and ranged[ranged > 0].max() <= 15
