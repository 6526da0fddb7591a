"""`dcslam synth --indoor` → `dcslam prepare-tum` → `dcslam slam` / `score` through the command line: exit codes,
messages and the files written."""
import json
from pathlib import Path

import numpy as np
import pytest

from dcslam.io.drive import DriveFile, read_splits

SEQ = "living_room_traj0_frei_png"


@pytest.fixture(autouse=True)
def _one_thread():
    """SLAM on tiny frames: torch's intra-op threads cost more than they give on shared cores."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def _files(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir()) if folder.exists() else []


@pytest.fixture(scope="module")
def workspace(cli, tmp_path_factory) -> Path:
    """A workspace whose tum/ holds one generated sequence of 6 frames at 96 x 72."""
    ws = tmp_path_factory.mktemp("ws")
    result = cli("synth", "--indoor", "--workspace", ws, "--drives", 1, "--frames", 6, "--scale", 0.15)
    assert result.exit_code == 0, result.output
    assert "wrote 1 indoor sequence(s) (6 frames" in result.stdout
    return ws


def test_synth_indoor_files(cli, workspace):
    assert _files(workspace / "tum") == [SEQ, "synth_indoor.json"]
    assert _files(workspace / "tum" / SEQ) == ["associations.txt", "depth", "intrinsics.txt",
                                               "livingRoom0.gt.freiburg", "rgb"]
    again = cli("synth", "--indoor", "--workspace", workspace, "--drives", 1, "--frames", 2, "--scale", 0.15)
    assert again.exit_code == 1 and "exists; pass --force" in again.stderr
    assert len(again.stderr.strip().splitlines()) == 1
    assert len(_files(workspace / "tum" / SEQ / "rgb")) == 6


def test_prepare_slam_score(cli, workspace, tmp_path):
    result = cli("prepare-tum", "--workspace", workspace)
    assert result.exit_code == 0, result.output
    drives = workspace / "drives"
    assert _files(drives) == [f"{SEQ}.h5", "prepare-tum.json", "splits.json"]
    assert read_splits(drives / "splits.json") == {"train": [], "val": [], "test": [SEQ]}
    assert f"{SEQ}: 6 frames, split test" in result.stdout
    with DriveFile(drives / f"{SEQ}.h5") as drive:
        assert drive.attrs["source"] == "tum" and drive.K[1, 1] < 0 and len(drive) == 6

    slam = cli("slam", "--workspace", workspace, "--depth", "dense")
    assert slam.exit_code == 0, slam.output
    assert _files(workspace / "slam" / "dense") == [f"{SEQ}.done", f"{SEQ}.json", f"{SEQ}.kitti.txt", f"{SEQ}.ply",
                                                     f"{SEQ}.txt"]
    summary = json.loads((workspace / "slam" / "dense" / f"{SEQ}.json").read_text())
    assert summary["frames"] == 6 and not summary["rejected_steps"]
    assert summary["translation_error_m"]["max"] < 0.02
    score = cli("score", "trajectory", "--workspace", workspace, "--layer", "dense")
    assert score.exit_code == 0, score.output
    assert (workspace / "results" / "trajectory_dense.csv").exists()


def test_options_and_force(cli, workspace, tmp_path):
    out = tmp_path / "drives"
    args = ("prepare-tum", "--tum", workspace / "tum" / SEQ, "--out", out)
    result = cli(*args, "--stride", 2, "--max-frames", 2, "--sparse-stride", 4,
                 "--intrinsics", "72.18,-72,47.5,35.5")
    assert result.exit_code == 0, result.output
    with DriveFile(out / f"{SEQ}.h5") as drive:
        assert drive.frame_ids.tolist() == [0, 2] and drive.K.tolist() == [[72.18, 0, 47.5], [0, -72, 35.5], [0, 0, 1]]
        assert 0.05 < np.mean(drive.depth("sparse", 0) > 0) < 0.07
    again = cli(*args)
    assert again.exit_code == 1 and f"{SEQ}.h5 exists; pass --force" in again.stderr
    assert len(again.stderr.strip().splitlines()) == 1
    assert cli(*args, "--force").exit_code == 0


@pytest.mark.parametrize("args, message", [
    (("--intrinsics", "1,2,3"), "--intrinsics: '1,2,3' is not four numbers"),
    (("--intrinsics", "500,0,1,1"), "fx and fy != 0"),
])
def test_bad_options(cli, workspace, tmp_path, args, message):
    result = cli("prepare-tum", "--tum", workspace / "tum", "--out", tmp_path / "drives", *args)
    assert result.exit_code == 1 and message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and not (tmp_path / "drives").exists()


def test_bad_input_writes_nothing(cli, workspace, tmp_path):
    src = tmp_path / "tum" / SEQ
    src.mkdir(parents=True)
    for item in (workspace / "tum" / SEQ).iterdir():
        (src / item.name).symlink_to(item)
    (src / "associations.txt").unlink()
    (src / "associations.txt").write_text("0 depth/0.png 0 rgb/0.png\n1 depth/1.png\n")
    result = cli("prepare-tum", "--tum", tmp_path / "tum", "--out", tmp_path / "drives")
    assert result.exit_code == 1
    assert result.stderr.strip() == (f"error: {src / 'associations.txt'}:2: 2 fields, expected 4 "
                                     "('timestamp depth/N.png timestamp rgb/N.png' per line)")
    assert not (tmp_path / "drives").exists()

    empty = cli("prepare-tum", "--workspace", tmp_path / "nothing")
    assert empty.exit_code == 1 and "run `dcslam synth --indoor`" in empty.stderr
    assert len(empty.stderr.strip().splitlines()) == 1


def test_wrong_depth_png_mid_sequence_leaves_no_drive_file(cli, workspace, tmp_path):
    import cv2

    src = tmp_path / "tum" / SEQ
    src.mkdir(parents=True)
    for item in (workspace / "tum" / SEQ).iterdir():
        if item.name != "depth":
            (src / item.name).symlink_to(item)
    (src / "depth").mkdir()
    for item in (workspace / "tum" / SEQ / "depth").iterdir():
        (src / "depth" / item.name).symlink_to(item)
    (src / "depth" / "3.png").unlink()
    cv2.imwrite(str(src / "depth" / "3.png"), np.zeros((72, 96), np.uint8))
    result = cli("prepare-tum", "--tum", src, "--out", tmp_path / "drives")
    assert result.exit_code == 1
    assert result.stderr.strip() == (f"error: {src / 'depth' / '3.png'}: expected a 16-bit single-channel depth PNG "
                                     "(metres = value / 5000), got uint8 with shape (72, 96)")
    assert _files(tmp_path / "drives") == []
