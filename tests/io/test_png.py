"""The PNG codecs: 16-bit depth at KITTI's and TUM's scales, 8-bit colour."""
import cv2
import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.io.png import read_depth_png, read_rgb_png, write_depth_png, write_rgb_png


@pytest.mark.parametrize("scale", [256.0, 5000.0])
def test_round_trip_quantised_to_one_step(tmp_path, scale):
    depth = np.random.default_rng(0).uniform(0.2, 60000 / scale, (5, 7)) * (np.arange(35).reshape(5, 7) % 4 > 0)
    assert write_depth_png(tmp_path / "d.png", depth, scale) == tmp_path / "d.png"
    back = read_depth_png(tmp_path / "d.png", scale)
    assert back.dtype == np.float32 and back.shape == (5, 7)
    assert np.abs(back - depth).max() <= 0.5 / scale + 1e-5
    assert np.array_equal(back == 0, depth == 0)


def test_depth_that_does_not_fit_is_no_value(tmp_path):
    depth = np.array([[-1.0, np.nan, np.inf], [255.99, 256.1, 1.0]])
    write_depth_png(tmp_path / "d.png", depth, 256.0)
    raw = cv2.imread(str(tmp_path / "d.png"), cv2.IMREAD_UNCHANGED)
    assert raw.tolist() == [[0, 0, 0], [65533, 0, 256]]


def test_malformed(tmp_path):
    cv2.imwrite(str(tmp_path / "rgb16.png"), np.zeros((3, 4, 3), np.uint16))
    expected = r"rgb16.png: expected a 16-bit single-channel depth PNG \(metres = value / 256\)"
    with pytest.raises(DcslamError, match=expected):
        read_depth_png(tmp_path / "rgb16.png", 256.0)
    (tmp_path / "cut.png").write_bytes(b"\x89PNG\r\n")
    with pytest.raises(DcslamError, match="cut.png: not a readable PNG"):
        read_depth_png(tmp_path / "cut.png", 256.0)
    with pytest.raises(DcslamError, match="not found"):
        read_depth_png(tmp_path / "none.png", 256.0)
    with pytest.raises(DcslamError, match=r"expected \(H, W\)"):
        write_depth_png(tmp_path / "x.png", np.zeros((2, 2, 1)), 256.0)


def test_rgb_round_trip_compression_changes_bytes_not_pixels(tmp_path):
    rgb = np.random.default_rng(1).integers(0, 256, (6, 5, 3), dtype=np.uint8)
    write_rgb_png(tmp_path / "a.png", rgb)
    write_rgb_png(tmp_path / "b.png", rgb, compression=9)
    for name in ("a.png", "b.png"):
        assert np.array_equal(read_rgb_png(tmp_path / name), rgb)
    assert np.array_equal(cv2.imread(str(tmp_path / "a.png"))[..., ::-1], rgb)  # BGR on disk
    cv2.imwrite(str(tmp_path / "rgba.png"), np.dstack([rgb[..., ::-1], np.full((6, 5), 9, np.uint8)]))
    assert np.array_equal(read_rgb_png(tmp_path / "rgba.png"), rgb)


def test_rgb_malformed(tmp_path):
    cv2.imwrite(str(tmp_path / "deep.png"), np.zeros((3, 4, 3), np.uint16))
    with pytest.raises(DcslamError, match="deep.png: expected an 8-bit colour image"):
        read_rgb_png(tmp_path / "deep.png")
    (tmp_path / "cut.png").write_bytes(b"\x89PNG\r\n")
    with pytest.raises(DcslamError, match="cut.png: not a readable image"):
        read_rgb_png(tmp_path / "cut.png")
    with pytest.raises(DcslamError, match=r"expected \(H, W, 3\) uint8"):
        write_rgb_png(tmp_path / "x.png", np.zeros((2, 2), np.uint8))
