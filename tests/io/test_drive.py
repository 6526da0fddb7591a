"""Drive files (DriveWriter / DriveFile) and depth-layer files."""
import json

import h5py
import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.io.drive import (DRIVE_SCHEMA, DriveFile, DriveFrame, DriveWriter, Layer, list_drives, load_depth,
                             read_layer_for,
                             read_layer, read_splits, write_layer)

H, W = 6, 10
K = np.array([[50.0, 0, 5], [0, 50, 3], [0, 0, 1]])


def make_frames(n: int, seed: int = 0) -> list[DriveFrame]:
    rng = np.random.default_rng(seed)
    frames = []
    for i in range(n):
        T = np.eye(4)
        T[:3, 3] = rng.normal(size=3)
        dense = (rng.uniform(1, 80, (H, W)) * (rng.random((H, W)) < 0.5)).astype(np.float32)
        frames.append(DriveFrame(rgb=rng.integers(0, 256, (H, W, 3), dtype=np.uint8), sparse=dense * (dense > 40),
                            dense=dense, T_world_cam=T, timestamp=100.0 + 0.1 * i, frame_id=5 + i))
    return frames


def write(path, frames, **kw):
    with DriveWriter(path, K, H, W, source="synthetic", date="2011_09_26", drive="d1", split="train", **kw) as w:
        for frame in frames:
            w.append(frame)
    return path


def _files(folder):
    return sorted(p.name for p in folder.iterdir())


class TestDriveRoundTrip:
    def test_round_trip(self, tmp_path):
        frames = make_frames(3)
        write(tmp_path / "d1.h5", frames)
        with DriveFile(tmp_path / "d1.h5") as drive:
            assert len(drive) == 3 and drive.shape == (3, H, W) and drive.name == "d1"
            assert drive.attrs == {"schema": DRIVE_SCHEMA, "source": "synthetic", "date": "2011_09_26",
                                   "drive": "d1", "split": "train"}
            assert np.array_equal(drive.K, K)
            for original, back in zip(frames, drive):
                assert np.array_equal(back.rgb, original.rgb)
                assert np.array_equal(back.sparse, original.sparse)
                assert np.array_equal(back.dense, original.dense)
                assert np.array_equal(back.T_world_cam, original.T_world_cam)
                assert back.timestamp == original.timestamp and back.frame_id == original.frame_id
            assert drive.frame_ids.dtype == np.int64 and drive.frame_ids.tolist() == [5, 6, 7]
            assert np.array_equal(load_depth(drive, "dense"), np.stack([f.dense for f in frames]))
            with pytest.raises(DcslamError, match="unknown depth kind"):
                drive.depth("fused", 0)

    def test_schema_on_disk(self, tmp_path):
        write(tmp_path / "d1.h5", make_frames(2))
        with h5py.File(tmp_path / "d1.h5", "r") as h5:
            expect = {"rgb": ((2, H, W, 3), np.uint8), "depth/sparse": ((2, H, W), np.float32),
                      "depth/dense": ((2, H, W), np.float32), "T_world_cam": ((2, 4, 4), np.float64),
                      "K": ((3, 3), np.float64), "timestamps": ((2,), np.float64), "frame_ids": ((2,), np.int64)}
            for name, (shape, dtype) in expect.items():
                assert h5[name].shape == shape and h5[name].dtype == dtype, name
            for name in ("rgb", "depth/sparse", "depth/dense"):
                assert h5[name].chunks[0] == 1 and h5[name].compression == "gzip"
            assert h5.attrs["schema"] == DRIVE_SCHEMA

    def test_no_overwrite_without_force(self, tmp_path):
        write(tmp_path / "d1.h5", make_frames(2))
        with pytest.raises(DcslamError, match="exists; pass --force"):
            write(tmp_path / "d1.h5", make_frames(1))
        write(tmp_path / "d1.h5", make_frames(1), force=True)
        with DriveFile(tmp_path / "d1.h5") as drive:
            assert len(drive) == 1


