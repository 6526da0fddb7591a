"""prepare_kitti: KITTI roots (real sample, tiny generated ones) → drive files, splits.json, config."""
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.io import kitti
from dcslam.io.drive import DriveFile, read_splits
from dcslam.stages.prepare import THESIS_SPLITS, prepare_kitti, proportional_splits
from tests.fixtures import kitti as fx


@pytest.fixture
def tiny_root(tmp_path) -> Path:
    """A KITTI root with one small drive 2011_09_26_drive_0002_sync (in no thesis split): 14 frames, depth 5..8."""
    fx.write_tiny_drive(tmp_path / "tiny")
    return tmp_path / "tiny"


def _files(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir()) if folder.exists() else []


class TestSplits:
    def test_thesis_split(self):
        sizes = {k: len(v) for k, v in THESIS_SPLITS.items()}
        assert sizes == {"train": 15, "val": 4, "test": 6}
        names = sum(THESIS_SPLITS.values(), [])
        assert len(set(names)) == len(names)
        assert "2011_09_26_drive_0001_sync" in THESIS_SPLITS["test"]
        assert "2011_10_03_drive_0042_sync" in THESIS_SPLITS["train"]

    @pytest.mark.parametrize("n, sizes", [(24, (15, 4, 5)), (1, (0, 0, 1)), (2, (1, 0, 1)), (3, (1, 1, 1)),
                                          (5, (3, 1, 1)), (12, (7, 2, 3)), (48, (30, 8, 10))])
    def test_proportional(self, n, sizes):
        names = [f"d{i:03d}" for i in range(n)]
        splits = proportional_splits(list(reversed(names)))
        assert tuple(len(splits[k]) for k in ("train", "val", "test")) == sizes
        assert sorted(sum(splits.values(), [])) == names
        assert splits == proportional_splits(names)  # deterministic, independent of the order given


