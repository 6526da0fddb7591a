"""Ordinary mistakes and broken inputs: one line on stderr, exit 1 (or 2 for usage), nothing written."""
import h5py
import numpy as np
import pytest

from tests.cli.test_filter import make_workspace



def one_line(result, code=1) -> str:
    assert result.exit_code == code, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    return lines[0]


def _files(root):
    return sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_file())


@pytest.fixture
def ws(tmp_path):
    return make_workspace(tmp_path / "ws")


@pytest.mark.parametrize("value, kinds", [(np.nan, "NaN"), (np.inf, "infinite"), (-1.0, "negative")])
@pytest.mark.parametrize("command", [("score", "depth", "--layer", "mse-dense"),
                                     ("filter", "--run", "mse-dense", "--filter", "edges")])
def test_a_layer_holding_bad_depth_is_refused_naming_file_and_frame(cli, ws, command, value, kinds):
    layer = ws / "predictions" / "mse-dense" / "d1.h5"
    with h5py.File(layer, "a") as h5:
        h5["depth"][2, 3, 4] = value
    before = _files(ws)
    line = one_line(cli(*command, "-w", ws))
    assert line == f"error: {layer}: frame 2 holds {kinds} depths (1 pixels); depth must be finite and >= 0 " \
                   "(0 = no value): remake the file"
    assert _files(ws) == before


def test_a_nan_pose_in_a_drive_file_is_refused_when_read(cli, ws):
    with h5py.File(ws / "drives" / "d1.h5", "a") as h5:
        h5["T_world_cam"][1, 0, 3] = np.nan
    line = one_line(cli("slam", "-w", ws, "--depth", "dense", "--odometry", "gt", "--drive", "d1"))
    assert line == f"error: {ws / 'drives' / 'd1.h5'}: T_world_cam is not finite at frame 1; remake the drive " \
                   "file with `dcslam prepare-kitti --force`"
    assert not (ws / "slam").exists()


def test_outputs_that_are_the_wrong_kind_of_path(cli, ws, tmp_path):
    a_file = tmp_path / "a_file"
    a_file.write_text("mine")
    for args, option in [(("slam", "-w", ws, "--depth", "dense", "--out", a_file), "--out"),
                         (("predict", "-w", ws, "--model", "ip-basic-fast", "--output", a_file), "--out"),
                         (("synth", "-w", a_file, "--drives", "1", "--frames", "11"), "workspace (-w)"),
                         (("prepare-kitti", "-w", ws, "--kitti", ws, "--out", a_file), "--out")]:
        line = one_line(cli(*args))
        assert line.startswith(f"error: {option} {a_file} is a file"), line
    assert a_file.read_text() == "mine"
    folder = ws / "scores"
    folder.mkdir()
    line = one_line(cli("score", "depth", "-w", ws, "--layer", "dense", "--out", folder, "--force"))
    assert line.startswith(f"error: --out {folder} is a folder; pass a file name")
    line = one_line(cli("score", "trajectory", "-w", ws, "--est", folder, "--gt", ws / "drives" / "d0.h5"))
    assert line.startswith(f"error: trajectory file {folder} is a folder; pass a TUM trajectory file")
    assert list(folder.iterdir()) == []


def test_slam_on_a_gpu_that_is_not_there(cli, ws):
    import torch

    if torch.cuda.is_available():
        pytest.skip("this machine has a GPU")
    assert one_line(cli("slam", "-w", ws, "--depth", "dense", "--device", "cuda")) == \
        "error: --device cuda, but no GPU is available"
    assert not (ws / "slam").exists()


def test_kitti_root_missing_or_a_file(cli, ws, tmp_path):
    line = one_line(cli("prepare-kitti", "-w", ws, "--kitti", tmp_path / "nowhere"))
    assert line.startswith(f"error: KITTI root {tmp_path / 'nowhere'} does not exist")
    (tmp_path / "f").write_text("x")
    line = one_line(cli("reproduce", "-w", ws, "--kitti", tmp_path / "f"))
    assert "does not exist or is not a folder" in line