class TestDriveWriterChecks:
    @pytest.mark.parametrize("change, match", [
        (dict(rgb=np.zeros((H, W, 3), np.float32)), "rgb has dtype float32"),
        (dict(rgb=np.zeros((H, W + 1, 3), np.uint8)), r"rgb has shape \(6, 11, 3\)"),
        (dict(dense=np.full((H, W), np.nan, np.float32)), "dense depth must be finite and >= 0"),
        (dict(sparse=-np.ones((H, W), np.float32)), "sparse depth must be finite and >= 0"),
        (dict(T_world_cam=np.eye(3)), r"T_world_cam has shape \(3, 3\)"),
    ])
    def test_bad_frame_leaves_no_file(self, tmp_path, change, match):
        good = make_frames(2)
        bad = DriveFrame(**{**good[1].__dict__, **change})
        with pytest.raises(DcslamError, match=match):
            write(tmp_path / "d1.h5", [good[0], bad])
        assert _files(tmp_path) == []

    def test_bad_K_and_no_frames(self, tmp_path):
        with pytest.raises(DcslamError, match=r"K has shape \(2, 2\)"):
            DriveWriter(tmp_path / "d.h5", np.eye(2), H, W, source="kitti", date="", drive="d")
        with pytest.raises(DcslamError, match="no frames"):
            write(tmp_path / "d1.h5", [])
        assert _files(tmp_path) == []

    def test_interrupted_write_leaves_nothing(self, tmp_path):
        frames = make_frames(3)
        with pytest.raises(KeyboardInterrupt):
            with DriveWriter(tmp_path / "d1.h5", K, H, W, source="kitti", date="", drive="d1") as w:
                w.append(frames[0])
                w.append(frames[1])
                raise KeyboardInterrupt
        assert _files(tmp_path) == []

    def test_interrupted_overwrite_keeps_the_old_file(self, tmp_path):
        write(tmp_path / "d1.h5", make_frames(2))
        with pytest.raises(RuntimeError):
            with DriveWriter(tmp_path / "d1.h5", K, H, W, source="kitti", date="", drive="d1", force=True) as w:
                w.append(make_frames(1)[0])
                raise RuntimeError("boom")
        assert _files(tmp_path) == ["d1.h5"]
        with DriveFile(tmp_path / "d1.h5") as drive:
            assert len(drive) == 2


