"""FrameReader: a frame read from its stored chunk is h5py's ``dataset[i]``, for every layout, and a broken chunk
fails as h5py fails."""
import zlib

import h5py
import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.io import chunks
from dcslam.io.chunks import FrameReader
from dcslam.io.drive import DriveFile

from .test_drive import make_frames, write

N, H, W = 4, 7, 9


def _data(dtype, seed=0):
    rng = np.random.default_rng(seed)
    if np.dtype(dtype).kind == "f":
        return (rng.uniform(0, 80, (N, H, W)) * (rng.random((N, H, W)) < 0.3)).astype(dtype)
    return rng.integers(0, 256, (N, H, W, 3)).astype(dtype)


LAYOUTS = {  # name -> (dtype, create_dataset options, read from the chunk)
    "dcslam depth: deflate + shuffle": (np.float32, dict(chunks=(1, H, W), compression="gzip",
                                                          compression_opts=1, shuffle=True), True),
    "dcslam colour: deflate": (np.uint8, dict(chunks=(1, H, W, 3), compression="gzip", compression_opts=1), True),
    "float64, deflate level 9 + shuffle": (np.float64, dict(chunks=(1, H, W), compression="gzip",
                                                            compression_opts=9, shuffle=True), True),
    "uint16, shuffle + deflate": (np.uint16, dict(chunks=(1, H, W, 3), compression="gzip", shuffle=True), True),
    "lzf": (np.float32, dict(chunks=(1, H, W), compression="lzf"), False),
    "contiguous": (np.float32, {}, False),
    "chunks of rows": (np.float32, dict(chunks=(1, 3, W), compression="gzip"), False),
    "two frames a chunk": (np.float32, dict(chunks=(2, H, W), compression="gzip"), False),
    "big-endian": (">f4", dict(chunks=(1, H, W), compression="gzip", shuffle=True), False),
    "deflate + fletcher32": (np.float32, dict(chunks=(1, H, W), compression="gzip", fletcher32=True), False),
}


@pytest.mark.parametrize("layout", LAYOUTS)
def test_every_frame_is_h5pys_and_writable(tmp_path, layout):
    dtype, options, fast = LAYOUTS[layout]
    data = _data(dtype)
    with h5py.File(tmp_path / "f.h5", "w") as h5:
        h5.create_dataset("x", data=data, **options)
    with h5py.File(tmp_path / "f.h5", "r") as h5:
        reader = FrameReader(h5["x"])
        assert reader.fast == fast
        for i in (*range(N), -1, -N):
            frame = reader(i)
            expected = h5["x"][i]
            assert frame.dtype == expected.dtype and frame.shape == expected.shape
            assert frame.tobytes() == expected.tobytes() and np.array_equal(frame, data[i])
            assert frame.flags.writeable
            frame[...] = 0                                  # a copy: the next read is unchanged
            assert np.array_equal(reader(i), data[i])
        with pytest.raises(IndexError):   # h5py's own error for a frame past the end
            reader(N)


def _broken(tmp_path, stored: bytes, mask: int = 0):
    """A dcslam-style depth dataset whose frame 1 is ``stored`` as it sits in the file (filter mask ``mask``)."""
    data = _data(np.float32)
    path = tmp_path / "broken.h5"
    with h5py.File(path, "w") as h5:
        x = h5.create_dataset("x", data=data, chunks=(1, H, W), compression="gzip", compression_opts=1, shuffle=True)
        x.id.write_direct_chunk((1, 0, 0), stored, filter_mask=mask)
    return path, data


def test_a_chunk_that_does_not_inflate_fails_as_h5py_fails(tmp_path):
    path, data = _broken(tmp_path, b"not a zlib stream")
    with h5py.File(path, "r") as h5:
        reader = FrameReader(h5["x"])
        assert reader.fast
        with pytest.raises(OSError) as ours:
            reader(1)
        with pytest.raises(OSError) as theirs:
            h5["x"][1]
        assert str(ours.value) == str(theirs.value)
        assert np.array_equal(reader(0), data[0]) and np.array_equal(reader(2), data[2])  # the others still read


@pytest.mark.parametrize("size", [12, 4 * H * W + 4])
def test_a_chunk_that_inflates_to_other_than_a_frame_is_refused_in_one_line(tmp_path, size):
    """HDF5 would return the frame with the missing bytes as its buffer held them: a different array each read."""
    path, data = _broken(tmp_path, zlib.compress(b"\1" * size))
    with h5py.File(path, "r") as h5:
        reader = FrameReader(h5["x"])
        with pytest.raises(DcslamError, match=rf"broken.h5: /x frame 1 inflates to {size} bytes, expected "
                                              rf"{4 * H * W}: the file is damaged"):
            reader(1)
        assert np.array_equal(reader(2), data[2])


def test_a_chunk_stored_without_its_filters_reads_as_h5py_reads_it(tmp_path):
    """A filter mask (here: deflate skipped for this chunk, shuffle applied) is HDF5's to honour: h5py reads it."""
    frame = np.arange(H * W, dtype=np.float32).reshape(H, W)
    shuffled = frame.view(np.uint8).reshape(-1, 4).T.tobytes()
    path, _ = _broken(tmp_path, shuffled, mask=0b10)
    with h5py.File(path, "r") as h5:
        assert np.array_equal(FrameReader(h5["x"])(1), h5["x"][1])
        assert np.array_equal(h5["x"][1], frame)


def test_drive_files_read_their_frames_through_it(tmp_path):
    path = write(tmp_path / "d.h5", make_frames(3))
    with DriveFile(path) as drive, h5py.File(path, "r") as h5:
        for i in range(3):
            assert np.array_equal(drive.rgb(i), h5["rgb"][i])
            assert drive.depth("sparse", i).tobytes() == h5["depth/sparse"][i].tobytes()
        assert drive._readers["rgb"].fast and drive._readers["depth/sparse"].shuffled


def test_without_isal_the_chunk_is_inflated_by_zlib(tmp_path, monkeypatch):
    monkeypatch.setattr(chunks, "_inflate", zlib.decompress)
    data = _data(np.float32)
    with h5py.File(tmp_path / "f.h5", "w") as h5:
        h5.create_dataset("x", data=data, chunks=(1, H, W), compression="gzip", shuffle=True)
    with h5py.File(tmp_path / "f.h5", "r") as h5:
        assert all(np.array_equal(FrameReader(h5["x"])(i), data[i]) for i in range(N))
