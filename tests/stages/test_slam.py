"""The slam stage: run() on a tiny workspace returns per-drive summaries and writes the configuration it ran."""
import json
import os

import numpy as np
import pytest

from dcslam.io.kitti_poses import read_kitti_poses
from dcslam.io.tum import read_tum

from dcslam.errors import DcslamError
from dcslam.stages.slam import SlamStageConfig, run


def test_gt_slam_over_the_test_drive_writes_outputs_and_config(ws):
    config = SlamStageConfig(odometry="gt", frames=2, voxel_size=0.1)
    results = run(ws, config)
    assert [r.drive for r in results] == ["drive_d"] and results[0].summary["frames"] == 2
    out = ws.slam / "dense"
    assert {p.name for p in out.iterdir()} == {"drive_d.txt", "drive_d.kitti.txt", "drive_d.ply", "drive_d.json",
                                               "drive_d.done"}
    _, T_tum = read_tum(out / "drive_d.txt")
    T_kitti = read_kitti_poses(out / "drive_d.kitti.txt")
    assert T_kitti.shape == (2, 4, 4) and np.allclose(T_kitti, T_tum, atol=1e-9)
    settings = json.loads((out / "drive_d.json").read_text())["settings"]
    assert settings["odometry"] == "gt" and settings["voxel_size"] == 0.1 and settings["frames"] == 2
    assert settings["source"] == "dense"
    with pytest.raises(DcslamError, match="--force"):
        run(ws, config)
    assert run(ws, config, force=True)[0].summary["translation_error_m"]["final"] < 1e-5


def test_layer_references_resolve_through_the_one_resolver(ws):
    with pytest.raises(DcslamError, match="predictions/r1 not found; run `dcslam predict` first"):
        run(ws, SlamStageConfig(depth="predicted", run="r1", odometry="gt"))
    with pytest.raises(DcslamError, match="no layers in"):
        run(ws, SlamStageConfig(depth="predicted", odometry="gt"))
    with pytest.raises(DcslamError, match="drive file .*nowhere.h5 not found"):
        run(ws, SlamStageConfig(drive=["nowhere"], odometry="gt"))
    assert not ws.slam.exists()


def test_a_layer_of_another_drive_under_this_drives_name_is_refused(ws):
    from dcslam.io.drive import DriveFile, Layer, write_layer

    with DriveFile(ws.drives / "drive_c.h5") as other:
        depth = np.stack([other.depth("dense", i) for i in range(len(other))])
        write_layer(ws.predictions / "copied" / "drive_d.h5", Layer(depth, drive=other.name, made_by="copied",
                                                                    frame_ids=other.frame_ids))
    with pytest.raises(DcslamError, match=r"drive_d\.h5: a layer of drive 'drive_c', not of 'drive_d'"):
        run(ws, SlamStageConfig(depth="predicted", run="copied", odometry="gt", frames=2))
    assert not (ws.slam / "copied").exists()


def test_an_empty_test_split_is_an_error(ws):
    ws.splits.write_text(json.dumps({"train": ["drive_a"], "val": ["drive_c"], "test": []}))
    with pytest.raises(DcslamError, match=r"splits\.json: no test drives; pass --drive"):
        run(ws, SlamStageConfig(odometry="gt", frames=2))
    assert not ws.slam.exists()


def test_sparse_of_fewer_beams_and_exact_depth(tmp_path):
    import json

    from dcslam.workspace import Workspace
    from tests.fixtures.depth import write_workspace

    ws = Workspace(write_workspace(tmp_path / "ws", extra=True))
    for kind in ("sparse@16", "exact"):
        (result,) = run(ws, SlamStageConfig(depth=kind, odometry="gt", frames=2, voxel_size=0.1))
        summary = json.loads((ws.slam / kind / "drive_d.json").read_text())
        assert summary["settings"]["depth"] == kind and summary["points"] == result.summary["points"]
    sixteen = json.loads((ws.slam / "sparse@16" / "drive_d.json").read_text())["points"]
    exact = json.loads((ws.slam / "exact" / "drive_d.json").read_text())["points"]
    assert exact > 0 and sixteen < exact  # two LiDAR rows per frame give (almost) no map points with normals


class TestConfidenceUse:
    depth = np.array([[5.0, 6.0, 0.0], [7.0, 8.0, 9.0]], np.float32)
    confidence = np.array([[0.9, 0.2, 0.0], [0.5, 0.0, 1.0]], np.float32)

    def test_weights_drop_below_the_minimum_and_weight_the_rest(self):
        from dcslam.slam.drive import ConfidenceUse

        depth, weight = ConfidenceUse("weights", 0.3).apply(self.depth, self.confidence)
        assert depth.tolist() == [[5, 0, 0], [7, 0, 9]]
        assert weight.tolist() == [[np.float32(0.9), 0, 0], [0.5, 0, 1]]

    def test_mask_and_ignore(self):
        from dcslam.slam.drive import ConfidenceUse

        depth, weight = ConfidenceUse("mask", 0.3).apply(self.depth, self.confidence)
        assert depth.tolist() == [[5, 0, 0], [7, 0, 9]] and weight is None
        depth, weight = ConfidenceUse("ignore", 0.0).apply(self.depth, self.confidence)
        assert depth is self.depth and weight is None
        depth, weight = ConfidenceUse("weights", 0.3).apply(self.depth, None)
        assert depth is self.depth and weight is None

    def test_config_checks(self):
        with pytest.raises(DcslamError, match="unknown confidence use"):
            SlamStageConfig(confidence="sometimes")
        with pytest.raises(DcslamError, match="within"):
            SlamStageConfig(min_confidence=2.0)
        with pytest.raises(DcslamError, match="needs --confidence weights or mask"):
            SlamStageConfig(confidence="ignore", min_confidence=0.2)
        with pytest.raises(DcslamError, match="give one above 0"):
            SlamStageConfig(confidence="mask")