class TestMalformedDriveFiles:
    def test_missing(self, tmp_path):
        with pytest.raises(DcslamError, match="run `dcslam prepare-kitti` first"):
            DriveFile(tmp_path / "none.h5")

    def test_not_hdf5(self, tmp_path):
        (tmp_path / "d.h5").write_text("not an HDF5 file")
        with pytest.raises(DcslamError, match="not a readable HDF5 drive file"):
            DriveFile(tmp_path / "d.h5")

    def test_wrong_schema(self, tmp_path):
        with h5py.File(tmp_path / "d.h5", "w") as h5:
            h5.attrs["schema"] = "something/else"
        with pytest.raises(DcslamError, match="schema is 'something/else'"):
            DriveFile(tmp_path / "d.h5")

    def test_missing_dataset(self, tmp_path):
        write(tmp_path / "d.h5", make_frames(2))
        with h5py.File(tmp_path / "d.h5", "a") as h5:
            del h5["frame_ids"]
        with pytest.raises(DcslamError, match="missing dataset.*frame_ids"):
            DriveFile(tmp_path / "d.h5")

    def test_inconsistent_shapes(self, tmp_path):
        write(tmp_path / "d.h5", make_frames(2))
        with h5py.File(tmp_path / "d.h5", "a") as h5:
            del h5["T_world_cam"]
            h5["T_world_cam"] = np.tile(np.eye(4), (3, 1, 1))
        with pytest.raises(DcslamError, match=r"d.h5: T_world_cam has 3 frames where the other datasets have 2"):
            DriveFile(tmp_path / "d.h5")

    def test_one_dataset_short_of_a_frame_is_the_one_blamed(self, tmp_path):
        write(tmp_path / "d.h5", make_frames(4))
        with h5py.File(tmp_path / "d.h5", "a") as h5:
            dense = h5["depth/dense"][:3]
            del h5["depth/dense"]
            h5["depth/dense"] = dense
        with pytest.raises(DcslamError) as error:
            DriveFile(tmp_path / "d.h5")
        assert str(error.value) == (f"{tmp_path / 'd.h5'}: depth/dense has 3 frames where the other datasets have 4; "
                                    "remake the drive file with `dcslam prepare-kitti --force`")

    @pytest.mark.parametrize("name, value, match", [
        ("T_world_cam", np.nan, "T_world_cam is not finite at frame 1"),
        ("timestamps", np.inf, "timestamps is not finite at frame 1"),
        ("K", np.nan, "K is not finite; remake"),
    ])
    def test_non_finite_poses_and_intrinsics(self, tmp_path, name, value, match):
        write(tmp_path / "d.h5", make_frames(3))
        with h5py.File(tmp_path / "d.h5", "a") as h5:
            data = h5[name][()]
            data.reshape(-1)[data[0].size if data.ndim > 1 and name != "K" else 1] = value
            del h5[name]
            h5[name] = data
        with pytest.raises(DcslamError, match=match):
            DriveFile(tmp_path / "d.h5")

    def test_wrong_dtype(self, tmp_path):
        write(tmp_path / "d.h5", make_frames(2))
        with h5py.File(tmp_path / "d.h5", "a") as h5:
            rgb = h5["rgb"][()].astype(np.float32)
            del h5["rgb"]
            h5["rgb"] = rgb
        with pytest.raises(DcslamError, match="rgb has dtype float32, expected uint8"):
            DriveFile(tmp_path / "d.h5")

    def test_bad_depth_is_named_by_file_and_frame_when_read(self, tmp_path):
        write(tmp_path / "d.h5", make_frames(3))
        with h5py.File(tmp_path / "d.h5", "a") as h5:
            h5["depth/sparse"][2, 0, 0] = -1.0
        with DriveFile(tmp_path / "d.h5") as drive:
            drive.depth("sparse", 1)
            with pytest.raises(DcslamError, match=r"d.h5: depth/sparse: frame 2 holds negative depths \(1 pixels\)"):
                drive.depth("sparse", 2)



def with_extra(frames, kinds):
    out = []
    for k, f in enumerate(frames):
        extra = {kind: (f.dense * (j + 1) * 0.5 + k).astype(np.float32) for j, kind in enumerate(kinds)}
        out.append(DriveFrame(f.rgb, f.sparse, f.dense, f.T_world_cam, f.timestamp, f.frame_id, extra))
    return out


