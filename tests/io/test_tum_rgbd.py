"""TUM RGB-D and ICL-NUIM file formats: lists, associations, depth and colour PNGs, intrinsics (IclWriter round
trips through tests/io/test_tum_sequence.py)."""
import cv2
import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.io import tum_rgbd as tr


class TestLists:
    def test_round_trip(self, tmp_path):
        times = np.array([1305031102.175304, 1305031102.211214, 1305031102.243211])
        names = [f"rgb/{t:.6f}.png" for t in times]
        tr.write_list(tmp_path / "rgb.txt", times, names, "color images")
        back_times, back_names = tr.read_list(tmp_path / "rgb.txt")
        assert back_names == names and np.abs(back_times - times).max() < 1e-6
        assert (tmp_path / "rgb.txt").read_text().startswith("# color images\n# timestamp filename\n")

    def test_comments_and_blank_lines(self, tmp_path):
        (tmp_path / "depth.txt").write_text("# depth maps\n# file: 'x.bag'\n\n1.5 depth/a.png\n  \n2.5 depth/b.png\n")
        times, names = tr.read_list(tmp_path / "depth.txt")
        assert times.tolist() == [1.5, 2.5] and names == ["depth/a.png", "depth/b.png"]

    @pytest.mark.parametrize("text, match", [
        ("1.0 rgb/a.png extra\n", r"rgb.txt:1: 3 fields, expected 2"),
        ("1.0\n", r"rgb.txt:1: 1 fields, expected 2"),
        ("1.0 rgb/a.png\nnoon rgb/b.png\n", r"rgb.txt:2: timestamp 'noon' is not a number"),
        ("1.0 rgb/a.png\ninf rgb/b.png\n", r"rgb.txt:2: timestamp 'inf' is not finite"),
        ("2.0 rgb/a.png\n1.0 rgb/b.png\n", r"rgb.txt:2: timestamp 1.0 is not after the previous one"),
        ("1.0 rgb/a.png\n1.0 rgb/b.png\n", "strictly increasing"),
        ("# nothing\n", "no entries"),
    ])
    def test_malformed(self, tmp_path, text, match):
        (tmp_path / "rgb.txt").write_text(text)
        with pytest.raises(DcslamError, match=match):
            tr.read_list(tmp_path / "rgb.txt")

    def test_missing_file_and_unsorted_writes(self, tmp_path):
        with pytest.raises(DcslamError, match="not found"):
            tr.read_list(tmp_path / "rgb.txt")
        with pytest.raises(DcslamError, match="strictly increasing"):
            tr.write_list(tmp_path / "rgb.txt", np.array([2.0, 1.0]), ["a", "b"])
        assert not (tmp_path / "rgb.txt").exists()


class TestAssociations:
    def test_round_trip_icl_order(self, tmp_path):
        t = np.arange(3.0)
        depth, rgb = [f"depth/{i}.png" for i in range(3)], [f"rgb/{i}.png" for i in range(3)]
        tr.write_associations(tmp_path / "associations.txt", t, depth, t, rgb)
        assert (tmp_path / "associations.txt").read_text().splitlines()[1] == "1 depth/1.png 1 rgb/1.png"
        td, nd, trgb, nrgb = tr.read_associations(tmp_path / "associations.txt")
        assert td.tolist() == [0, 1, 2] and nd == depth and trgb.tolist() == [0, 1, 2] and nrgb == rgb

    def test_rgb_first_order_of_associate_py(self, tmp_path):
        (tmp_path / "associations.txt").write_text("1.01 rgb/a.png 1.0 depth/a.png\n2.02 rgb/b.png 2.0 depth/b.png\n")
        td, nd, trgb, nrgb = tr.read_associations(tmp_path / "associations.txt")
        assert td.tolist() == [1.0, 2.0] and nd == ["depth/a.png", "depth/b.png"]
        assert trgb.tolist() == [1.01, 2.02] and nrgb == ["rgb/a.png", "rgb/b.png"]

    @pytest.mark.parametrize("text, match", [
        ("0 depth/0.png 0\n", r"associations.txt:1: 3 fields, expected 4 \('timestamp depth/N.png"),
        ("0 depth/0.png 0 rgb/0.png\n1 depth/1.png x rgb/1.png\n", r"associations.txt:2: timestamp 'x'"),
        ("0 depth/0.png 0 rgb/0.png\n2 depth/2.png 2 rgb/2.png\n1 depth/1.png 1 rgb/1.png\n",
         r"associations.txt:3: .*strictly increasing"),
        ("\n# empty\n", "no entries"),
    ])
    def test_malformed(self, tmp_path, text, match):
        (tmp_path / "associations.txt").write_text(text)
        with pytest.raises(DcslamError, match=match):
            tr.read_associations(tmp_path / "associations.txt")


