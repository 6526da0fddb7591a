import json

import numpy as np
import pytest

from dcslam.io.drive import DriveFrame, DriveWriter, Layer, write_layer
from dcslam.io.ply import read_ply
from dcslam.io.tum import read_tum
from dcslam.slam.scene import StreetScene, kitti_K, lidar_mask, street_trajectory

H, W, N = 48, 160, 5


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    ws = tmp_path_factory.mktemp("ws")
    (ws / "drives").mkdir()
    scene, K = StreetScene(1), kitti_K(H, W)
    poses = street_trajectory(N, step=0.5)
    with DriveWriter(ws / "drives" / "street_0001.h5", K.double().numpy(), H, W, source="synthetic",
                     date="2011_09_26", drive="street_0001", split="test") as writer:
        for i in range(N):
            dense = scene.render(poses[i], K, H, W).float().numpy()
            sparse = dense * lidar_mask(H, W).numpy()
            rgb = np.full((H, W, 3), 40 * i, np.uint8)
            writer.append(DriveFrame(rgb, sparse, dense, poses[i].numpy(), 0.1 * i, i))
    (ws / "drives" / "splits.json").write_text(json.dumps({"train": [], "val": [], "test": ["street_0001"]}))
    return ws


def test_dense_icp_writes_trajectory_map_and_summary(cli, workspace):
    result = cli("slam", "--depth", "dense", "--odometry", "icp", "-w", workspace)
    assert result.exit_code == 0, result.output
    out = workspace / "slam" / "dense"
    timestamps, poses = read_tum(out / "street_0001.txt")
    assert poses.shape == (N, 4, 4) and np.allclose(timestamps, 0.1 * np.arange(N))
    truth = street_trajectory(N, step=0.5).numpy()
    assert np.abs(poses[:, :3, 3] - truth[:, :3, 3]).max() < 0.1
    points, normals, colors = read_ply(out / "street_0001.ply")
    assert len(points) > 1000 and normals is not None and colors is not None
    record = json.loads((out / "street_0001.json").read_text())
    assert record["frames"] == N and record["points"] == len(points)
    assert record["settings"]["odometry"] == "icp" and record["seconds_per_frame"] > 0
    assert record["rejected_steps"] == []
    # Refuses to overwrite without --force, keeps the files, then overwrites with it.
    again = cli("slam", "--depth", "dense", "-w", workspace)
    assert again.exit_code == 1 and "--force" in again.output
    assert cli("slam", "--depth", "dense", "-w", workspace, "--force", "--frames", "2").exit_code == 0
    assert read_tum(out / "street_0001.txt")[1].shape == (2, 4, 4)


def test_gt_icpslam_sparse_and_layer_path(cli, workspace, tmp_path):
    result = cli("slam", "--depth", "sparse", "--odometry", "gt", "--mapper", "icpslam", "-w", workspace,
                 "--out", tmp_path / "o")
    assert result.exit_code == 0, result.output
    _, poses = read_tum(tmp_path / "o" / "street_0001.txt")
    np.testing.assert_allclose(poses, street_trajectory(N, step=0.5).numpy(), atol=1e-6)
    layer_path = tmp_path / "mylayer.h5"
    from dcslam.io.drive import DriveFile
    with DriveFile(workspace / "drives" / "street_0001.h5") as drive:
        write_layer(layer_path, Layer(np.stack([drive.depth("dense", i) for i in range(N)]), "street_0001", "test"))
    result = cli("slam", "--depth", layer_path, "--odometry", "gradicp", "--frames", "3", "-w", workspace)
    assert result.exit_code == 0, result.output
    assert (workspace / "slam" / "mylayer" / "street_0001.ply").exists()


def test_predicted_without_predictions_names_predict(cli, workspace):
    result = cli("slam", "--depth", "predicted", "-w", workspace)
    assert result.exit_code == 1 and "dcslam predict" in result.output


def test_missing_drives_name_prepare(cli, tmp_path):
    result = cli("slam", "-w", tmp_path)
    assert result.exit_code == 1 and "dcslam prepare-kitti" in result.output


def test_bad_choice_is_usage_error(cli, workspace):
    assert cli("slam", "--odometry", "magic", "-w", workspace).exit_code == 2