class TestExtraDepth:
    KINDS = ("sparse@16", "sparse@8", "exact")

    def test_round_trip(self, tmp_path):
        frames = with_extra(make_frames(3), self.KINDS)
        write(tmp_path / "d1.h5", frames, extra=self.KINDS)
        with DriveFile(tmp_path / "d1.h5") as drive:
            assert set(drive.kinds) == {"sparse", "dense", *self.KINDS}
            assert drive.attrs["sparse_beams"].tolist() == [16, 8]
            for original, back in zip(frames, drive):
                assert set(back.extra) == set(self.KINDS)
                for kind in self.KINDS:
                    assert np.array_equal(back.extra[kind], original.extra[kind])
            assert np.array_equal(load_depth(drive, "sparse@8"), np.stack([f.extra["sparse@8"] for f in frames]))
        with h5py.File(tmp_path / "d1.h5") as h5:
            assert h5["depth/sparse_16"].attrs["beams"] == 16 and h5["depth/exact"].attrs["synthetic_only"]

    def test_old_files_read_and_name_what_is_missing(self, tmp_path):
        write(tmp_path / "d1.h5", make_frames(2))
        with DriveFile(tmp_path / "d1.h5") as drive:
            assert drive.kinds == ("sparse", "dense") and "sparse_beams" not in drive.attrs
            assert drive.frame(0).extra == {}
            with pytest.raises(DcslamError, match=r"holds no sparse@16 depth.*prepare-kitti --beams 16 --force"):
                drive.depth("sparse@16", 0)
            with pytest.raises(DcslamError, match="holds no exact depth.*generated drives only"):
                load_depth(drive, "exact")

    @pytest.mark.parametrize("kind", ["sparse@", "sparse@x", "sparse@0", "dense@16", "exactly"])
    def test_unknown_kinds(self, tmp_path, kind):
        with pytest.raises(DcslamError, match="unknown depth kind"):
            DriveWriter(tmp_path / "d1.h5", K, H, W, source="kitti", date="d", drive="d", extra=(kind,))

    def test_frame_without_its_extra_depth_leaves_no_file(self, tmp_path):
        frames = make_frames(2)
        with pytest.raises(DcslamError, match="expects"):
            write(tmp_path / "d1.h5", frames, extra=("exact",))
        bad = with_extra(frames, ("exact",))
        bad[1].extra["exact"][0, 0] = np.nan
        with pytest.raises(DcslamError, match="exact depth must be finite"):
            write(tmp_path / "d1.h5", bad, extra=("exact",))
        assert _files(tmp_path) == []

    @pytest.mark.parametrize("damage, match", [
        (lambda h5: h5["depth/sparse_16"].attrs.__setitem__("beams", 32), "records beams=32, expected 16"),
        (lambda h5: h5.attrs.__setitem__("sparse_beams", [16, 32]), "sparse_beams is"),
        (lambda h5: h5.create_dataset("depth/fused", data=np.zeros((3, H, W), np.float32)), "depth/fused"),
        (lambda h5: (h5.__delitem__("depth/exact"), h5.create_dataset("depth/exact", data=np.zeros((2, H, W)))),
         r"depth/exact has shape \(2, 6, 10\)"),
    ])
    def test_malformed(self, tmp_path, damage, match):
        write(tmp_path / "d1.h5", with_extra(make_frames(3), ("sparse@16", "exact")), extra=("sparse@16", "exact"))
        with h5py.File(tmp_path / "d1.h5", "r+") as h5:
            damage(h5)
        with pytest.raises(DcslamError, match=match):
            DriveFile(tmp_path / "d1.h5")

