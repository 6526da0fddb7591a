"""KITTI raw + depth-completion reading, against the real files of drive 2011_09_26_drive_0001_sync."""
from pathlib import Path

import cv2
import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.io import kitti
from dcslam.io.kitti_oxts import (OxtsPacket, mercator_to_lat_lon_alt, mercator_xyz, parse_oxts_line,
                                  write_oxts_dataformat)
from tests.fixtures.kitti import velodyne_raw_agreement

SAMPLE = Path(__file__).parents[1] / "data" / "kitti-sample"
DATE_DIR = SAMPLE / "raw" / "2011_09_26"
RAW = DATE_DIR / "2011_09_26_drive_0001_sync"
DEPTH = SAMPLE / "depth_completion" / "train" / "2011_09_26_drive_0001_sync" / "proj_depth"


@pytest.fixture(scope="module")
def calib():
    return kitti.read_calibration(DATE_DIR)


@pytest.fixture(scope="module")
def packets():
    return [kitti.read_oxts(RAW / "oxts" / "data" / kitti.frame_name(i, ".txt")) for i in range(108)]


class TestDepthPng:
    def test_round_trip_quantised_to_1_256_m(self, tmp_path):
        depth = np.random.default_rng(0).uniform(0, 200, (6, 9)) * (np.arange(54).reshape(6, 9) % 3 > 0)
        kitti.write_depth_png(tmp_path / "d.png", depth)
        back = kitti.read_depth_png(tmp_path / "d.png")
        assert back.dtype == np.float32 and back.shape == (6, 9)
        assert np.abs(back - depth).max() <= 0.5 / 256 + 1e-6
        assert np.array_equal(back == 0, depth == 0)

    def test_real_png_statistics(self):
        dense = kitti.read_depth_png(DEPTH / "groundtruth" / "image_02" / "0000000005.png")
        assert dense.shape == (375, 1242)
        assert (dense > 0).sum() == 90839  # as measured in SOURCES.md
        assert dense[dense > 0].min() == pytest.approx(5.332, abs=1e-3)

    def test_8bit_png_is_refused(self, tmp_path):
        cv2.imwrite(str(tmp_path / "d.png"), np.full((4, 5), 7, np.uint8))
        with pytest.raises(DcslamError, match="16-bit"):
            kitti.read_depth_png(tmp_path / "d.png")

    def test_truncated_png_is_refused(self, tmp_path):
        data = (DEPTH / "velodyne_raw" / "image_02" / "0000000005.png").read_bytes()
        (tmp_path / "d.png").write_bytes(data[:200])
        with pytest.raises(DcslamError, match="d.png"):
            kitti.read_depth_png(tmp_path / "d.png")

    def test_missing_png(self, tmp_path):
        with pytest.raises(DcslamError, match="not found"):
            kitti.read_depth_png(tmp_path / "none.png")


class TestOtherFormats:
    def test_image_round_trip(self, tmp_path):
        rgb = np.random.default_rng(1).integers(0, 256, (5, 7, 3), dtype=np.uint8)
        kitti.write_image(tmp_path / "i.png", rgb)
        assert np.array_equal(kitti.read_image(tmp_path / "i.png"), rgb)

    def test_real_image_is_rgb(self):
        rgb = kitti.read_image(RAW / "image_02" / "data" / "0000000005.png")
        assert rgb.shape == (375, 1242, 3) and rgb.dtype == np.uint8

    def test_velodyne_round_trip_and_bad_size(self, tmp_path):
        points = np.random.default_rng(2).normal(size=(10, 4)).astype(np.float32)
        kitti.write_velodyne(tmp_path / "v.bin", points)
        assert np.array_equal(kitti.read_velodyne(tmp_path / "v.bin"), points)
        (tmp_path / "bad.bin").write_bytes(b"\0" * 20)
        with pytest.raises(DcslamError, match="bad.bin"):
            kitti.read_velodyne(tmp_path / "bad.bin")

    def test_real_velodyne(self):
        points = kitti.read_velodyne(RAW / "velodyne_points" / "data" / "0000000005.bin")
        assert points.shape == (121948, 4)

    def test_timestamps_keep_nanoseconds(self, tmp_path):
        stamps = kitti.read_timestamps(RAW / "image_02" / "timestamps.txt")
        assert len(stamps) == 108 and np.all(np.diff(stamps) > 0.09)
        kitti.write_timestamps(tmp_path / "t.txt", stamps)
        # float64 POSIX seconds hold about 0.2 µs, not the file's nanoseconds
        assert (tmp_path / "t.txt").read_text().splitlines()[0].startswith("2011-09-26 13:02:25.961661")
        assert np.abs(kitti.read_timestamps(tmp_path / "t.txt") - stamps).max() < 1e-6

    def test_malformed_timestamp(self, tmp_path):
        (tmp_path / "t.txt").write_text("2011-09-26 13:02:25.9\nyesterday\n")
        with pytest.raises(DcslamError, match=r"t.txt:2"):
            kitti.read_timestamps(tmp_path / "t.txt")