class TestPrepareReal:
    def test_real_drive(self, tmp_path):
        root = fx.link_real_drive(tmp_path / "kitti")
        result = prepare_kitti(root, tmp_path / "drives", max_frames=3)
        name = "2011_09_26_drive_0001_sync"
        assert result.source == "kitti"
        assert [(d.name, d.split, d.frames) for d in result.drives] == [(name, "test", 3)]
        assert _files(tmp_path / "drives") == [f"{name}.h5", "prepare-kitti.json", "splits.json"]
        assert read_splits(result.splits_path) == {"train": [], "val": [], "test": [name]}
        assert any("of the thesis split not found" in note for note in result.notes)
        index = kitti.index_drive(kitti.find_drives(root)[0])
        with DriveFile(tmp_path / "drives" / f"{name}.h5") as drive:
            assert drive.shape == (3, 375, 1242)
            assert drive.attrs == {"schema": "dcslam.drive/1", "source": "kitti", "date": "2011_09_26",
                                   "drive": name, "split": "test"}
            assert drive.frame_ids.tolist() == [5, 6, 7]
            assert np.array_equal(drive.poses[0], np.eye(4))
            assert np.allclose(drive.poses, index.T_world_cam[:3], atol=1e-12)
            assert np.array_equal(drive.timestamps, index.timestamps[:3])
            assert np.array_equal(drive.K, index.calib.K_cam2)
            assert np.array_equal(drive.rgb(1), kitti.read_image(fx.REAL_RAW / "image_02" / "data" / "0000000005.png"))
            sparse = kitti.read_depth_png(fx.REAL_DEPTH / "velodyne_raw" / "image_02" / "0000000005.png")
            assert np.array_equal(drive.depth("sparse", 2), sparse)
        config = json.loads(result.config_path.read_text())
        assert config["stage"] == "prepare-kitti" and config["settings"]["max_frames"] == 3

    def test_beams_from_the_real_scan(self, tmp_path):
        from dcslam.geometry.lidar_beams import keep_beams

        root = fx.link_real_drive(tmp_path / "kitti")
        scan_path = fx.REAL_RAW / "velodyne_points" / "data" / "0000000005.bin"
        name = "2011_09_26_drive_0001_sync"
        scans = root / "raw" / "2011_09_26" / name / "velodyne_points" / "data"
        scans.mkdir(parents=True)
        for i in (5, 6):
            (scans / kitti.frame_name(i, ".bin")).symlink_to(scan_path)
        result = prepare_kitti(root, tmp_path / "drives", max_frames=2, beams=(16, 64, 16))
        calib = kitti.read_calibration(root / "raw" / "2011_09_26")
        scan = kitti.read_velodyne(scan_path)
        with DriveFile(tmp_path / "drives" / f"{name}.h5") as drive:
            assert drive.kinds == ("sparse", "dense", "sparse@16", "sparse@64")
            assert drive.attrs["sparse_beams"].tolist() == [64, 16]
            assert np.array_equal(drive.depth("sparse@64", 1), kitti.project_velodyne(scan, calib))
            assert np.array_equal(drive.depth("sparse@16", 0), kitti.project_velodyne(keep_beams(scan, 16), calib))
            assert (drive.depth("sparse@16", 0) > 0).sum() < 0.3 * (drive.depth("sparse", 0) > 0).sum()
        assert json.loads(result.config_path.read_text())["settings"]["beams"] == [64, 16]

    def test_beams_need_the_scans(self, tmp_path):
        root = fx.link_real_drive(tmp_path / "kitti")
        with pytest.raises(DcslamError, match=r"0000000005.bin not found.*drop --beams"):
            prepare_kitti(root, tmp_path / "drives", max_frames=1, beams=(16,))
        with pytest.raises(DcslamError, match="--beams is 12; expected a divisor"):
            prepare_kitti(root, tmp_path / "drives", beams=(12,))
        assert _files(tmp_path / "drives") == []

    def test_malformed_scan(self, tmp_path):
        root = fx.link_real_drive(tmp_path / "kitti")
        scans = root / "raw" / "2011_09_26" / "2011_09_26_drive_0001_sync" / "velodyne_points" / "data"
        scans.mkdir(parents=True)
        (scans / "0000000005.bin").write_bytes(np.zeros(4 * 100, np.float32).tobytes())  # 100 points at the origin
        with pytest.raises(DcslamError, match=r"0000000005.bin: scan has fewer than 64 distinct elevation"):
            prepare_kitti(root, tmp_path / "drives", max_frames=1, beams=(16,))
        (scans / "0000000005.bin").write_bytes(b"\0" * 10)
        with pytest.raises(DcslamError, match="not a whole number"):
            prepare_kitti(root, tmp_path / "drives", max_frames=1, beams=(16,))

    def test_thesis_split_notes_and_unsplit(self, tmp_path):
        root = tmp_path / "kitti"
        for name in ("2011_09_26_drive_0011_sync", "2011_09_26_drive_0029_sync", "2011_09_26_drive_0002_sync"):
            fx.write_tiny_drive(root, name, n_frames=12)
        fx.write_tiny_drive(root, "2011_09_28_drive_0075_sync", n_frames=12, depth_split="val")
        result = prepare_kitti(root, tmp_path / "drives")
        assert result.splits == {"train": ["2011_09_26_drive_0011_sync", "2011_09_28_drive_0075_sync"],
                                 "val": ["2011_09_26_drive_0029_sync"], "test": []}
        assert not (tmp_path / "drives" / "2011_09_26_drive_0002_sync.h5").exists()
        assert any("in no split" in n and "2011_09_26_drive_0002_sync" in n for n in result.notes)
        again = prepare_kitti(root, tmp_path / "drives", include_unsplit=True, force=True)
        assert {d.name: d.split for d in again.drives}["2011_09_26_drive_0002_sync"] == ""
        with DriveFile(tmp_path / "drives" / "2011_09_26_drive_0002_sync.h5") as drive:
            assert drive.attrs["split"] == "" and drive.frame_ids.tolist() == [5, 6]

    def test_raw_only_and_depth_only_are_noted(self, tmp_path):
        root = tmp_path / "kitti"
        fx.write_tiny_drive(root, "2011_09_26_drive_0011_sync", n_frames=11)
        fx.write_tiny_drive(root, "2011_09_26_drive_0001_sync", n_frames=11)
        fx.write_tiny_drive(root, "2011_09_26_drive_0005_sync", n_frames=11)
        import shutil
        shutil.rmtree(root / "depth_completion" / "train" / "2011_09_26_drive_0001_sync")
        shutil.rmtree(root / "raw" / "2011_09_26" / "2011_09_26_drive_0005_sync")
        result = prepare_kitti(root, tmp_path / "drives")
        assert [d.name for d in result.drives] == ["2011_09_26_drive_0011_sync"]
        assert any("without depth-completion" in n and "0001" in n for n in result.notes)
        assert any("without raw" in n and "0005" in n for n in result.notes)