class TestLayers:
    @pytest.mark.parametrize("value, kinds", [(np.nan, "NaN"), (np.inf, "infinite"), (-2.0, "negative")])
    def test_non_finite_or_negative_depth_is_refused_naming_file_and_frame(self, tmp_path, value, kinds):
        import h5py

        depth = np.ones((3, H, W), np.float32)
        write_layer(tmp_path / "l.h5", Layer(depth, drive="d1.h5", made_by="x"))
        with h5py.File(tmp_path / "l.h5", "a") as h5:
            h5["depth"][1, 2, :3] = value
        with pytest.raises(DcslamError) as error:
            read_layer(tmp_path / "l.h5")
        assert str(error.value) == (f"{tmp_path / 'l.h5'}: frame 1 holds {kinds} depths (3 pixels); depth must be "
                                    "finite and >= 0 (0 = no value): remake the file")

    def test_round_trip(self, tmp_path):
        depth = np.random.default_rng(0).uniform(0, 50, (3, H, W)).astype(np.float32)
        write_layer(tmp_path / "l.h5", Layer(depth, drive="d1.h5", made_by="run-a", config={"lr": 1e-3}))
        layer = read_layer(tmp_path / "l.h5", expect_frames=3)
        assert np.array_equal(layer.depth, depth) and layer.depth.dtype == np.float32
        assert (layer.drive, layer.made_by, layer.config) == ("d1.h5", "run-a", {"lr": 1e-3})
        with pytest.raises(DcslamError, match="exists"):
            write_layer(tmp_path / "l.h5", layer)

    def test_frame_count_mismatch(self, tmp_path):
        write(tmp_path / "d1.h5", make_frames(3))
        write_layer(tmp_path / "l.h5", Layer(np.ones((2, H, W), np.float32), drive="d1.h5", made_by="x"))
        with pytest.raises(DcslamError, match="layer has 2 frames but its drive has 3"):
            read_layer(tmp_path / "l.h5", expect_frames=3)
        with DriveFile(tmp_path / "d1.h5") as drive:
            with pytest.raises(DcslamError, match="2 frames but its drive has 3"):
                load_depth(drive, tmp_path / "l.h5")
        write_layer(tmp_path / "m.h5", Layer(np.ones((3, H, W + 1), np.float32), drive="d1.h5", made_by="x"))
        with DriveFile(tmp_path / "d1.h5") as drive:
            with pytest.raises(DcslamError, match="layer frames are"):
                load_depth(drive, tmp_path / "m.h5")
            write_layer(tmp_path / "ok.h5", Layer(np.ones((3, H, W), np.float32), drive="d1.h5", made_by="x"))
            assert load_depth(drive, tmp_path / "ok.h5").shape == (3, H, W)

    @pytest.mark.parametrize("depth, match", [(np.full((1, 2, 2), np.nan), "finite"),
                                              (-np.ones((1, 2, 2)), ">= 0"), (np.ones((2, 2)), r"\(N, H, W\)")])
    def test_bad_layer_depth(self, tmp_path, depth, match):
        with pytest.raises(DcslamError, match=match):
            write_layer(tmp_path / "l.h5", Layer(depth, drive="d", made_by="x"))
        assert _files(tmp_path) == []

    def test_malformed_layer_files(self, tmp_path):
        with pytest.raises(DcslamError, match="not found; run `dcslam predict`"):
            read_layer(tmp_path / "none.h5")
        (tmp_path / "text.h5").write_text("hello")
        with pytest.raises(DcslamError, match="not a readable HDF5 layer"):
            read_layer(tmp_path / "text.h5")
        write(tmp_path / "drive.h5", make_frames(1))
        with pytest.raises(DcslamError, match="not a dcslam depth layer"):
            read_layer(tmp_path / "drive.h5")



class TestLayerOfItsDrive:
    """A layer is read for one drive and refused, in one line naming the file, when it was made for another."""

    def test_frame_ids_round_trip_and_a_layer_of_this_drive_is_read(self, tmp_path):
        drive_path = write(tmp_path / "d1.h5", make_frames(3))
        depth = np.ones((3, H, W), np.float32)
        write_layer(tmp_path / "l.h5", Layer(depth, drive="d1", made_by="x", frame_ids=np.array([5, 6, 7])))
        with DriveFile(drive_path) as drive:
            layer = read_layer_for(drive, tmp_path / "l.h5")
            assert layer.frame_ids.tolist() == [5, 6, 7] and np.array_equal(load_depth(drive, tmp_path / "l.h5"),
                                                                             depth)

    @pytest.mark.parametrize("name, frame_ids, match", [
        ("d2", [5, 6, 7], r"l\.h5: a layer of drive 'd2', not of 'd1' \(.*d1\.h5\); run `dcslam predict`"),
        ("d1.h5", [5, 6, 9], r"l\.h5: layer frame 2 is KITTI frame 9, its drive's 7 \(.*d1\.h5\)"),
    ])
    def test_a_layer_of_another_drive_under_this_drives_name(self, tmp_path, name, frame_ids, match):
        drive_path = write(tmp_path / "d1.h5", make_frames(3))
        write_layer(tmp_path / "l.h5", Layer(np.ones((3, H, W), np.float32), drive=name, made_by="x",
                                             frame_ids=np.array(frame_ids)))
        with DriveFile(drive_path) as drive, pytest.raises(DcslamError, match=match) as error:
            load_depth(drive, tmp_path / "l.h5")
        assert "\n" not in str(error.value)

    def test_malformed_frame_ids(self, tmp_path):
        with pytest.raises(DcslamError, match=r"frame_ids have shape \(2,\), expected \(3,\)"):
            write_layer(tmp_path / "l.h5", Layer(np.ones((3, H, W), np.float32), drive="d1", made_by="x",
                                                 frame_ids=np.array([5, 6])))
        write_layer(tmp_path / "l.h5", Layer(np.ones((3, H, W), np.float32), drive="d1", made_by="x"))
        with h5py.File(tmp_path / "l.h5", "a") as h5:
            h5["frame_ids"] = np.array([5, 6])
        with pytest.raises(DcslamError, match=r"l\.h5: frame_ids of shape \(2,\), expected \(3,\)"):
            read_layer(tmp_path / "l.h5")


