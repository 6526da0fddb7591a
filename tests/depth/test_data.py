import numpy as np
import pytest

from dcslam.depth.data import DriveFrames, downscale_depth, frame_windows, view_intrinsics
from dcslam.errors import DcslamError


def test_frame_windows():
    assert frame_windows(17, 8) == [range(0, 8), range(8, 16), range(16, 17)]
    assert frame_windows(3, 7) == [range(0, 3)]
    with pytest.raises(DcslamError):
        frame_windows(3, 0)


def test_downscale_keeps_nearest_valid():
    d = np.array([[0, 5, 0, 0], [7, 0, 0, 0]], np.float32)
    assert downscale_depth(d, 2).tolist() == [[5.0, 0.0]]


def test_crop_and_scale_keep_geometry(drive_path):
    full = DriveFrames(drive_path)
    view = DriveFrames(drive_path, scale=0.5, crop=16, stride=2, max_frames=2)
    assert view.indices == [0, 2]
    a, b = full.load([0]), view.load([0])
    assert b.dense.shape == (1, 1, 8, 32)
    # a 3-D point projects to matching positions: full-image pixel (u, v) ↔ view pixel ((u + .5) / 2 − .5, ...)
    point = np.array([1.3, 0.9, 6.0])
    u, v, _ = a.K.numpy() @ point / point[2]
    ub, vb, _ = b.K.numpy() @ point / point[2]
    assert ub == pytest.approx((u + 0.5) / 2 - 0.5) and vb == pytest.approx((v - 16 + 0.5) / 2 - 0.5)
    # and the depth of a view pixel is the nearest valid depth of its 2x2 block
    block = a.dense[0, 0, 16 + 6:16 + 8, 20:22]
    assert float(b.dense[0, 0, 3, 10]) == float(block[block > 0].min())
    assert np.allclose(view_intrinsics(np.eye(3), 10, 0, 1), np.eye(3))


def test_bad_views(drive_path):
    with pytest.raises(DcslamError):
        DriveFrames(drive_path, scale=0.3)
    with pytest.raises(DcslamError):
        DriveFrames(drive_path, crop=1000)
    with pytest.raises(DcslamError):
        DriveFrames(drive_path, stride=0)


def test_input_mix_rotates_the_kinds_over_positions_and_epochs(tmp_path):
    from dcslam.io.drive import DriveFile
    from tests.fixtures.depth import write_drive

    path = write_drive(tmp_path / "d.h5", n=3, height=32, width=64, extra=True)
    frames = DriveFrames(path, mix=["sparse", "sparse@16"])
    assert [frames.input_of(p, 0) for p in range(3)] == ["sparse", "sparse@16", "sparse"]
    assert [frames.input_of(p, 1) for p in range(3)] == ["sparse@16", "sparse", "sparse@16"]
    batch = frames.load([0, 1], epoch=1)
    with DriveFile(path) as drive:
        assert np.array_equal(batch.sparse[0, 0].numpy(), drive.depth("sparse@16", 0))
        assert np.array_equal(batch.sparse[1, 0].numpy(), drive.depth("sparse", 1))
    assert DriveFrames(path).input_of(1, 1) == "sparse"
    with pytest.raises(DcslamError, match="holds no sparse@32"):
        DriveFrames(path, mix=["sparse", "sparse@32"])
