"""Faults in the stages: a SLAM output set is complete or absent, a checkpoint on a full disk is one line, any
refused write that reaches the command line is one line, and an interrupted training says what it kept."""
from __future__ import annotations

import errno
import os

import numpy as np
import pytest

from dcslam.errors import DcslamError

pytestmark = pytest.mark.faults
NO_SPACE = "no space left on device"


def _drive_run(name="drive_d", n=4):
    from dcslam.slam.drive import DriveRun
    from dcslam.slam.pointmap import PointMap

    T = np.repeat(np.eye(4)[None], n, 0)
    T[:, 0, 3] = np.arange(n)
    return DriveRun(name, T, 10 + 0.1 * np.arange(n), T.copy(), PointMap.empty(), [], 1.0)


def test_a_slam_output_set_that_fails_to_write_leaves_nothing_a_reader_takes(tmp_path, monkeypatch):
    from dcslam.io.slam_summary import committed_outputs
    from dcslam.stages.slam import write_outputs

    def full(path, *args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

    monkeypatch.setattr("dcslam.io.ply.write_ply", full)
    out = tmp_path / "slam" / "dense"
    with pytest.raises(DcslamError, match=rf"^could not write {out / 'drive_d.ply'}: {NO_SPACE}$"):
        write_outputs(_drive_run(), out)
    assert sorted(p.name for p in out.iterdir()) == []
    with pytest.raises(DcslamError, match="trajectory .*drive_d.txt not found; run `dcslam slam"):
        committed_outputs(out, "drive_d", "dcslam slam --depth dense --force")
    monkeypatch.undo()
    written = write_outputs(_drive_run(), out)
    assert sorted(p.name for p in out.iterdir()) == ["drive_d.done", "drive_d.json", "drive_d.kitti.txt",
                                                     "drive_d.ply", "drive_d.txt"]
    assert committed_outputs(out, "drive_d") == {k: v for k, v in written.items() if k != "done"}


def test_slam_outputs_without_their_marker_are_refused_in_one_line(tmp_path):
    from dcslam.io.slam_summary import committed_outputs
    from dcslam.stages.slam import write_outputs

    out = tmp_path / "slam" / "dense"
    write_outputs(_drive_run(), out)
    (out / "drive_d.done").unlink()  # a set of an older dcslam, or one whose writer died before its marker
    with pytest.raises(DcslamError, match=r"^the SLAM outputs of drive_d in .* are not committed \(no drive_d\.done: "
                                          r".*\); rerun `dcslam slam --depth dense --force`$"):
        committed_outputs(out, "drive_d", "dcslam slam --depth dense --force")
    write_outputs(_drive_run(), out, force=True)
    (out / "drive_d.kitti.txt").write_text("cut short")
    with pytest.raises(DcslamError, match=r"drive_d\.kitti\.txt: changed since it was committed .*; rerun `dcslam "
                                          r"slam --force`"):
        committed_outputs(out, "drive_d")


def test_a_checkpoint_on_a_full_disk_is_one_line(tmp_path, monkeypatch):
    from dcslam.depth.models import save_torch

    class Full:
        def __init__(self, path, mode):
            self.path = path

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def write(self, data):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self.path))

    monkeypatch.setattr("dcslam.depth.models.open", Full, raising=False)
    with pytest.raises(DcslamError, match=rf"^could not write {tmp_path / 'last.pt'}: {NO_SPACE}$"):
        save_torch(tmp_path / "last.pt", {"epoch": 1})
    assert list(tmp_path.iterdir()) == []


def test_a_refused_write_no_stage_named_is_one_line_at_the_command_line(ws, cli, monkeypatch):
    def read_only(*args, **kwargs):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(ws.slam / "dense" / "x"))

    monkeypatch.setattr("dcslam.stages.slam._run_drives", read_only)
    result = cli("slam", "-w", ws.root, "--odometry", "gt", "--frames", 2)
    assert result.exit_code == 1 and result.output.count("\n") == 1
    assert f"error: could not write {ws.slam / 'dense' / 'x'}: read-only file system" in result.output


def test_an_interrupted_training_says_its_run_folder_is_kept_and_how_to_resume(ws, cli, monkeypatch):
    from dcslam import interrupt

    def interrupted(run_dir, *args, **kwargs):
        (run_dir / "last.pt").write_bytes(b"checkpoint")
        raise KeyboardInterrupt

    monkeypatch.setattr("dcslam.depth.train.train_loop", interrupted)
    monkeypatch.setattr(interrupt, "_told", False)
    result = cli("train", "-w", ws.root, "--max-frames", 2, "--device", "cpu")
    assert result.exit_code == 130
    run_dir = ws.runs / "mse-dense"
    assert f"interrupted: the run folder {run_dir} is kept with last.pt" in result.output
    assert "--resume" in result.output and "no partial output" not in result.output
    assert (run_dir / "last.pt").exists()


@pytest.mark.parametrize("change, how", [("equal", "equal to"), ("backwards", "before")])
def test_prepare_kitti_refuses_timestamps_that_do_not_strictly_increase(tmp_path, change, how):
    from dcslam.io import kitti
    from dcslam.stages.prepare import prepare_kitti
    from tests.fixtures import kitti as fx

    raw = fx.write_tiny_drive(tmp_path / "kitti")
    stamps = kitti.read_timestamps(raw / "image_02" / "timestamps.txt")
    stamps[7] = stamps[6] if change == "equal" else stamps[6] - 0.05
    kitti.write_timestamps(raw / "image_02" / "timestamps.txt", stamps)
    with pytest.raises(DcslamError, match=rf"^drive 2011_09_26_drive_0002_sync: the timestamp of frame 7 is {how} "
                                          r"that of frame 6 in image_02/timestamps\.txt; timestamps must strictly "
                                          r"increase"):
        prepare_kitti(tmp_path / "kitti", tmp_path / "drives", include_unsplit=True)
    assert not (tmp_path / "drives").exists() or list((tmp_path / "drives").iterdir()) == []


def test_a_synth_run_that_fails_to_write_leaves_no_calibration_behind(tmp_path, monkeypatch):
    from dcslam.stages.synth import SynthConfig, run
    from dcslam.workspace import Workspace

    def full(*args, **kwargs):
        raise DcslamError("could not write x.png: no space left on device")

    monkeypatch.setattr("dcslam.synth.street.generate._write_drives", full)
    ws = Workspace(tmp_path / "ws")
    with pytest.raises(DcslamError, match=NO_SPACE):
        run(ws, SynthConfig(drives=1, frames=11))
    assert not ws.root.exists()  # nothing: the folders this run made are gone with its files