def test_a_room_run_records_its_effective_settings(tmp_path):
    """A room (median depth ~2 m) runs at settings scaled down from the street's: the summary keeps the requested
    ones under settings and the ones used under effective_settings."""
    from dcslam.io.drive import DriveFile
    from dcslam.stages.prepare_tum import PrepareTumConfig, run as prepare
    from dcslam.synth.indoor import generate_indoor
    from dcslam.workspace import Workspace

    ws = Workspace(tmp_path / "room")
    generate_indoor(ws.root / "tum", sequences=1, frames=3, seed=1, scale=0.1)
    prepare(ws, PrepareTumConfig())
    (result,) = run(ws, SlamStageConfig(depth="dense", odometry="icp"))
    summary = json.loads((ws.slam / "dense" / f"{result.drive}.json").read_text())
    requested, effective = summary["settings"], summary["effective_settings"]
    assert requested["voxel_size"] == 0.2 and requested["source_voxel"] == 0.2 and requested["max_distance"] == 0.5
    with DriveFile(ws.drives / f"{result.drive}.h5") as drive:
        depth = drive.depth("dense", 0)
    median = float(np.median(depth[depth > 0]))
    assert effective["first_frame_median_depth"] == pytest.approx(median, rel=0.1)
    scale = effective["scene_scale"]
    assert scale == pytest.approx(effective["first_frame_median_depth"] / 12.0) and 0.05 < scale < 0.5
    assert effective["reference_depth"] == 12.0
    assert effective["voxel_size"] == pytest.approx(0.2 * scale)
    assert effective["source_voxel"] == pytest.approx(0.2 * scale)
    assert effective["max_distance"] == pytest.approx(0.5 * scale)
    assert effective["gates"] == pytest.approx([2.0 * scale, 1.0 * scale, 0.5 * scale])
    assert result.summary["effective_settings"] == effective


def test_a_street_run_records_scale_one(ws):
    summary = run(ws, SlamStageConfig(odometry="gt", frames=2, voxel_size=0.1, reference_depth=0))[0].summary
    assert summary["effective_settings"] == {"scene_scale": 1.0, "reference_depth": 0.0,
                                             "first_frame_median_depth": None, "voxel_size": 0.1}


def test_camera_steps_are_kept_per_drive_kind_and_start_and_measured_again_when_unreadable(tmp_path):
    """The camera's steps of a drive, measured kind and start trajectory are kept beside the drive and read back as
    measured; another start is another file; a file that cannot be read as the steps is measured again; once the
    drive file is rewritten, keeping new steps removes the drive's older files (not another drive's); a drive folder
    that cannot be written keeps nothing and changes no step."""
    from dcslam.io.camera_steps import write_camera_steps
    from dcslam.stages.slam import camera_steps
    from tests.fixtures.street import write_generated_drive

    drive = write_generated_drive(tmp_path / "drives" / "2011_09_26_drive_7302_sync.h5", seed=7302, frames=4, beams=8)
    start = np.repeat(np.eye(4)[None], 4, 0)
    start[:, 2, 3] = -np.arange(4) * 0.9           # the camera looks along z; near the generator's speed
    first = camera_steps(drive, "sparse@8", start)
    kept = list((drive.parent / ".camera").glob("*.npz"))
    assert len(kept) == 1 and len(first) == 3 and all(s.measured for s in first)
    again = camera_steps(drive, "sparse@8", start)
    assert all(np.array_equal(a.T, b.T) and np.array_equal(a.covariance, b.covariance) and a.returns == b.returns
               for a, b in zip(first, again))
    write_camera_steps(kept[0], np.stack([s.T for s in first]), np.stack([s.covariance for s in first]),
                       np.full(3, 7), np.ones(3, bool))               # what is kept is what is read
    assert [s.returns for s in camera_steps(drive, "sparse@8", start)] == [7, 7, 7]
    other = start.copy()
    other[1, 2, 3] -= 0.05
    camera_steps(drive, "sparse@8", other)
    assert len(list((drive.parent / ".camera").glob("*.npz"))) == 2
    kept[0].write_bytes(b"not a camera")
    mended = camera_steps(drive, "sparse@8", start)
    assert all(np.array_equal(a.T, b.T) for a, b in zip(first, mended)) and kept[0].stat().st_size > 100
    neighbour = drive.parent / ".camera" / f"{drive.stem}-b-0123abcd-{'0' * 20}.npz"  # drive <stem>-b's
    neighbour.write_bytes(b"kept")
    os.utime(drive, ns=(drive.stat().st_atime_ns, drive.stat().st_mtime_ns + 10**9))  # the drive file rewritten
    before = {p.name for p in (drive.parent / ".camera").glob("*.npz")}
    camera_steps(drive, "sparse@8", start)
    after = {p.name for p in (drive.parent / ".camera").glob("*.npz")}
    assert len(before) == 3 and len(after - before) == 1 and after & before == {neighbour.name}  # the other two: gone
    for path in (drive.parent / ".camera").glob("*.npz"):
        path.unlink()
    (drive.parent / ".camera").rmdir()
    (drive.parent / ".camera").write_text("a file where the folder would be")   # no folder can be made there
    unkept = camera_steps(drive, "sparse@8", start)
    assert (drive.parent / ".camera").read_text() == "a file where the folder would be"
    assert all(np.array_equal(a.T, b.T) for a, b in zip(first, unkept))
