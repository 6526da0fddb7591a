"""Frames of a drive read one at a time for SLAM: the values of the whole-file readers, only the frames asked for,
and a layer refused (or a frame rejected) as the whole-layer reader would."""
import h5py
import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.io.drive import DriveFile, Layer, read_layer, write_layer
from dcslam.io.drive_frames import drive_frames
from tests.fixtures.street import write_analytic_street

H, W, N = 24, 80, 6


@pytest.fixture
def drive(tmp_path):
    path = tmp_path / "street.h5"
    write_analytic_street(path, N, H, W)
    return path


def _layer(drive, path, confidence=True):
    with DriveFile(drive) as d:
        dense = np.stack([d.depth("dense", i) for i in range(len(d))])
        conf = np.linspace(0, 1, dense.size, dtype=np.float32).reshape(dense.shape) if confidence else None
        return write_layer(path, Layer(dense, drive=d.name, made_by="test", confidence=conf, frame_ids=d.frame_ids))


def test_frames_are_those_of_the_whole_file_readers(drive, tmp_path):
    layer = _layer(drive, tmp_path / "layer" / "street.h5")
    whole = read_layer(layer)
    with DriveFile(drive) as d, drive_frames(drive, layer, sources_kind="sparse") as frames:
        assert len(frames) == N and frames.has_confidence and frames.name == d.name
        assert np.array_equal(frames.T_world_cam, d.poses) and np.array_equal(frames.timestamps, d.timestamps)
        read = list(frames.frames)
        assert len(read) == N
        for i, f in enumerate(read):
            assert np.array_equal(f.depth, whole.depth[i]) and np.array_equal(f.confidence, whole.confidence[i])
            assert np.array_equal(f.rgb, d.rgb(i)) and np.array_equal(f.sources, d.depth("sparse", i))
    with drive_frames(drive, "sparse", 2, sources_kind="sparse") as frames:  # the input is its own sources
        read = list(frames.frames)
        assert len(read) == 2 and len(frames) == 2 and not frames.has_confidence
        assert all(f.sources is None and f.confidence is None for f in read)


def test_without_colour_no_colour_image_is_read(drive, monkeypatch):
    with DriveFile(drive) as d:
        depth = [d.depth("sparse", i) for i in range(N)]

    def refuse(self, i):
        raise AssertionError(f"colour image {i} read")

    monkeypatch.setattr(DriveFile, "rgb", refuse)
    with drive_frames(drive, "sparse", colour=False) as frames:
        read = list(frames.frames)
    assert len(read) == N and all(f.rgb is None for f in read)
    assert all(np.array_equal(f.depth, depth[i]) for i, f in enumerate(read))
    with drive_frames(drive, "sparse") as frames, pytest.raises(AssertionError, match="colour image 0 read"):
        next(frames.frames)


def test_only_the_frames_asked_for_are_read(drive, tmp_path):
    """A bad value in frame 4 of a layer stops a run over all its frames at that frame, not one over the first 3."""
    layer = _layer(drive, tmp_path / "layer" / "street.h5")
    with h5py.File(layer, "r+") as h5:
        h5["depth"][4] = np.full((H, W), np.nan, np.float32)
    with drive_frames(drive, layer, 3) as frames:
        assert len(list(frames.frames)) == 3
    with drive_frames(drive, layer) as frames, pytest.raises(DcslamError, match="frame 4 holds NaN"):
        list(frames.frames)


def test_a_bad_confidence_is_refused_at_its_frame(drive, tmp_path):
    layer = _layer(drive, tmp_path / "layer" / "street.h5")
    with h5py.File(layer, "r+") as h5:
        h5["confidence"][2] = np.full((H, W), 1.5, np.float32)
    with drive_frames(drive, layer) as frames, pytest.raises(DcslamError, match="confidence of frame 2 must be"):
        list(frames.frames)


def test_layers_of_other_drives_and_other_files_are_refused_before_any_frame(drive, tmp_path):
    with pytest.raises(DcslamError, match="layer file .* not found; run `dcslam predict`"):
        with drive_frames(drive, tmp_path / "absent.h5"):
            pass
    other = write_layer(tmp_path / "other.h5", Layer(np.ones((N, H, W), np.float32), drive="elsewhere", made_by="x"))
    with pytest.raises(DcslamError, match="a layer of drive 'elsewhere', not of 'street'"):
        with drive_frames(drive, other):
            pass
    short = write_layer(tmp_path / "short.h5", Layer(np.ones((N - 1, H, W), np.float32), drive="street", made_by="x"))
    with pytest.raises(DcslamError, match=f"layer has {N - 1} frames but its drive has {N}"):
        with drive_frames(drive, short):
            pass
    (tmp_path / "junk.h5").write_bytes(b"not hdf5")
    with pytest.raises(DcslamError, match="not a readable HDF5 layer file"):
        with drive_frames(drive, tmp_path / "junk.h5"):
            pass
    with h5py.File(tmp_path / "schema.h5", "w") as h5:
        h5["depth"] = np.ones((N, H, W), np.float32)
    with pytest.raises(DcslamError, match="not a dcslam depth layer"):
        with drive_frames(drive, tmp_path / "schema.h5"):
            pass
    with pytest.raises(DcslamError, match="holds no sparse@16 depth"):
        with drive_frames(drive, "dense", sources_kind="sparse@16"):
            pass