def test_strict_exits_1_on_a_suspect_drive_and_still_writes_it(cli, workspace, tmp_path):
    """A layer that is empty after the first frame leaves every step without data: rejected, so the drive is
    suspect. Without --strict that is reported and exits 0; with it, exit 1 naming the drive and why."""
    depth = np.zeros((N, H, W), np.float32)
    scene, K = StreetScene(1), kitti_K(H, W)
    depth[0] = scene.render(street_trajectory(1, step=0.5)[0], K, H, W).float().numpy()
    layer = tmp_path / "empty.h5"
    write_layer(layer, Layer(depth=depth, drive="street_0001", made_by="test", config={}))
    args = ("--depth", str(layer), "--odometry", "icp", "-w", str(workspace), "--threads", "1")
    relaxed = cli("slam", *args, "--out", tmp_path / "relaxed")
    assert relaxed.exit_code == 0, relaxed.output
    assert "SUSPECT" in relaxed.output and "rejected" in relaxed.output
    summary = json.loads((tmp_path / "relaxed" / "street_0001.json").read_text())
    assert summary["health"]["suspect"] and summary["health"]["rejected"] == N - 1
    strict = cli("slam", *args, "--out", tmp_path / "strict", "--strict")
    assert strict.exit_code == 1
    assert "suspect trajectories (--strict): street_0001" in strict.output
    assert (tmp_path / "strict" / "street_0001.txt").exists()


@pytest.fixture(scope="module")
def confident_layer(workspace, tmp_path_factory):
    """A layer of the drive's dense depth with 20 % of its pixels pushed 1 m away, where its confidence is 0.1
    (elsewhere 0.9): what a completer that knows its mistakes would write."""
    from dcslam.io.drive import DriveFile

    with DriveFile(workspace / "drives" / "street_0001.h5") as drive:
        depth = np.stack([drive.depth("dense", i) for i in range(N)])
    bad = (np.random.default_rng(0).random(depth.shape) < 0.2) & (depth > 0)
    confidence = np.where(bad, 0.1, 0.9).astype(np.float32)
    path = tmp_path_factory.mktemp("layers") / "noisy.h5"
    write_layer(path, Layer(np.where(bad, depth + 1.0, depth), "street_0001", "test", confidence=confidence))
    return path, float(1 - bad[depth > 0].mean())


@pytest.mark.parametrize("use, minimum", [("weights", 0.0), ("mask", 0.5), ("ignore", 0.0), ("weights", 0.5)])
def test_confidence_use_is_applied_and_recorded(cli, workspace, confident_layer, tmp_path, use, minimum):
    from dcslam.report.layers import slam_settings
    from dcslam.workspace import Workspace

    path, good_fraction = confident_layer
    out = tmp_path / "slam" / "noisy"
    result = cli("slam", "--depth", path, "--confidence", use, "--min-confidence", minimum, "-w", workspace,
                 "--out", out, "--frames", "3")
    assert result.exit_code == 0, result.output
    assert {p.name for p in out.iterdir()} == {f"street_0001{s}" for s in (".txt", ".kitti.txt", ".ply", ".json",
                                                                            ".done")}
    record = json.loads((out / "street_0001.json").read_text())
    assert record["settings"]["confidence"] == use and record["settings"]["min_confidence"] == minimum
    used = record["confidence"]
    assert used["mode"] == use and used["min_confidence"] == minimum and used["layer_has_confidence"]
    expected = good_fraction if minimum > 0 else 1.0
    assert abs(used["kept_fraction"] - expected) < 0.02
    settings = slam_settings(Workspace(tmp_path), "noisy", "street_0001")
    assert settings["confidence"] == use and settings["min_confidence"] == minimum and settings["camera"] is True


def test_confidence_of_a_layer_without_one(cli, workspace, tmp_path):
    result = cli("slam", "--depth", "dense", "--min-confidence", "0.3", "-w", workspace, "--out", tmp_path / "o")
    assert result.exit_code == 1 and "holds no confidence" in result.output
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())
    result = cli("slam", "--depth", "dense", "--odometry", "gt", "--frames", "2", "-w", workspace,
                 "--out", tmp_path / "p")
    assert result.exit_code == 0, result.output
    used = json.loads((tmp_path / "p" / "street_0001.json").read_text())["confidence"]
    assert used == {"mode": "none", "min_confidence": 0.0, "layer_has_confidence": False, "kept_fraction": 1.0}
    result = cli("slam", "--depth", "dense", "--confidence", "ignore", "--min-confidence", "0.3", "-w", workspace)
    assert result.exit_code == 1 and "--min-confidence needs --confidence weights or mask" in result.output
    assert cli("slam", "--depth", "dense", "--confidence", "often", "-w", workspace).exit_code == 2
    assert cli("slam", "--depth", "dense", "--min-confidence", "1.5", "-w", workspace).exit_code == 2


def test_the_global_map_can_be_switched_off(cli, workspace, tmp_path):
    """``--keep-global-map`` is on by default and ``--no-keep-global-map`` turns it off: with a one-frame local map
    the map file then holds the last frame's points only, and the summary records the setting."""
    sizes = {}
    for flag in ("--keep-global-map", "--no-keep-global-map"):
        out = tmp_path / flag
        result = cli("slam", "--depth", "dense", "--odometry", "gt", "--local-map-frames", "1", flag, "-w", workspace,
                     "--out", out)
        assert result.exit_code == 0, result.output
        record = json.loads((out / "street_0001.json").read_text())
        assert record["settings"]["keep_global_map"] is (flag == "--keep-global-map")
        sizes[flag] = len(read_ply(out / "street_0001.ply")[0])
    assert 0 < sizes["--no-keep-global-map"] < sizes["--keep-global-map"]


