"""The slam stage: run() on a tiny workspace returns per-drive summaries and writes the configuration it ran."""
import json

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
    assert {p.name for p in out.iterdir()} == {"drive_d.txt", "drive_d.kitti.txt", "drive_d.ply", "drive_d.json"}
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
