"""The camera's kept steps (dcslam.io.camera_steps): a round trip, and None for whatever does not read as the steps."""
import io
import zipfile

import numpy as np
import pytest

from dcslam.io.camera_steps import read_camera_steps, write_camera_steps


def _steps(n: int = 3):
    rng = np.random.default_rng(3)
    T = np.repeat(np.eye(4)[None], n, 0)
    T[:, :3, 3] = rng.normal(size=(n, 3))
    covariance = rng.normal(size=(n, 6, 6))
    covariance[1] = np.nan                                  # an unmeasured step
    return T, covariance, np.array([120, 0, 4000]), np.array([True, False, True])


def test_steps_round_trip_bit_for_bit(tmp_path):
    path = tmp_path / ".camera" / "drive-key.npz"
    assert write_camera_steps(path, *_steps())
    for written, read in zip(_steps(), read_camera_steps(path, 3)):
        np.testing.assert_array_equal(written, read)
    assert read_camera_steps(path, 4) is None and read_camera_steps(tmp_path / "none.npz", 3) is None


def test_malformed_files_read_as_nothing(tmp_path):
    T, covariance, returns, measured = _steps()
    cases = {"garbage.npz": b"not a camera", "empty.npz": b""}
    buffer = io.BytesIO()
    np.savez(buffer, T=T, covariance=covariance, returns=returns)   # a field missing
    cases["missing.npz"] = buffer.getvalue()
    cases["truncated.npz"] = buffer.getvalue()[:200]                # a zip cut short
    buffer = io.BytesIO()
    np.savez(buffer, T=T[:, :3], covariance=covariance, returns=returns, measured=measured)  # another shape
    cases["shape.npz"] = buffer.getvalue()
    buffer = io.BytesIO()
    np.savez(buffer, T=T, covariance=covariance, returns=returns.astype(str), measured=measured)  # another kind
    cases["kind.npz"] = buffer.getvalue()
    for name, data in cases.items():
        (tmp_path / name).write_bytes(data)
        assert read_camera_steps(tmp_path / name, 3) is None, name
    assert zipfile.is_zipfile(tmp_path / "missing.npz")


def test_mismatched_arrays_are_refused_and_an_unwritable_folder_keeps_nothing(tmp_path):
    T, covariance, returns, measured = _steps()
    with pytest.raises(ValueError, match="returns has shape"):
        write_camera_steps(tmp_path / "a.npz", T, covariance, returns[:2], measured)
    (tmp_path / "blocked").write_text("a file where the folder would be")
    assert not write_camera_steps(tmp_path / "blocked" / "a.npz", T, covariance, returns, measured)
    assert not (tmp_path / "a.npz").exists()
