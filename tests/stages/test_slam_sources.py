"""``dcslam slam --sources measured``: the odometry aligns the measured LiDAR pixels behind the depth input against
the map fused from that input; checked options, one-line errors, the summary's record, and that it localises
better than SLAM on the sparse input alone."""
import json

import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.stages.slam import SlamStageConfig, run, run_drive_file


def test_option_checks():
    assert SlamStageConfig().sources == "depth" and SlamStageConfig().measured is None
    with pytest.raises(DcslamError, match="unknown ICP sources 'lidar'"):
        SlamStageConfig(sources="lidar")
    with pytest.raises(DcslamError, match="--measured sparse@16 needs --sources measured"):
        SlamStageConfig(measured="sparse@16")
    with pytest.raises(DcslamError, match="'lidar' is not a drive depth kind"):
        SlamStageConfig(sources="measured", measured="lidar")


def test_cli_exit_codes(cli, ws):
    bad = cli("slam", "-w", ws.root, "--sources", "lidar")
    assert bad.exit_code == 2 and not ws.slam.exists()
    needs = cli("slam", "-w", ws.root, "--measured", "sparse@16")
    assert needs.exit_code == 1 and "needs --sources measured" in needs.output
    missing = cli("slam", "-w", ws.root, "--sources", "measured", "--measured", "sparse@16", "--frames", 2)
    assert missing.exit_code == 1 and "holds no sparse@16 depth" in missing.output
    assert len(missing.output.strip().splitlines()) == 1 and not ws.slam.exists()


def _layer(ws, name, config):
    """A layer under predictions/<name>/ holding drive_d's sparse depth, with the given provenance."""
    from dcslam.io.drive import DriveFile, Layer, write_layer

    with DriveFile(ws.drives / "drive_d.h5") as drive:
        depth = np.stack([drive.depth("sparse", i) for i in range(len(drive))])
        write_layer(ws.predictions / name / "drive_d.h5", Layer(depth, drive=drive.name, made_by=name,
                                                                config=config, frame_ids=drive.frame_ids))


def test_a_layer_that_does_not_say_its_input_errors_in_one_line_and_writes_nothing(cli, ws):
    _layer(ws, "foreign", {})
    with pytest.raises(DcslamError, match="does not record the LiDAR input .* pass --measured KIND"):
        run(ws, SlamStageConfig(depth="predicted", run="foreign", sources="measured", frames=2))
    result = cli("slam", "-w", ws.root, "--depth", "predicted", "--run", "foreign", "--sources", "measured")
    assert result.exit_code == 1 and len(result.output.strip().splitlines()) == 1
    assert not ws.slam.exists()
    (ok,) = run(ws, SlamStageConfig(depth="predicted", run="foreign", sources="measured", measured="sparse",
                                    frames=3))
    assert ok.summary["sources"] == {"mode": "measured", "kind": "sparse"}


def _street_drive(path, frames=4, H=48, W=160):
    """An analytic street (dcslam.slam.scene) whose sparse depth ICP aligns with accepted steps."""
    from tests.fixtures.street import write_analytic_street

    write_analytic_street(path, frames, H, W)
    return path


def test_the_sparse_input_as_its_own_measured_sources_gives_the_poses_of_depth_mode(tmp_path):
    """Sparse depth aligned as measured sources is depth mode: as the drive's kind (its frames serve both) and as a
    layer file holding the same depth (a second frame is prepared from the drive's sparse depth for the odometry)."""
    from dcslam.io.drive import DriveFile, Layer, write_layer
    from dcslam.slam.config import SlamSettings, build_slam

    path = _street_drive(tmp_path / "street.h5")
    with DriveFile(path) as drive:
        layer = write_layer(tmp_path / "copy" / "street.h5", Layer(
            np.stack([drive.depth("sparse", i) for i in range(len(drive))]), drive=drive.name, made_by="copy",
            config={"input": "sparse"}, frame_ids=drive.frame_ids))
    plain = run_drive_file(path, "sparse", build_slam(SlamSettings()))
    assert plain.summary()["sources"] == {"mode": "depth"}
    assert all(r.accepted for r in plain.reports) and sum(r.iterations for r in plain.reports) > 0
    for source in ("sparse", layer):
        measured = run_drive_file(path, source, build_slam(SlamSettings()), sources_kind="sparse")
        assert np.array_equal(measured.T_world_cam, plain.T_world_cam), source
        assert [(r.sources, r.inliers, r.iterations) for r in measured.reports] == \
            [(r.sources, r.inliers, r.iterations) for r in plain.reports]
        assert measured.summary()["sources"] == {"mode": "measured", "kind": "sparse"}


def test_the_summary_and_the_printed_line_record_the_sources(cli, ws):
    result = cli("slam", "-w", ws.root, "--depth", "dense", "--sources", "measured", "--frames", 3)
    assert result.exit_code == 0 and "ICP sources sparse" in result.output
    summary = json.loads((ws.slam / "dense" / "drive_d.json").read_text())
    assert summary["sources"] == {"mode": "measured", "kind": "sparse"}   # dense: the drive's own sparse pixels
    assert summary["settings"]["sources"] == "measured" and summary["settings"]["measured"] is None
    plain = cli("slam", "-w", ws.root, "--depth", "dense", "--frames", 3, "--out", ws.root / "plain")
    assert plain.exit_code == 0 and "ICP sources" not in plain.output
    assert json.loads((ws.root / "plain" / "drive_d.json").read_text())["sources"] == {"mode": "depth"}


@pytest.mark.slow
def test_measured_sources_against_an_exact_map_localise_better_than_sparse_slam(tmp_path):
    """At 16 beams almost all of sparse SLAM's error comes from its map: the same measured points aligned against
    a map fused from exact depth localise several times better (generated drives at half KITTI size, 10 frames;
    docs/slam.md, "Measured sources against a completed map", has the full-size figures)."""
    from dcslam.eval.trajectory import localisation_accuracy
    from dcslam.slam.config import SlamSettings, build_slam
    from tests.fixtures.street import write_generated_drive

    for seed in (1, 2):
        path = write_generated_drive(tmp_path / f"drive_{seed}.h5", seed, frames=10, scale=0.5, beams=16)
        sparse = run_drive_file(path, "sparse@16", build_slam(SlamSettings()))
        measured = run_drive_file(path, "exact", build_slam(SlamSettings()), sources_kind="sparse@16")
        on_sparse = localisation_accuracy(sparse.T_gt, sparse.T_world_cam)
        on_exact = localisation_accuracy(measured.T_gt, measured.T_world_cam)
        assert on_exact < 0.6 * on_sparse, (seed, on_exact, on_sparse)
        assert all(r.accepted for r in measured.reports)