class TestPrepareSynthetic:
    def test_proportional_split_and_source(self, tmp_path):
        root = tmp_path / "kitti"
        names = [f"2011_09_26_drive_{i:04d}_sync" for i in range(1, 6)]
        for i, name in enumerate(names):
            fx.write_tiny_drive(root, name, n_frames=11, size=(16, 24), seed=i)
        (root / kitti.SYNTHETIC_MARKER).write_text("made by dcslam synth\n")
        result = prepare_kitti(root, tmp_path / "drives")
        assert result.source == "synthetic" and not result.notes
        assert result.splits == {"train": names[:3], "val": names[3:4], "test": names[4:]}
        for d in result.drives:
            with DriveFile(d.path) as drive:
                assert drive.attrs["source"] == "synthetic" and drive.attrs["split"] == d.split
                assert drive.frame_ids.tolist() == [5] and drive.shape == (1, 16, 24)

    def test_splits_file(self, tmp_path):
        root = tmp_path / "kitti"
        fx.write_tiny_drive(root, "2011_09_26_drive_0001_sync", n_frames=11)
        fx.write_tiny_drive(root, "2011_09_26_drive_0002_sync", n_frames=11)
        (tmp_path / "s.json").write_text(json.dumps({"train": ["2011_09_26_drive_0002_sync"], "val": [],
                                                     "test": ["2011_09_26_drive_0001_sync", "other_drive"]}))
        result = prepare_kitti(root, tmp_path / "drives", splits_file=tmp_path / "s.json")
        assert result.splits == {"train": ["2011_09_26_drive_0002_sync"], "val": [],
                                 "test": ["2011_09_26_drive_0001_sync"]}
        assert any("other_drive" in n for n in result.notes)
        (tmp_path / "bad.json").write_text('{"train": ["a"], "val": [], "test": ["a"]}')
        with pytest.raises(DcslamError, match="in both train and test"):
            prepare_kitti(root, tmp_path / "out2", splits_file=tmp_path / "bad.json")


