"""TUM RGB-D and ICL-NUIM sequences: lists, associations, depth PNGs, pose lookup, sequence indexing, errors."""
import cv2
import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.io import tum_rgbd as tr
from dcslam.io.tum import quaternion_to_rotation, read_tum, write_tum

H, W = 6, 8


def pose(t: float) -> np.ndarray:
    """A smooth known motion: constant velocity, constant rate about a fixed axis."""
    T = np.eye(4)
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    angle = 0.4 * t
    T[:3, :3] = quaternion_to_rotation(np.append(axis * np.sin(angle / 2), np.cos(angle / 2)))
    T[:3, 3] = [0.2 * t, -0.1 * t, 1.0 + 0.05 * t]
    return T


def write_tum_sequence(root, rgb_times, depth_times, gt_times, size=(H, W)):
    """A TUM RGB-D folder: rgb.txt, depth.txt, groundtruth.txt and tiny images."""
    root.mkdir(parents=True)
    names = {"rgb": [], "depth": []}
    rng = np.random.default_rng(0)
    for kind, times in (("rgb", rgb_times), ("depth", depth_times)):
        for t in times:
            name = f"{kind}/{t:.6f}.png"
            names[kind].append(name)
            if kind == "rgb":
                tr.write_rgb_png(root / name, rng.integers(0, 255, (*size, 3), dtype=np.uint8))
            else:
                tr.write_depth_png(root / name, rng.uniform(0.5, 4.0, size))
        tr.write_list(root / f"{kind}.txt", np.array(times), names[kind], f"{kind} images")
    write_tum(root / "groundtruth.txt", np.array(gt_times), np.stack([pose(t) for t in gt_times]))
    return root


def write_icl_sequence(root, frames=4, gt_from=0, K=None, size=(H, W)):
    """An ICL-NUIM folder through :class:`IclWriter` (poses of :func:`pose` at t = frame number)."""
    writer = tr.IclWriter(root, "livingRoom0.gt.freiburg", K)
    rng = np.random.default_rng(1)
    for k in range(frames):
        writer.append(rng.integers(0, 255, (*size, 3), dtype=np.uint8), rng.uniform(0.5, 4.0, size), pose(k))
    writer.close()
    if gt_from:  # as the real download: no pose for the first frame(s)
        times, T = read_tum(root / "livingRoom0.gt.freiburg")
        write_tum(root / "livingRoom0.gt.freiburg", times[gt_from:], T[gt_from:], force=True)
    return root


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
        with pytest.raises(DcslamError, match="not a readable image"):
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


class TestPoses:
    def test_interpolates_between_close_poses(self):
        gt_t = np.arange(0.0, 1.0, 0.01)
        T, found = tr.interpolate_poses(np.array([0.123, 0.5]), gt_t, np.stack([pose(t) for t in gt_t]))
        assert found.all()
        for k, t in enumerate([0.123, 0.5]):
            assert np.abs(T[k] - pose(t)).max() < 1e-9  # lerp / slerp are exact for this motion

    def test_nearest_within_tolerance_across_a_gap_else_none(self):
        gt_t = np.array([0.0, 1.0, 2.0])
        T_gt = np.stack([pose(t) for t in gt_t])
        T, found = tr.interpolate_poses(np.array([-0.5, 0.01, 1.0, 1.5, 2.019, 2.5]), gt_t, T_gt)
        assert found.tolist() == [False, True, True, False, True, False]
        assert np.array_equal(T[1], T_gt[0]) and np.array_equal(T[2], T_gt[1]) and np.array_equal(T[4], T_gt[2])