class TestAssociate:
    def test_nearest_one_to_one_within_tolerance(self):
        a = np.array([0.0, 0.033, 0.066, 0.1])
        b = np.array([0.001, 0.03, 0.031, 0.2])
        ia, ib = tr.associate(a, b)
        assert ia.tolist() == [0, 1] and ib.tolist() == [0, 2]  # 0.066 is 0.035 from 0.031: too far

    def test_closest_pair_wins_a_shared_candidate(self):
        ia, ib = tr.associate(np.array([0.0, 0.01]), np.array([0.006]))
        assert ia.tolist() == [1] and ib.tolist() == [0]

    def test_empty(self):
        ia, ib = tr.associate(np.array([0.0]), np.array([1.0]))
        assert ia.shape == ib.shape == (0,)


class TestImages:
    def test_depth_round_trip(self, tmp_path):
        depth = np.array([[0.0, 0.0002, 1.0], [2.5, 13.107, 14.0]])
        tr.write_depth_png(tmp_path / "d.png", depth)
        raw = cv2.imread(str(tmp_path / "d.png"), cv2.IMREAD_UNCHANGED)
        assert raw.dtype == np.uint16 and raw.tolist() == [[0, 1, 5000], [12500, 65535, 0]]  # beyond 13.1 m: none
        back = tr.read_depth_png(tmp_path / "d.png")
        assert back.dtype == np.float32 and np.allclose(back, [[0, 0.0002, 1], [2.5, 13.107, 0]], atol=1e-6, rtol=0)

    def test_depth_wrong_dtype(self, tmp_path):
        cv2.imwrite(str(tmp_path / "eight.png"), np.zeros((4, 5), np.uint8))
        cv2.imwrite(str(tmp_path / "colour16.png"), np.zeros((4, 5, 3), np.uint16))
        with pytest.raises(DcslamError, match=r"eight.png: expected a 16-bit single-channel depth PNG .*uint8"):
            tr.read_depth_png(tmp_path / "eight.png")
        with pytest.raises(DcslamError, match=r"colour16.png: expected a 16-bit single-channel .*\(4, 5, 3\)"):
            tr.read_depth_png(tmp_path / "colour16.png")

    def test_rgb_round_trip_grey_and_wrong_dtype(self, tmp_path):
        rgb = np.random.default_rng(0).integers(0, 255, (4, 5, 3), dtype=np.uint8)
        tr.write_rgb_png(tmp_path / "c.png", rgb)
        assert np.array_equal(tr.read_rgb_png(tmp_path / "c.png"), rgb)
        cv2.imwrite(str(tmp_path / "grey.png"), rgb[..., 0])
        assert np.array_equal(tr.read_rgb_png(tmp_path / "grey.png"), np.repeat(rgb[..., :1], 3, 2))
        cv2.imwrite(str(tmp_path / "deep.png"), np.zeros((4, 5, 3), np.uint16))
        with pytest.raises(DcslamError, match="expected an 8-bit colour image, got uint16"):
            tr.read_rgb_png(tmp_path / "deep.png")

    def test_unreadable_and_missing(self, tmp_path):
        (tmp_path / "broken.png").write_bytes(b"\x89PNG not really")
        with pytest.raises(DcslamError, match="not a readable PNG"):
            tr.read_depth_png(tmp_path / "broken.png")
        with pytest.raises(DcslamError, match="not found"):
            tr.read_rgb_png(tmp_path / "none.png")


class TestIntrinsics:
    def test_parse_negative_fy(self):
        K = tr.parse_intrinsics("481.2,-480,319.5,239.5")
        assert K.tolist() == [[481.2, 0, 319.5], [0, -480.0, 239.5], [0, 0, 1]]
        assert np.array_equal(K, tr.ICL_K) and tr.ICL_K[1, 1] < 0

    @pytest.mark.parametrize("text", ["1,2,3", "a,b,c,d", "525,0,319.5,239.5", "1,2,3,nan"])
    def test_bad(self, text):
        with pytest.raises(DcslamError, match="intrinsics"):
            tr.parse_intrinsics(text, "--intrinsics")

    def test_file_round_trip(self, tmp_path):
        tr.write_intrinsics(tmp_path / "intrinsics.txt", tr.ICL_K)
        assert np.array_equal(tr.read_intrinsics(tmp_path / "intrinsics.txt"), tr.ICL_K)
