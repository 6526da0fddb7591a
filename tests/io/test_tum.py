"""TUM trajectory files."""
import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.geometry.rotations import quaternion_to_rotation
from dcslam.io.tum import read_tum, write_tum


def random_poses(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = quaternion_to_rotation(rng.normal(size=(n, 4)))
    T[:, :3, 3] = rng.uniform(-500, 500, (n, 3))
    return T


class TestTumFile:
    def test_round_trip_random_poses(self, tmp_path):
        T = random_poses(200)
        stamps = 1.3e9 + np.cumsum(np.random.default_rng(1).uniform(0.01, 0.2, 200))
        write_tum(tmp_path / "t.txt", stamps, T)
        back_stamps, back = read_tum(tmp_path / "t.txt")
        assert np.abs(back - T).max() < 1e-9
        assert np.abs(back_stamps - stamps).max() < 1e-6
        assert (tmp_path / "t.txt").read_text().startswith("# timestamp tx ty tz qx qy qz qw\n")

    def test_comments_blank_lines_and_commas(self, tmp_path):
        (tmp_path / "t.txt").write_text("# header\n\n0.5 1 2 3 0 0 0 1\n1.0, 1, 2, 4, 0, 0, 0, 1\n")
        stamps, T = read_tum(tmp_path / "t.txt")
        assert stamps.tolist() == [0.5, 1.0] and T[1, :3, 3].tolist() == [1, 2, 4]

    @pytest.mark.parametrize("text, match", [
        ("0 1 2 3 0 0 1\n", r"t.txt:1: 7 fields, expected 8"),
        ("0 1 2 3 0 0 0 1\n1 1 2 3 0 0 zero 1\n", r"t.txt:2: not a number"),
        ("0 1 2 3 0 0 0 2\n", "norm 2.0000, expected 1"),
        ("0 1 2 3 0 0 0 1\n0 1 2 3 0 0 0 1\n", "not strictly increasing"),
        ("2 1 2 3 0 0 0 1\n1 1 2 3 0 0 0 1\n", "not strictly increasing"),
        ("0 nan 2 3 0 0 0 1\n", "pose 0 has non-finite values"),
        ("# only a comment\n", "no poses"),
    ])
    def test_malformed(self, tmp_path, text, match):
        (tmp_path / "t.txt").write_text(text)
        with pytest.raises(DcslamError, match=match):
            read_tum(tmp_path / "t.txt")

    def test_missing_file(self, tmp_path):
        with pytest.raises(DcslamError, match="not found"):
            read_tum(tmp_path / "none.txt")

    def test_write_checks(self, tmp_path):
        T = random_poses(3)
        with pytest.raises(DcslamError, match=r"\(N, 4, 4\)"):
            write_tum(tmp_path / "a.txt", np.arange(2.0), T)
        T[1, 0, 3] = np.inf
        with pytest.raises(DcslamError, match="non-finite"):
            write_tum(tmp_path / "a.txt", np.arange(3.0), T)
        assert not (tmp_path / "a.txt").exists()

    def test_no_overwrite_without_force(self, tmp_path):
        write_tum(tmp_path / "a.txt", np.arange(2.0), random_poses(2))
        with pytest.raises(DcslamError, match="exists"):
            write_tum(tmp_path / "a.txt", np.arange(2.0), random_poses(2, seed=1))
        write_tum(tmp_path / "a.txt", np.arange(2.0), random_poses(2, seed=1), force=True)
        assert read_tum(tmp_path / "a.txt")[1] == pytest.approx(random_poses(2, seed=1), abs=1e-9)
