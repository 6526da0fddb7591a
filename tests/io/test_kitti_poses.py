"""KITTI odometry pose files (3x4 row-major per line)."""
from pathlib import Path

import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.io.kitti_poses import read_kitti_poses, write_kitti_poses

POSES_04 = Path(__file__).parents[1] / "data" / "kitti-sample" / "odometry" / "poses" / "04.txt"


def random_poses(n: int, seed: int = 0) -> np.ndarray:
    """n rigid transforms: rotations from the QR factorisation of Gaussian matrices, translations up to 500 m."""
    rng = np.random.default_rng(seed)
    q, r = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    q *= np.sign(np.diagonal(r, axis1=1, axis2=2))[:, None, :]
    q[np.linalg.det(q) < 0] *= -1
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = q
    T[:, :3, 3] = rng.uniform(-500, 500, (n, 3))
    return T


def test_reads_sequence_04():
    T = read_kitti_poses(POSES_04)
    assert T.shape == (271, 4, 4)
    np.testing.assert_allclose(T[0], np.eye(4), atol=1e-9)
    np.testing.assert_array_equal(T[:, 3], np.tile([0.0, 0.0, 0.0, 1.0], (271, 1)))
    # the last pose as printed in the file: x, y, z of the translation column
    np.testing.assert_allclose(T[-1, :3, 3], [-0.3203, -7.728, 393.56], atol=0.01)
    first_line = POSES_04.read_text().splitlines()[1].split()
    np.testing.assert_array_equal(T[1, :3, :].ravel(), [float(v) for v in first_line])
    path_length = np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1).sum()
    assert path_length == pytest.approx(393.6, abs=0.1)


def test_round_trip(tmp_path):
    T = random_poses(7)
    out = write_kitti_poses(tmp_path / "est.txt", T)
    assert out == tmp_path / "est.txt"
    lines = out.read_text().splitlines()
    assert len(lines) == 7 and all(len(line.split()) == 12 for line in lines)
    np.testing.assert_allclose(read_kitti_poses(out), T, rtol=1e-11, atol=1e-9)


def test_round_trip_of_sequence_04(tmp_path):
    T = read_kitti_poses(POSES_04)
    np.testing.assert_array_equal(read_kitti_poses(write_kitti_poses(tmp_path / "04.txt", T)), T)


def test_write_refuses_overwrite_and_leaves_no_temporary(tmp_path):
    path = write_kitti_poses(tmp_path / "a.txt", random_poses(2))
    with pytest.raises(DcslamError):
        write_kitti_poses(path, random_poses(3))
    assert len(read_kitti_poses(path)) == 2
    write_kitti_poses(path, random_poses(3), force=True)
    assert len(read_kitti_poses(path)) == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt"]


@pytest.mark.parametrize("bad", ["shape", "nan", "bottom", "scaled"])
def test_write_refuses_bad_poses(tmp_path, bad):
    T = random_poses(3)
    if bad == "shape":
        T = T[:, :3, :]
    elif bad == "nan":
        T[1, 0, 3] = np.nan
    elif bad == "bottom":
        T[2, 3, 0] = 0.5
    else:
        T[0, :3, :3] *= 1.1
    with pytest.raises(DcslamError):
        write_kitti_poses(tmp_path / "x.txt", T)
    assert not (tmp_path / "x.txt").exists()


def _line(T: np.ndarray) -> str:
    return " ".join(f"{v:.9e}" for v in T[:3, :].ravel())


@pytest.mark.parametrize("content, message", [
    ("", "no poses"),
    ("\n\n", "no poses"),
    ("1 0 0 0 0 1 0 0 0 0 1\n", "11 numbers"),
    ("1 0 0 0 0 1 0 0 0 0 1 0 7\n", "13 numbers"),
    ("1 0 0 0 0 1 0 0 0 0 1 x\n", "not a number"),
    ("1 0 0 nan 0 1 0 0 0 0 1 0\n", "non-finite"),
    ("1 0 0 0 0 1 0 0 0 0 1 inf\n", "non-finite"),
    ("2 0 0 0 0 1 0 0 0 0 1 0\n", "not orthonormal"),
    ("1 0.2 0 0 0 1 0 0 0 0 1 0\n", "not orthonormal"),
    ("-1 0 0 0 0 1 0 0 0 0 1 0\n", "determinant"),
])
def test_read_rejects_malformed(tmp_path, content, message):
    path = tmp_path / "bad.txt"
    path.write_text(_line(np.eye(4)) + "\n" + content if content.strip() else content)
    with pytest.raises(DcslamError, match=message):
        read_kitti_poses(path)


def test_read_missing_file(tmp_path):
    with pytest.raises(DcslamError, match="not found"):
        read_kitti_poses(tmp_path / "none.txt")


def test_read_names_the_line(tmp_path):
    path = tmp_path / "bad.txt"
    path.write_text(_line(np.eye(4)) + "\n" + _line(np.eye(4)) + "\n1 2 3\n")
    with pytest.raises(DcslamError, match=r"bad.txt:3: 3 numbers"):
        read_kitti_poses(path)
