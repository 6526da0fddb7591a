import numpy as np
import pytest

from dcslam.depth.models.ip_basic import IPBasic, complete_fast, cross_kernel, diamond_kernel
from dcslam.errors import DcslamError
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


def test_real_kitti_frame_accuracy(data_dir):
    sparse = read_depth_png(data_dir / SAMPLE / "velodyne_raw/image_02/0000000005.png")
    gt = read_depth_png(data_dir / SAMPLE / "groundtruth/image_02/0000000005.png")
    valid = gt > 0
    for variant in ("fast", "multiscale"):
        err = IPBasic(variant)(sparse)[valid] - gt[valid]
        # the paper reports 302.6 mm MAE / 1288.5 mm RMSE on the KITTI test set
        assert np.abs(err).mean() < 0.45 and np.sqrt((err ** 2).mean()) < 1.6
