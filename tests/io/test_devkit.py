"""The KITTI devkit's prediction PNGs: what dcslam writes is what the devkit's ``depth_read`` reads (PIL, uint16,
depth = png / 256, png == 0 → invalid), the reader places cropped files and refuses malformed ones, and list files
read back in order."""
import io

import numpy as np
import pytest
from PIL import Image

from dcslam.errors import DcslamError
from dcslam.io import devkit


def devkit_depth_read(data: bytes) -> np.ndarray:
    """The devkit's own reader (its ``depth_read``), on PIL alone: metres, -1 where there is no depth."""
    png = np.array(Image.open(io.BytesIO(data)), dtype=int)
    assert np.max(png) > 255, "the devkit refuses 8-bit files"
    depth = png.astype(float) / 256.0
    depth[png == 0] = -1.0
    return depth


def test_encoded_files_are_what_the_devkit_reads():
    depth = np.array([[0.0, 0.05, 1.0, 12.34], [80.0, np.nan, 300.0, 255.99]], np.float32)
    data = devkit.encode_prediction(depth)
    image = Image.open(io.BytesIO(data))
    assert image.size == (4, 2) and np.array(image).dtype == np.uint16  # (W, H)
    read = devkit_depth_read(data)
    np.testing.assert_array_equal(read[0, :2], [-1, -1])  # a hole, and a depth below 0.1 m (a hole in dcslam)
    np.testing.assert_allclose(read[0, 2:], [1.0, 12.34], atol=0.5 / 256)
    assert read[1, 0] == 80.0 and read[1, 1] == -1 and read[1, 2] == -1  # NaN and beyond 256 m: no depth
    np.testing.assert_allclose(read[1, 3], 255.99, atol=0.5 / 256)


def test_read_places_a_cropped_file_and_round_trips(tmp_path):
    rng = np.random.default_rng(0)
    full = rng.uniform(1, 80, (10, 12)).astype(np.float32)
    full[rng.random(full.shape) < 0.3] = 0
    path = tmp_path / "0000000000.png"
    path.write_bytes(devkit.encode_prediction(full[3:, 2:11]))
    placed = devkit.read_prediction(path, 10, 12, offset=(3, 2))
    assert placed.shape == (10, 12) and placed.dtype == np.float32
    assert not placed[:3].any() and not placed[:, :2].any() and not placed[:, 11:].any()
    np.testing.assert_allclose(placed[3:, 2:11], full[3:, 2:11], atol=0.5 / 256)
    path.write_bytes(devkit.encode_prediction(full))
    np.testing.assert_allclose(devkit.read_prediction(path, 10, 12), full, atol=0.5 / 256)


def _png(path, array):
    import cv2

    assert cv2.imwrite(str(path), array)
    return path


@pytest.mark.parametrize("case, array, offset, message", [
    ("8-bit", np.full((4, 6), 200, np.uint8), (0, 0), "16-bit"),
    ("colour", np.full((4, 6, 3), 2000, np.uint16), (0, 0), "16-bit"),
    ("wrong size", np.full((4, 5), 2560, np.uint16), (0, 0), "4 × 5 pixels, its drive's frames are 4 × 6"),
    ("does not fit", np.full((3, 6), 2560, np.uint16), (2, 0), "do not fit"),
    ("too near", np.full((4, 6), 3, np.uint16), (0, 0), "outside 0.1-120 m"),
    ("too far", np.full((4, 6), 121 * 256, np.uint16), (0, 0), "outside 0.1-120 m"),
])
def test_malformed_files_are_refused_naming_the_file(tmp_path, case, array, offset, message):
    path = _png(tmp_path / "0000000007.png", array)
    with pytest.raises(DcslamError, match=message) as error:
        devkit.read_prediction(path, 4, 6, offset=offset)
    assert str(path) in str(error.value) and "\n" not in str(error.value)


def test_truncated_and_missing_files_are_refused(tmp_path):
    path = tmp_path / "0000000000.png"
    path.write_bytes(devkit.encode_prediction(np.ones((4, 6)))[:40])
    with pytest.raises(DcslamError, match="not a readable PNG"):
        devkit.read_prediction(path, 4, 6)
    with pytest.raises(DcslamError, match="not found"):
        devkit.read_prediction(tmp_path / "none.png", 4, 6)


def test_list_files_round_trip_and_take_the_methods_paths(tmp_path):
    entries = [("drive_b", 3), ("drive_a", 0), ("drive_a", 1)]
    path = tmp_path / "list.txt"
    path.write_text(devkit.list_text(entries))
    assert path.read_text().splitlines()[0] == "drive_b 0000000003"
    assert devkit.read_list(path, ["drive_a", "drive_b"]) == entries
    path.write_text("# PENet's test list\n/data/val/drive_a/proj_depth/velodyne_raw/image_02/0000000005.png\n\n"
                    "drive_b 12\n")
    assert devkit.read_list(path, ["drive_a", "drive_b"]) == [("drive_a", 5), ("drive_b", 12)]


@pytest.mark.parametrize("text, message", [
    ("drive_x 3\n", "names no drive"),
    ("drive_a/proj_depth/image_02/frame.png\n", "no frame number"),
    ("drive_a 3\ndrive_a 0000000003\n", "listed again"),
    ("# nothing\n", "names no frames"),
])
def test_malformed_lists_are_refused(tmp_path, text, message):
    path = tmp_path / "list.txt"
    path.write_text(text)
    with pytest.raises(DcslamError, match=message):
        devkit.read_list(path, ["drive_a"])