class TestCalibration:
    def test_known_values(self, calib):
        assert calib.image_size == (375, 1242)
        assert calib.K_cam2 == pytest.approx(np.array([[721.5377, 0, 609.5593], [0, 721.5377, 172.854], [0, 0, 1]]))
        assert calib.T_velo_imu[:3, 3] == pytest.approx([-0.8086759, 0.3195559, -0.7997231])

    def test_chain_reproduces_kitti_projection(self, calib):
        # K · T_cam2_velo must equal P_rect_02 · R_rect_00 · T_cam0_velo (KITTI's projection) exactly.
        assert calib.K_cam2 @ calib.T_cam2_velo[:3] == pytest.approx(
            calib.P_rect_02 @ calib.R_rect_00 @ calib.T_cam0_velo, abs=1e-9)
        R = calib.T_cam2_imu[:3, :3]
        assert R @ R.T == pytest.approx(np.eye(3), abs=1e-5)

    def test_camera_2_offset_is_full_not_x_only(self, calib):
        t = calib.T_cam2_rect0[:3, 3]
        pykitti_x = calib.P_rect_02[0, 3] / calib.P_rect_02[0, 0]
        assert t[0] == pytest.approx(pykitti_x - calib.K_cam2[0, 2] * t[2] / calib.K_cam2[0, 0])
        assert t[1] == pytest.approx(2.16379e-1 / 721.5377 - 172.854 * 2.745884e-3 / 721.5377, rel=1e-5)
        assert t[2] == pytest.approx(2.745884e-3)
        assert np.linalg.norm(t - [pykitti_x, 0, 0]) == pytest.approx(3.6e-3, abs=0.05e-3)  # as documented

    def test_record_is_immutable(self, calib):
        with pytest.raises(ValueError):
            calib.P_rect_02[0, 0] = 1.0
        calib.K_cam2[0, 0] = 1.0  # a copy
        assert calib.P_rect_02[0, 0] == pytest.approx(721.5377)

    def _copy(self, tmp_path):
        for name in kitti.CALIB_FILES:
            (tmp_path / name).write_text((DATE_DIR / name).read_text())
        return tmp_path

    def test_missing_file(self, tmp_path):
        (self._copy(tmp_path) / "calib_imu_to_velo.txt").unlink()
        with pytest.raises(DcslamError, match="calib_imu_to_velo.txt not found"):
            kitti.read_calibration(tmp_path)

    @pytest.mark.parametrize("bad, match", [
        ("P_rect_02: 1 2 3\n", "P_rect_02 has 3 values, expected 12"),
        ("P_rect_02: 1 2 x 4 5 6 7 8 9 10 11 12\n", "not numbers"),
        ("garbage line\n", r"calib_cam_to_cam.txt:\d+: expected 'key: values'"),
    ])
    def test_malformed_entries(self, tmp_path, bad, match):
        path = self._copy(tmp_path) / "calib_cam_to_cam.txt"
        lines = [line for line in path.read_text().splitlines(keepends=True) if not line.startswith("P_rect_02")]
        path.write_text("".join(lines) + bad)
        with pytest.raises(DcslamError, match=match):
            kitti.read_calibration(tmp_path)

    def test_missing_entry(self, tmp_path):
        path = self._copy(tmp_path) / "calib_velo_to_cam.txt"
        path.write_text("".join(line for line in path.read_text().splitlines(True) if not line.startswith("T:")))
        with pytest.raises(DcslamError, match="missing entry 'T'"):
            kitti.read_calibration(tmp_path)