class TestLayerConfidence:
    def test_round_trip_and_old_layers(self, tmp_path):
        rng = np.random.default_rng(1)
        depth = rng.uniform(0, 50, (3, H, W)).astype(np.float32)
        confidence = rng.uniform(0, 1, (3, H, W)).astype(np.float32)
        write_layer(tmp_path / "c.h5", Layer(depth, drive="d1.h5", made_by="nconv", confidence=confidence))
        layer = read_layer(tmp_path / "c.h5", expect_frames=3)
        assert np.array_equal(layer.confidence, confidence) and np.array_equal(layer.depth, depth)
        with h5py.File(tmp_path / "c.h5") as h5:
            assert h5["confidence"].dtype == np.float32 and h5["confidence"].chunks == (1, H, W)
        write_layer(tmp_path / "old.h5", Layer(depth, drive="d1.h5", made_by="sparse-conv"))
        assert read_layer(tmp_path / "old.h5").confidence is None

    @pytest.mark.parametrize("confidence, match", [
        (np.full((3, H, W), 1.5, np.float32), r"within \[0, 1\]"),
        (np.full((3, H, W), np.nan, np.float32), "finite"),
        (np.ones((2, H, W), np.float32), "like its depth"),
    ])
    def test_bad_confidence(self, tmp_path, confidence, match):
        depth = np.ones((3, H, W), np.float32)
        with pytest.raises(DcslamError, match=match):
            write_layer(tmp_path / "c.h5", Layer(depth, drive="d", made_by="x", confidence=confidence))
        assert _files(tmp_path) == []
        write_layer(tmp_path / "c.h5", Layer(depth, drive="d", made_by="x"))
        with h5py.File(tmp_path / "c.h5", "r+") as h5:
            h5.create_dataset("confidence", data=confidence)
        with pytest.raises(DcslamError, match=match):
            read_layer(tmp_path / "c.h5")


class TestListingAndSplits:
    def test_list_drives_skips_temporary_files(self, tmp_path):
        write(tmp_path / "b.h5", make_frames(1))
        write(tmp_path / "a.h5", make_frames(1))
        (tmp_path / ".c.h5.tmp-1.h5").write_text("")
        (tmp_path / "splits.json").write_text("{}")
        assert [p.name for p in list_drives(tmp_path)] == ["a.h5", "b.h5"]

    def test_read_splits(self, tmp_path):
        (tmp_path / "s.json").write_text(json.dumps({"train": ["a"], "val": [], "test": ["b"]}))
        assert read_splits(tmp_path / "s.json")["test"] == ["b"]
        (tmp_path / "bad.json").write_text("{train")
        with pytest.raises(DcslamError, match="not valid JSON"):
            read_splits(tmp_path / "bad.json")
        (tmp_path / "shape.json").write_text(json.dumps({"train": ["a"], "test": []}))
        with pytest.raises(DcslamError, match="expected"):
            read_splits(tmp_path / "shape.json")
        with pytest.raises(DcslamError, match="prepare-kitti"):
            read_splits(tmp_path / "none.json")
