import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.eval.maps import chamfer, read_points, score_map


def test_chamfer_known_answer():
    a = np.array([[0.0, 0, 0], [1, 0, 0]])
    b = np.array([[0.0, 0, 0], [1, 0, 0], [3, 0, 0]])
    scores = chamfer(a, b)
    # a→b: 0, 0 ; b→a: 0, 0, 2 (squared 4)
    assert scores.chamfer_m2 == pytest.approx(4 / 3)
    assert scores.accuracy_m == 0 and scores.completeness_m == pytest.approx(2 / 3)
    assert (scores.map_points, scores.gt_points) == (2, 3)


def test_chamfer_is_symmetric_and_zero_on_itself():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(50, 3)), rng.normal(size=(70, 3))
    assert chamfer(a, b).chamfer_m2 == pytest.approx(chamfer(b, a).chamfer_m2)
    assert chamfer(a, a).chamfer_m2 == 0


def test_bad_points():
    with pytest.raises(DcslamError, match=r"\(N, 3\)"):
        chamfer(np.zeros((3, 2)), np.zeros((3, 3)))
    with pytest.raises(DcslamError, match="no points"):
        chamfer(np.zeros((0, 3)), np.zeros((3, 3)))


def write_ply(path, points):
    header = ("ply\nformat ascii 1.0\n" f"element vertex {len(points)}\n"
              "property float x\nproperty float y\nproperty float z\nend_header\n")
    path.write_text(header + "".join(f"{x} {y} {z}\n" for x, y, z in points))
    return path


def test_ply_round_trip_and_score(tmp_path):
    a = write_ply(tmp_path / "a.ply", [[0, 0, 0], [1, 0, 0]])
    b = write_ply(tmp_path / "b.ply", [[0, 0, 0], [1, 0, 0], [3, 0, 0]])
    np.testing.assert_allclose(read_points(a), [[0, 0, 0], [1, 0, 0]])
    assert score_map(a, b).chamfer_m2 == pytest.approx(4 / 3)


def test_malformed_or_missing_ply(tmp_path):
    bad = tmp_path / "bad.ply"
    bad.write_text("not a ply file\n")
    with pytest.raises(DcslamError, match="no points"):
        read_points(bad)
    with pytest.raises(DcslamError, match="run `dcslam slam` first"):
        read_points(tmp_path / "missing.ply")