class TestProjectVelodyne:
    def test_reproduces_velodyne_raw_of_frame_5(self, calib):
        points = kitti.read_velodyne(RAW / "velodyne_points" / "data" / "0000000005.bin")
        projected = kitti.project_velodyne(points, calib)
        reference = kitti.read_depth_png(DEPTH / "velodyne_raw" / "image_02" / "0000000005.png")
        assert projected.shape == reference.shape == (375, 1242)
        assert velodyne_raw_agreement(projected, reference) >= 0.95
        measured = int((reference > 0).sum())
        assert abs(int((projected > 0).sum()) - measured) < 0.02 * measured

    def test_agreement_check_tells_a_shift_from_a_scale(self):
        """The shared check accepts the reference moved by 2 pixels and refuses it 3 % farther."""
        reference = kitti.read_depth_png(DEPTH / "velodyne_raw" / "image_02" / "0000000005.png")
        assert velodyne_raw_agreement(np.roll(reference, 2, axis=1), reference) >= 0.99
        assert velodyne_raw_agreement(reference * 1.03, reference) < 0.5
        with pytest.raises(ValueError, match="one shape"):
            velodyne_raw_agreement(reference[:10], reference)

    def test_known_point_and_nearest_wins(self, calib):
        T_velo_cam2 = np.linalg.inv(calib.T_cam2_velo)
        in_cam = np.array([[0.0, 0.0, 10.0, 1.0], [0.0, 0.0, 20.0, 1.0], [0.0, 0.0, -5.0, 1.0]])
        points = (in_cam @ T_velo_cam2.T)[:, :3]
        depth = kitti.project_velodyne(points, calib, image_size=(375, 1242))
        u, v = int(round(calib.K_cam2[0, 2])), int(round(calib.K_cam2[1, 2]))
        assert depth[v, u] == pytest.approx(10.0, abs=1e-5)
        assert (depth > 0).sum() == 1  # the far point is hidden, the one behind the camera dropped

    def test_shape_checked(self, calib):
        with pytest.raises(DcslamError, match=r"\(N, 3\) or \(N, 4\)"):
            kitti.project_velodyne(np.zeros((4, 2)), calib)


class TestOxts:
    def test_fields_of_a_real_packet(self, packets):
        first = packets[0]
        assert first.lat == 49.015003823272 and first.lon == 8.4342971002335
        assert first.yaw == pytest.approx(-2.6087069803847)
        assert (first.navstat, first.numsats, first.posmode, first.velmode, first.orimode) == (4, 11, 6, 6, 6)
        assert isinstance(first.numsats, int)

    def test_line_round_trip(self, tmp_path, packets):
        kitti.write_oxts(tmp_path / "p.txt", packets[7])
        assert kitti.read_oxts(tmp_path / "p.txt") == packets[7]

    @pytest.mark.parametrize("line, match", [("1 2 3", "3 fields, expected 30"), (" ".join(["1"] * 31), "31 fields"),
                                             (" ".join(["1"] * 29 + ["x"]), "not numbers")])
    def test_malformed_packets(self, tmp_path, line, match):
        (tmp_path / "p.txt").write_text(line + "\n")
        with pytest.raises(DcslamError, match=match):
            kitti.read_oxts(tmp_path / "p.txt")

    def test_path_length_and_speeds(self, packets):
        T = kitti.oxts_to_T_world_imu(packets)
        assert T.shape == (108, 4, 4) and np.array_equal(T[0, :3, 3], np.zeros(3))
        steps = np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1)
        assert steps.sum() == pytest.approx(106.97, abs=0.05)
        stamps = kitti.read_timestamps(RAW / "oxts" / "timestamps.txt")
        speed = np.array([np.hypot(p.vf, p.vl) for p in packets])
        logged = 0.5 * (speed[1:] + speed[:-1]) * np.diff(stamps)
        assert np.median(np.abs(steps / logged - 1)) < 0.02
        assert np.abs(steps / logged - 1).max() < 0.05

    def test_mercator_known_answer(self):
        scale = np.cos(np.deg2rad(49.0))
        xyz = mercator_xyz([49.0, 49.001], [8.0, 8.001], [100.0, 101.0], scale)
        d = xyz[1] - xyz[0]
        assert d[0] == pytest.approx(scale * 6378137.0 * np.deg2rad(0.001))
        assert d[1] == pytest.approx(6378137.0 * np.deg2rad(0.001), rel=1e-4)  # 1/cos(lat) · cos(lat0) ≈ 1
        assert d[2] == 1.0

    def test_mercator_inverse(self):
        scale = np.cos(np.deg2rad(49.0))
        lat, lon, alt = [49.0, 49.01, 48.99], [8.0, 8.4, 7.9], [100.0, 101.0, 99.5]
        back = mercator_to_lat_lon_alt(mercator_xyz(lat, lon, alt, scale), scale)
        np.testing.assert_allclose(np.stack(back), [lat, lon, alt], rtol=0, atol=1e-11)

    def test_packet_from_values_and_dataformat_file(self, tmp_path, packets):
        assert OxtsPacket.from_values(packets[3].values()) == packets[3]
        assert isinstance(OxtsPacket.from_values(np.array(packets[3].values(), float)).numsats, int)
        write_oxts_dataformat(tmp_path / "dataformat.txt")
        assert (tmp_path / "dataformat.txt").read_bytes() == (RAW / "oxts" / "dataformat.txt").read_bytes()

    def test_camera_poses(self, packets, calib):
        T_world_imu = kitti.oxts_to_T_world_imu(packets)
        T_world_cam = kitti.camera_poses(T_world_imu, calib)
        assert np.array_equal(T_world_cam[0], np.eye(4))
        # the same rigid offset between camera and IMU at every frame
        offset = T_world_cam @ calib.T_cam2_imu @ np.linalg.inv(T_world_imu)
        assert np.abs(offset - offset[0]).max() < 1e-6  # calibration rotations are orthonormal to ~1e-7
        # the car drives forward: the camera moves along its own +z, about 107 m
        assert T_world_cam[-1, 2, 3] > 100 and abs(T_world_cam[-1, 1, 3]) < 2
        R = T_world_cam[:, :3, :3]
        assert np.abs(R @ R.transpose(0, 2, 1) - np.eye(3)).max() < 1e-9

    def test_parse_names_the_file(self):
        with pytest.raises(DcslamError, match="^somewhere: 2 fields"):
            parse_oxts_line("1 2", "somewhere")


