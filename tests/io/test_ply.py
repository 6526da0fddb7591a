import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.io.ply import read_ply, write_ply


def _cloud(n=50, seed=0):
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(n, 3)).astype(np.float32)
    normals = rng.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    colors = rng.random((n, 3))
    return points, normals.astype(np.float32), colors


def test_round_trip(tmp_path):
    points, normals, colors = _cloud()
    path = write_ply(tmp_path / "map.ply", points, normals, colors)
    p, n, c = read_ply(path)
    np.testing.assert_array_equal(p, points)
    np.testing.assert_array_equal(n, normals)
    np.testing.assert_array_equal(c, np.round(colors * 255).astype(np.uint8))


@pytest.mark.parametrize("n", [0, 1, 7, 8, 9, 50])
def test_written_in_pieces_as_in_one(tmp_path, monkeypatch, n):
    """The file is written WRITE_CHUNK vertices at a time: a cloud of any length (the last piece short, or none at
    all) gives the bytes a one-piece write gives, colours outside [0, 1] clipped and uint8 colours as they are."""
    import dcslam.io.ply as ply

    points, normals, colors = _cloud(n, seed=n)
    colors = colors * 1.4 - 0.2                                     # some below 0, some above 1
    for rgb in (colors, (colors.clip(0, 1) * 255).astype(np.uint8), None):
        monkeypatch.setattr(ply, "WRITE_CHUNK", 1 << 16)
        whole = write_ply(tmp_path / "whole.ply", points, normals, rgb, force=True).read_bytes()
        monkeypatch.setattr(ply, "WRITE_CHUNK", 8)
        assert write_ply(tmp_path / "pieces.ply", points, normals, rgb, force=True).read_bytes() == whole
        p, _, c = read_ply(tmp_path / "pieces.ply")
        assert len(p) == n
        if rgb is not None and n:
            expected = rgb if rgb.dtype == np.uint8 else np.clip(np.round(rgb * 255), 0, 255).astype(np.uint8)
            np.testing.assert_array_equal(c, expected)


def test_points_only_round_trip(tmp_path):
    points, _, _ = _cloud(7)
    p, n, c = read_ply(write_ply(tmp_path / "p.ply", points))
    np.testing.assert_array_equal(p, points)
    assert n is None and c is None


def test_open3d_reads_points_normals_and_colours(tmp_path):
    o3d = pytest.importorskip("open3d")
    points, normals, colors = _cloud()
    path = write_ply(tmp_path / "map.ply", points, normals, colors)
    cloud = o3d.io.read_point_cloud(str(path))
    assert cloud.has_normals() and cloud.has_colors()
    np.testing.assert_allclose(np.asarray(cloud.points), points, atol=1e-6)
    np.testing.assert_allclose(np.asarray(cloud.normals), normals, atol=1e-6)
    np.testing.assert_allclose(np.asarray(cloud.colors), np.round(colors * 255) / 255, atol=1e-6)


def test_refuses_overwrite_without_force(tmp_path):
    points, _, _ = _cloud(3)
    path = write_ply(tmp_path / "p.ply", points)
    with pytest.raises(DcslamError, match="exists"):
        write_ply(path, points)
    write_ply(path, points * 2, force=True)
    np.testing.assert_array_equal(read_ply(path)[0], points * 2)


def test_rejects_bad_shapes_and_nan(tmp_path):
    with pytest.raises(DcslamError, match=r"\(P, 3\)"):
        write_ply(tmp_path / "a.ply", np.zeros((4, 2)))
    with pytest.raises(DcslamError, match="non-finite"):
        write_ply(tmp_path / "a.ply", np.full((2, 3), np.nan))
    assert not (tmp_path / "a.ply").exists()


@pytest.mark.parametrize("content, message", [
    (b"hello\n", "not a PLY"),
    (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
     b"end_header\n0 0 0\n", "unsupported PLY format"),
    (b"ply\nformat binary_little_endian 1.0\nelement face 1\nend_header\n", "unexpected element"),
    (b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
     b"property float z\nend_header\n" + b"\0" * 12, "truncated"),
])
def test_malformed_files(tmp_path, content, message):
    path = tmp_path / "bad.ply"
    path.write_bytes(content)
    with pytest.raises(DcslamError, match=message):
        read_ply(path)


def test_missing_file(tmp_path):
    with pytest.raises(DcslamError, match="not found"):
        read_ply(tmp_path / "none.ply")
