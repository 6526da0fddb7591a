import numpy as np
import pytest

from dcslam.depth.models.ip_basic import IPBasic, complete_fast, complete_multiscale, cross_kernel, diamond_kernel
from dcslam.errors import DcslamError
from dcslam.eval.depth import depth_errors
from dcslam.io.kitti import read_depth_png

SAMPLE = "kitti-sample/depth_completion/train/2011_09_26_drive_0001_sync/proj_depth"


def test_kernels():
    d = diamond_kernel(5)
    assert d.sum() == 13 and d[0, 2] == 1 and d[0, 0] == 0
    c = cross_kernel(5)
    assert c.sum() == 9


def _scene(h=64, w=96, seed=0):
    rng = np.random.default_rng(seed)
    rows = np.arange(h)[:, None] * np.ones((1, w))
    dense = (8.0 + 4.0 * (1 - rows / h)).astype(np.float32)  # a ground-like ramp, 8 to 12 m
    dense[20:40, 30:50] = 6.0  # a near box
    sparse = np.where(rng.random((h, w)) < 0.1, dense, 0).astype(np.float32)
    return sparse, dense


@pytest.mark.parametrize("variant", ["fast", "multiscale"])
def test_fills_everything_and_keeps_close_to_truth(variant):
    sparse, dense = _scene()
    out = IPBasic(variant)(sparse)
    assert out.shape == sparse.shape and out.dtype == np.float32
    assert (out > 0).all() and np.isfinite(out).all()
    err = np.abs(out - dense)
    nearest_fill = np.abs(sparse[sparse > 0] - dense[sparse > 0]).mean()  # 0: sparse = dense there
    assert nearest_fill == 0
    assert np.median(err / dense) < 0.05
    assert sparse is not out and (sparse == _scene()[0]).all()  # input untouched


def test_constant_depth_is_a_fixed_point():
    sparse = np.zeros((40, 60), np.float32)
    sparse[::3, ::4] = 12.0
    out = complete_fast(sparse)
    assert np.allclose(out, 12.0, atol=1e-3)


def test_closer_surface_wins_at_edges():
    sparse = np.zeros((30, 30), np.float32)
    sparse[15, 14] = 5.0
    sparse[15, 16] = 50.0
    out = complete_fast(sparse, blur="none")
    assert out[15, 15] == pytest.approx(5.0, abs=1e-3)


def test_bad_input():
    with pytest.raises(DcslamError):
        IPBasic("fast")(np.zeros((2, 3, 4), np.float32))
    with pytest.raises(DcslamError):
        IPBasic("nope")
    with pytest.raises(DcslamError):
        complete_fast(np.ones((8, 8), np.float32), blur="box")


def _kitti_frame(data_dir):
    sparse = read_depth_png(data_dir / SAMPLE / "velodyne_raw/image_02/0000000005.png")
    gt = read_depth_png(data_dir / SAMPLE / "groundtruth/image_02/0000000005.png")
    return sparse, gt


# The authors' code (kujason/ip_basic, depth_map_utils.py) on the real KITTI frame (drive 0001, frame 5, image_02),
# scored over its ground-truth pixels, mm. dcslam's output was also checked identical, pixel
# for pixel, to the authors' functions run locally on this frame, for both variants, both blurs, with and without
# extrapolation; the extrapolate=False figures below are those runs' (scored with dcslam's devkit interpolation).
AUTHORS_FIGURES = [
    ("fast", True, "gaussian", 268.1, 1079.8),
    ("fast", True, "bilateral", 281.9, 1166.1),
    ("multiscale", True, "gaussian", 300.4, 1370.5),
    ("fast", False, "bilateral", 276.0, 1072.7),
    ("multiscale", False, "bilateral", 367.1, 1583.5),
]


@pytest.mark.parametrize("variant, extrapolate, blur, mae_mm, rmse_mm", AUTHORS_FIGURES)
def test_real_kitti_frame_matches_the_authors(data_dir, variant, extrapolate, blur, mae_mm, rmse_mm):
    sparse, gt = _kitti_frame(data_dir)
    out = IPBasic(variant, extrapolate=extrapolate, blur=blur)(sparse)
    errors = depth_errors(out, gt)
    assert errors.coverage == 1.0
    assert errors.mae_mm == pytest.approx(mae_mm, abs=0.1)
    assert errors.rmse_mm == pytest.approx(rmse_mm, abs=0.1)


@pytest.mark.parametrize("variant, holes", [("fast", 92), ("multiscale", 1123)])
def test_no_extrapolation_leaves_the_top_empty(data_dir, variant, holes):
    """Without extrapolation the authors' code fills nothing above each column's highest depth (no 31x31 fill):
    on the KITTI frame that leaves 92 (fast) / 1123 (multiscale) ground-truth pixels without depth."""
    sparse, gt = _kitti_frame(data_dir)
    out = IPBasic(variant, extrapolate=False)(sparse)
    assert int(((gt > 0) & (out == 0)).sum()) == holes
    assert (out[0] == 0).all()                        # the top row is above every LiDAR return
    filled = IPBasic(variant, extrapolate=True)(sparse)
    assert (filled > 0).all()


def test_multiscale_dilates_each_range_with_its_cross():
    """A far wall (50 m, cols 0-19) and a near wall (5 m, cols 24-39) with a 4-column gap: the far bin's 3x3 cross
    reaches one column (20), the near bin's 7x7 cross three (21-23), and the near one wins where both reach. (The
    earlier diamonds 5/7/9 let the near wall reach column 20 as well.)"""
    sparse = np.zeros((30, 40), np.float32)
    sparse[:, :20] = 50.0
    sparse[:, 24:] = 5.0
    out = complete_multiscale(sparse, extrapolate=False, blur="none")
    assert out[15, 20] == pytest.approx(50.0, abs=1e-4)
    np.testing.assert_allclose(out[15, 21:24], 5.0, atol=1e-4)


def test_inputs_below_a_decimetre_are_no_depth():
    sparse = np.zeros((30, 30), np.float32)
    sparse[10:20, 10:20] = 12.0
    with_tiny = sparse.copy()
    with_tiny[5, 5] = 0.05
    np.testing.assert_array_equal(complete_fast(with_tiny), complete_fast(sparse))