class TestDrives:
    def test_find_sample_drive(self, tmp_path):
        drives = kitti.find_drives(SAMPLE)
        assert [d.name for d in drives] == ["2011_09_26_drive_0001_sync"]
        d = drives[0]
        assert (d.date, d.number, d.source, d.has_raw) == ("2011_09_26", "0001", "kitti", True)
        assert d.depth_dir == SAMPLE / "depth_completion" / "train" / d.name
        assert kitti.find_drives(tmp_path) == []

    def test_synthetic_marker(self, tiny_root):
        assert kitti.find_drives(tiny_root)[0].source == "kitti"
        (tiny_root / kitti.SYNTHETIC_MARKER).write_text("generated by dcslam synth\n")
        assert kitti.find_drives(tiny_root)[0].source == "synthetic"

    def test_incomplete_sample_is_refused(self):
        # the committed sample has one image but 108 image timestamps
        with pytest.raises(DcslamError, match="108 timestamps but 1 images"):
            kitti.index_drive(kitti.find_drives(SAMPLE)[0])

    def test_index_real_drive(self, real_root):
        index = kitti.index_drive(kitti.find_drives(real_root)[0])
        assert len(index) == 98 and index.frame_ids[0] == 5 and index.frame_ids[-1] == 102
        stamps = kitti.read_timestamps(RAW / "image_02" / "timestamps.txt")
        assert np.array_equal(index.timestamps, stamps[5:103])
        assert np.array_equal(index.T_world_cam[0], np.eye(4))
        # poses are the raw-frame poses re-based at frame 5
        all_poses = kitti.camera_poses(kitti.oxts_to_T_world_imu(
            [kitti.read_oxts(RAW / "oxts" / "data" / kitti.frame_name(i, ".txt")) for i in range(108)]), index.calib)
        assert index.T_world_cam == pytest.approx(np.linalg.inv(all_poses[5]) @ all_poses[5:103], abs=1e-9)
        assert index.head(3).frame_ids.tolist() == [5, 6, 7]
        with pytest.raises(DcslamError):
            index.head(0)

    def test_read_real_frames(self, real_root):
        index = kitti.index_drive(kitti.find_drives(real_root)[0]).head(2)
        frames = list(kitti.read_drive(index))
        assert [f.frame_id for f in frames] == [5, 6]
        first = frames[0]
        assert first.rgb.shape == (375, 1242, 3)
        sparse = kitti.read_depth_png(DEPTH / "velodyne_raw" / "image_02" / "0000000005.png")
        assert np.array_equal(first.sparse, sparse)
        assert np.array_equal(first.dense, kitti.read_depth_png(DEPTH / "groundtruth" / "image_02" / "0000000005.png"))
        assert first.timestamp == index.timestamps[0]

    def test_tiny_drive(self, tiny_root):
        index = kitti.index_drive(kitti.find_drives(tiny_root)[0])
        assert index.frame_ids.tolist() == [5, 6, 7, 8]
        assert [f.rgb.shape for f in kitti.read_drive(index)] == [(32, 48, 3)] * 4