class TestPrepareFailures:
    """Each failure names the file, and leaves no drive file (complete or partial) and no temporary file."""

    def test_no_data_suggests_synth(self, tmp_path):
        (tmp_path / "empty").mkdir()
        with pytest.raises(DcslamError, match=r"no KITTI drives under .*empty.*dcslam synth"):
            prepare_kitti(tmp_path / "empty", tmp_path / "drives")

    def test_missing_root_or_a_file_does_not_exist(self, tmp_path):
        with pytest.raises(DcslamError, match=r"KITTI root .*nowhere does not exist; pass --kitti DIR"):
            prepare_kitti(tmp_path / "nowhere", tmp_path / "drives")
        (tmp_path / "file").write_text("x")
        with pytest.raises(DcslamError, match=r"KITTI root .*file is a file, not a folder"):
            prepare_kitti(tmp_path / "file", tmp_path / "drives")
        assert not (tmp_path / "drives").exists()

    def test_out_a_regular_file_is_refused(self, tiny_root, tmp_path):
        (tmp_path / "out").write_text("mine")
        with pytest.raises(DcslamError, match=r"--out .*out is a file; pass a folder"):
            prepare_kitti(tiny_root, tmp_path / "out", include_unsplit=True)
        assert (tmp_path / "out").read_text() == "mine"

    def test_a_broken_second_drive_leaves_no_drive_and_the_rerun_completes(self, tmp_path):
        root = tmp_path / "two"
        fx.write_tiny_drive(root, name="2011_09_26_drive_0002_sync")
        fx.write_tiny_drive(root, name="2011_09_26_drive_0003_sync")
        second = kitti.find_drives(root)[1]
        png = second.depth_path("groundtruth", 8)
        good = png.read_bytes()
        png.write_bytes(good[:100])
        out = tmp_path / "drives"
        with pytest.raises(DcslamError, match="0000000008.png: not a readable PNG"):
            prepare_kitti(root, out, include_unsplit=True)
        assert _files(out) == []  # not even the first, complete drive
        png.write_bytes(good)
        result = prepare_kitti(root, out, include_unsplit=True)
        assert len(result.drives) == 2
        assert _files(out) == ["2011_09_26_drive_0002_sync.h5", "2011_09_26_drive_0003_sync.h5", "prepare-kitti.json",
                               "splits.json"]

    def test_existing_output_needs_force(self, tiny_root, tmp_path):
        out = tmp_path / "drives"
        first = prepare_kitti(tiny_root, out, include_unsplit=True)
        stamp = first.drives[0].path.stat().st_mtime_ns
        with pytest.raises(DcslamError, match="2011_09_26_drive_0002_sync.h5 exists; pass --force"):
            prepare_kitti(tiny_root, out, include_unsplit=True)
        assert first.drives[0].path.stat().st_mtime_ns == stamp
        prepare_kitti(tiny_root, out, include_unsplit=True, force=True)
        (out / "2011_09_26_drive_0002_sync.h5").unlink()
        with pytest.raises(DcslamError, match="splits.json exists"):  # checked before any drive is written
            prepare_kitti(tiny_root, out, include_unsplit=True)
        assert not (out / "2011_09_26_drive_0002_sync.h5").exists()

    @pytest.mark.parametrize("breakage, match", [
        ("calib", "calib_cam_to_cam.txt not found"),
        ("oxts", r"0000000003.txt: 29 fields, expected 30"),
        ("timestamps", "timestamps.txt: 15 timestamps but 14 images"),
        ("8bit", "0000000007.png: expected a 16-bit"),
        ("truncated", "0000000008.png: not a readable PNG"),
    ])
    def test_bad_input(self, tiny_root, tmp_path, breakage, match):
        drive = kitti.find_drives(tiny_root)[0]
        if breakage == "calib":
            (drive.date_dir / "calib_cam_to_cam.txt").unlink()
        elif breakage == "oxts":
            drive.oxts_path(3).write_text(" ".join(drive.oxts_path(3).read_text().split()[:29]) + "\n")
        elif breakage == "timestamps":
            path = drive.raw_dir / "image_02" / "timestamps.txt"
            path.write_text(path.read_text() + "2011-09-26 13:02:40.000000000\n")
        elif breakage == "8bit":
            cv2.imwrite(str(drive.depth_path("velodyne_raw", 7)), np.zeros((32, 48), np.uint8))
        else:
            path = drive.depth_path("groundtruth", 8)
            path.write_bytes(path.read_bytes()[:100])
        out = tmp_path / "drives"
        with pytest.raises(DcslamError, match=match):
            prepare_kitti(tiny_root, out, include_unsplit=True)
        assert _files(out) == []

    def test_interrupted_conversion_leaves_nothing(self, tiny_root, tmp_path, monkeypatch):
        calls = []
        real_read_image = kitti.read_image

        def interrupted(path):
            calls.append(path)
            if len(calls) == 3:
                raise KeyboardInterrupt
            return real_read_image(path)

        monkeypatch.setattr(kitti, "read_image", interrupted)
        out = tmp_path / "drives"
        with pytest.raises(KeyboardInterrupt):
            prepare_kitti(tiny_root, out, include_unsplit=True)
        assert len(calls) == 3 and _files(out) == []

    def test_exact_depth_round_trip_and_mismatch(self, tiny_root, tmp_path):
        drive = kitti.find_drives(tiny_root)[0]
        rng = np.random.default_rng(5)
        exact = {i: rng.uniform(1, 90, (32, 48)).astype(np.float32) for i in range(5, 9)}
        for i, depth in exact.items():
            kitti.write_depth_png(drive.exact_path(i), depth)
        result = prepare_kitti(tiny_root, tmp_path / "drives", include_unsplit=True)
        assert result.drives[0].exact
        with DriveFile(result.drives[0].path) as written:
            assert written.kinds == ("sparse", "dense", "exact")
            for k, i in enumerate(range(5, 9)):
                assert np.abs(written.depth("exact", k) - exact[i]).max() <= 0.5 / 256 + 1e-5
        drive.exact_path(8).unlink()
        with pytest.raises(DcslamError, match=r"dcslam_exact_synthetic: 3 frames but velodyne_raw has 4"):
            prepare_kitti(tiny_root, tmp_path / "other", include_unsplit=True)
        drive.exact_path(8).write_bytes(b"not a png")
        with pytest.raises(DcslamError, match="0000000008.png"):
            prepare_kitti(tiny_root, tmp_path / "other", include_unsplit=True)
        assert _files(tmp_path / "other") == []

    def test_max_frames_checked(self, tiny_root, tmp_path):
        with pytest.raises(DcslamError, match="at least 1"):
            prepare_kitti(tiny_root, tmp_path / "drives", max_frames=0)


def test_stage_run_uses_the_workspace_folders(tiny_root, tmp_path):
    from dcslam.stages.prepare import PrepareConfig, run
    from dcslam.workspace import Workspace

    ws = Workspace(tmp_path / "ws")
    result = run(ws, PrepareConfig(kitti=tiny_root, all_drives=True, max_frames=2))
    assert result.splits_path == ws.splits and [d.frames for d in result.drives] == [2]
    record = json.loads((ws.drives / "prepare-kitti.json").read_text())
    assert record["settings"]["max_frames"] == 2 and record["settings"]["include_unsplit"] is True
    with pytest.raises(DcslamError, match="--max-frames"):
        PrepareConfig(max_frames=0)