def test_camera_abstains_on_blank_images_and_leaves_the_verdict(cli, workspace, tmp_path):
    """This drive's images are flat grey: no return lies on texture, so the camera measures no step, says so, and
    the run keeps the verdict of its own rules, and its line says the camera abstained."""
    result = cli("slam", "--depth", "sparse", "--camera", "-w", workspace, "--out", tmp_path / "o")
    assert result.exit_code == 0, result.output
    health = json.loads((tmp_path / "o" / "street_0001.json").read_text())["health"]
    camera = health["camera"]
    assert camera["verdict"] == "unmeasured" and camera["steps_measured"] == 0 and camera["steps"] == N - 1
    assert camera["measured_kind"] == "sparse" and "overruled" not in health
    assert f"the camera abstained: 0 of {N - 1} steps measured from images" in result.output


def test_camera_cannot_judge_a_layer_that_does_not_say_what_it_was_made_from(cli, workspace, tmp_path):
    from dcslam.io.drive import DriveFile

    with DriveFile(workspace / "drives" / "street_0001.h5") as drive:
        depth = np.stack([drive.depth("dense", i) for i in range(N)])
    layer = write_layer(tmp_path / "foreign.h5", Layer(depth, "street_0001", "another tool"))
    result = cli("slam", "--depth", layer, "--camera", "--evidence", "none", "-w", workspace, "--out", tmp_path / "o")
    assert result.exit_code == 0, result.output
    camera = json.loads((tmp_path / "o" / "street_0001.json").read_text())["health"]["camera"]
    assert camera["verdict"] == "unmeasured" and "does not say which measured depth" in camera["note"]
    assert f"the camera abstained: {layer} does not say which measured depth" in " ".join(result.output.split())


def test_camera_judges_a_generated_drive_and_the_tables_follow(cli, tmp_path):
    """A textured generated drive at 8 beams: the camera measures every step, its verdict is the run's distance
    from the camera's trajectory against 0.5 m, and the tables' reader (run_verdict) follows it."""
    from dcslam.io.slam_summary import read_verdict
    from dcslam.report.layers import slam_settings
    from dcslam.workspace import Workspace
    from tests.fixtures.street import write_generated_drive

    name = "2011_09_26_drive_7303_sync"
    (tmp_path / "drives").mkdir()
    write_generated_drive(tmp_path / "drives" / f"{name}.h5", seed=7303, frames=8, beams=8)
    (tmp_path / "drives" / "splits.json").write_text(json.dumps({"train": [], "val": [], "test": [name]}))
    result = cli("slam", "--depth", "sparse@8", "--camera", "--threads", "1", "-w", tmp_path)
    assert result.exit_code == 0, result.output
    summary = json.loads((tmp_path / "slam" / "sparse@8" / f"{name}.json").read_text())
    camera, health = summary["health"]["camera"], summary["health"]
    assert camera["steps_measured"] == camera["steps"] == 7 and camera["measured_kind"] == "sparse@8"
    assert camera["verdict"] == ("departs" if camera["gap_m"] > 0.5 else "agrees")
    # the camera's trajectory ends within centimetres of the truth (6 cm here, at half size), so its gap is the
    # run's error within them
    assert camera["gap_m"] == pytest.approx(summary["translation_error_m"]["final"], abs=0.1)
    assert health["suspect"] == (camera["verdict"] == "departs")
    assert read_verdict(tmp_path / "slam" / "sparse@8" / f"{name}.json").suspect == health["suspect"]
    settings = slam_settings(Workspace(tmp_path), "sparse@8", name)  # the tables say the camera judged it
    assert settings["camera"] is True and settings["suspect"] == health["suspect"]
    # a completion of the same 8-beam depth: its camera starts from its companion's steps, the 8-beam run's, so it
    # is the same camera, read from what the first run kept
    assert camera["started_from"] == "run" and len(list((tmp_path / "drives" / ".camera").glob("*.npz"))) == 1
    predicted = cli("predict", "--model", "ip-basic-fast", "--input", "sparse@8", "--split", "test", "--out",
                    tmp_path / "predictions" / "ipb8", "-w", tmp_path)
    assert predicted.exit_code == 0, predicted.output
    result = cli("slam", "--depth", tmp_path / "predictions" / "ipb8", "--camera", "--threads", "1", "-w", tmp_path,
                 "--out", tmp_path / "slam" / "ipb8")
    assert result.exit_code == 0, result.output
    completed = json.loads((tmp_path / "slam" / "ipb8" / f"{name}.json").read_text())["health"]["camera"]
    assert completed["started_from"] == "companion" and completed["measured_kind"] == "sparse@8"
    assert len(list((tmp_path / "drives" / ".camera").glob("*.npz"))) == 1