class TestIndexSequence:
    def test_tum(self, tmp_path):
        rgb_t = [10.0 + 0.033 * k for k in range(6)]
        depth_t = [t + 0.004 for t in rgb_t[:5]] + [rgb_t[5] + 0.03]  # the last depth has no partner
        root = write_tum_sequence(tmp_path / "rgbd_dataset_freiburg1_xyz", rgb_t, depth_t,
                                  list(np.arange(9.9, 10.3, 0.01)))
        seq = tr.index_sequence(root)
        assert seq.format == tr.TUM and seq.name == "rgbd_dataset_freiburg1_xyz" and len(seq) == 5
        assert np.array_equal(seq.K, tr.TUM_K) and seq.groundtruth == root / "groundtruth.txt"
        assert seq.timestamps == pytest.approx(depth_t[:5]) and seq.frame_ids.tolist() == [0, 1, 2, 3, 4]
        assert [p.name for p in seq.rgb_paths] == [f"{t:.6f}.png" for t in rgb_t[:5]]
        for k, t in enumerate(depth_t[:5]):  # pose at the depth timestamp, interpolated
            assert np.abs(seq.T_world_cam[k] - pose(t)).max() < 1e-6
        assert any("1 of 6 depth images have no colour image" in n for n in seq.notes)
        rgb, depth = next(seq.frames())
        assert rgb.shape == (H, W, 3) and depth.shape == (H, W) and depth.dtype == np.float32

    def test_icl_negative_fy_and_trajectory_round_trip(self, tmp_path):
        root = write_icl_sequence(tmp_path / "living_room_traj0_frei_png", frames=4)
        seq = tr.index_sequence(root)
        assert seq.format == tr.ICL and seq.K[1, 1] == -480.0 and np.array_equal(seq.K, tr.ICL_K)
        assert seq.timestamps.tolist() == [0, 1, 2, 3] and len(seq) == 4
        assert np.abs(seq.T_world_cam - np.stack([pose(k) for k in range(4)])).max() < 1e-9
        assert (root / "associations.txt").read_text().splitlines()[0] == "0 depth/0.png 0 rgb/0.png"

    def test_icl_groundtruth_in_parent_and_first_frame_without_pose(self, tmp_path):
        root = write_icl_sequence(tmp_path / "living_room_traj2n_frei_png", frames=5, gt_from=1)
        (root / "livingRoom0.gt.freiburg").rename(tmp_path / "livingRoom2.gt.freiburg")
        seq = tr.index_sequence(root)
        assert seq.groundtruth == tmp_path / "livingRoom2.gt.freiburg"
        assert seq.frame_ids.tolist() == [1, 2, 3, 4] and seq.timestamps.tolist() == [1, 2, 3, 4]
        assert any("1 frame(s) without a ground-truth pose" in n for n in seq.notes)
        assert seq.subsample(2).frame_ids.tolist() == [1, 3] and seq.subsample(1, 2).frame_ids.tolist() == [1, 2]

    def test_intrinsics_given_then_file_then_default(self, tmp_path):
        K = tr.make_K(100.0, -90.0, 3.5, 2.5)
        root = write_icl_sequence(tmp_path / "living_room_traj0_frei_png", K=K)
        assert np.array_equal(tr.index_sequence(root).K, K)                      # intrinsics.txt
        assert np.array_equal(tr.index_sequence(root, intrinsics=tr.TUM_K).K, tr.TUM_K)
        (root / tr.INTRINSICS_FILE).unlink()
        assert np.array_equal(tr.index_sequence(root).K, tr.ICL_K)

    def test_missing_image(self, tmp_path):
        root = write_icl_sequence(tmp_path / "living_room_traj0_frei_png")
        (root / "rgb" / "2.png").unlink()
        with pytest.raises(DcslamError, match=r"rgb/2.png not found \(listed in .*associations.txt\)"):
            tr.index_sequence(root)

    def test_missing_tum_depth_image(self, tmp_path):
        root = write_tum_sequence(tmp_path / "seq", [1.0, 1.1], [1.0, 1.1], [0.9, 1.0, 1.05, 1.1, 1.2])
        (root / "depth" / "1.100000.png").unlink()
        with pytest.raises(DcslamError, match=r"1.100000.png not found \(listed in .*depth.txt\)"):
            tr.index_sequence(root)

    def test_unsorted_association(self, tmp_path):
        root = write_icl_sequence(tmp_path / "living_room_traj0_frei_png")
        lines = (root / "associations.txt").read_text().splitlines()
        (root / "associations.txt").write_text("\n".join([lines[1], lines[0], *lines[2:]]) + "\n")
        with pytest.raises(DcslamError, match="associations.txt:2: .*strictly increasing"):
            tr.index_sequence(root)

    def test_no_groundtruth(self, tmp_path):
        root = write_icl_sequence(tmp_path / "living_room_traj3_frei_png")
        (root / "livingRoom0.gt.freiburg").unlink()
        with pytest.raises(DcslamError, match=r"no ground-truth trajectory .*livingRoom3.gt.freiburg"):
            tr.index_sequence(root)

    def test_no_pose_overlap(self, tmp_path):
        root = write_tum_sequence(tmp_path / "seq", [1.0, 1.1], [1.0, 1.1], [5.0, 5.01])
        with pytest.raises(DcslamError, match="no frame has a ground-truth pose"):
            tr.index_sequence(root)

    def test_not_a_sequence(self, tmp_path):
        (tmp_path / "empty").mkdir()
        with pytest.raises(DcslamError, match="not a TUM RGB-D or ICL-NUIM sequence"):
            tr.index_sequence(tmp_path / "empty")
        with pytest.raises(DcslamError, match="no TUM RGB-D or ICL-NUIM sequence in"):
            tr.find_sequences(tmp_path / "empty")
        with pytest.raises(DcslamError, match="is not a folder"):
            tr.find_sequences(tmp_path / "none")


def test_find_sequences_and_groundtruth_names(tmp_path):
    for name in ("living_room_traj1_frei_png", "living_room_traj0_frei_png"):
        write_icl_sequence(tmp_path / name, frames=1)
    (tmp_path / "notes").mkdir()
    assert [p.name for p in tr.find_sequences(tmp_path)] == ["living_room_traj0_frei_png",
                                                           "living_room_traj1_frei_png"]
    assert tr.find_sequences(tmp_path / "living_room_traj1_frei_png") == [tmp_path / "living_room_traj1_frei_png"]
    office = tmp_path / "traj2_frei_png"
    office.mkdir()
    (tmp_path / "traj2.gt.freiburg").write_text("0 0 0 0 0 0 0 1\n")
    assert tr.find_groundtruth(office) == tmp_path / "traj2.gt.freiburg"
    one = tmp_path / "living_room_traj0_frei_png"
    (one / "other.gt.freiburg").write_text("0 0 0 0 0 0 0 1\n")
    assert tr.find_groundtruth(one) == one / "livingRoom0.gt.freiburg"  # of two, the one named as ICL-NUIM's
    (one / "livingRoom0.gt.freiburg").rename(one / "third.gt.freiburg")
    with pytest.raises(DcslamError, match="2 \\*.gt.freiburg files"):
        tr.find_groundtruth(one)
    (one / "groundtruth.txt").write_text("0 0 0 0 0 0 0 1\n")
    assert tr.find_groundtruth(one) == one / "groundtruth.txt"