def _tiny(root):
    return kitti.find_drives(root)[0]


class TestBadDrives:
    """Every malformed drive fails with one message naming the offending file."""

    def test_missing_calibration(self, tiny_root):
        (tiny_root / "raw" / "2011_09_26" / "calib_velo_to_cam.txt").unlink()
        with pytest.raises(DcslamError, match="calib_velo_to_cam.txt not found"):
            kitti.index_drive(_tiny(tiny_root))

    def test_timestamps_lines_differ_from_images(self, tiny_root):
        path = tiny_root / "raw" / "2011_09_26" / "2011_09_26_drive_0002_sync" / "image_02" / "timestamps.txt"
        path.write_text("\n".join(path.read_text().splitlines()[:-1]) + "\n")
        with pytest.raises(DcslamError, match="timestamps.txt: 13 timestamps but 14 images"):
            kitti.index_drive(_tiny(tiny_root))

    def test_missing_image_in_the_middle(self, tiny_root):
        drive = _tiny(tiny_root)
        drive.image_path(3).unlink()
        drive.image_path(13).rename(drive.image_path(14))
        path = drive.raw_dir / "image_02" / "timestamps.txt"
        path.write_text("\n".join(path.read_text().splitlines()[:-1]) + "\n")
        with pytest.raises(DcslamError, match="not frames 0..12"):
            kitti.index_drive(drive)

    def test_oxts_packet_with_wrong_field_count(self, tiny_root):
        drive = _tiny(tiny_root)
        drive.oxts_path(4).write_text("49.0 8.4 116.0\n")
        with pytest.raises(DcslamError, match=r"0000000004.txt: 3 fields, expected 30"):
            kitti.index_drive(drive)

    def test_oxts_count_differs(self, tiny_root):
        drive = _tiny(tiny_root)
        drive.oxts_path(13).unlink()
        with pytest.raises(DcslamError, match="13 OXTS packets but 14 images"):
            kitti.index_drive(drive)

    def test_depth_kinds_differ(self, tiny_root):
        drive = _tiny(tiny_root)
        drive.depth_path("groundtruth", 6).unlink()
        with pytest.raises(DcslamError, match="differ at 0000000006.png"):
            kitti.index_drive(drive)

    def test_depth_frame_without_raw_frame(self, tiny_root):
        drive = _tiny(tiny_root)
        for kind in ("velodyne_raw", "groundtruth"):
            kitti.write_depth_png(drive.depth_path(kind, 20), np.ones((32, 48)))
        with pytest.raises(DcslamError, match="0000000020.png has no raw frame"):
            kitti.index_drive(drive)

    def test_8bit_depth_png(self, tiny_root):
        drive = _tiny(tiny_root)
        cv2.imwrite(str(drive.depth_path("groundtruth", 7)), np.full((32, 48), 9, np.uint8))
        index = kitti.index_drive(drive)
        with pytest.raises(DcslamError, match=r"0000000007.png: expected a 16-bit"):
            list(kitti.read_drive(index))

    def test_truncated_depth_png(self, tiny_root):
        drive = _tiny(tiny_root)
        path = drive.depth_path("velodyne_raw", 5)
        path.write_bytes(path.read_bytes()[:40])
        with pytest.raises(DcslamError, match=r"0000000005.png: not a readable PNG"):
            list(kitti.read_drive(kitti.index_drive(drive)))

    def test_depth_size_differs_from_image(self, tiny_root):
        drive = _tiny(tiny_root)
        kitti.write_depth_png(drive.depth_path("groundtruth", 8), np.ones((30, 48)))
        with pytest.raises(DcslamError, match="0000000008.png: depth is 48x30 but image"):
            list(kitti.read_drive(kitti.index_drive(drive)))

    def test_no_depth_folder(self, tiny_root):
        import shutil

        shutil.rmtree(tiny_root / "depth_completion")
        drive = _tiny(tiny_root)
        assert drive.depth_dir is None
        with pytest.raises(DcslamError, match="no depth folder"):
            kitti.index_drive(drive)
