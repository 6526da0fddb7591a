"""`dcslam synth`: exit codes and the files it writes."""
import json

from typer.testing import CliRunner

from dcslam.cli import app

runner = CliRunner()


def test_synth_writes_drives_into_the_workspace(tmp_path):
    result = runner.invoke(app, ["synth", "--workspace", str(tmp_path), "--drives", "2", "--frames", "2",
                                 "--seed", "9"])
    assert result.exit_code == 0, result.output
    assert "wrote 2 drives" in result.stdout
    kitti = tmp_path / "kitti"
    for number in ("1000", "1001"):
        raw = kitti / "raw" / "2011_09_26" / f"2011_09_26_drive_{number}_sync"
        assert sorted(p.name for p in (raw / "image_02" / "data").iterdir()) == ["0000000000.png", "0000000001.png"]
        assert len(list((raw / "velodyne_points" / "data").glob("*.bin"))) == 2
        assert len(list((raw / "oxts" / "data").glob("*.txt"))) == 2
    assert (kitti / "raw" / "2011_09_26" / "calib_cam_to_cam.txt").exists()
    assert (kitti / "SYNTHETIC").exists()
    config = json.loads((kitti / "synth_config.json").read_text())
    assert config["stage"] == "synth" and config["settings"]["seed"] == 9

    again = runner.invoke(app, ["synth", "--out", str(kitti), "--drives", "1", "--frames", "2"])
    assert again.exit_code == 1
    assert "--force" in again.stderr

    forced = runner.invoke(app, ["synth", "--out", str(kitti), "--drives", "1", "--frames", "1", "--force"])
    assert forced.exit_code == 0, forced.output
    raw0 = kitti / "raw" / "2011_09_26" / "2011_09_26_drive_1000_sync" / "image_02" / "data"
    assert [p.name for p in raw0.iterdir()] == ["0000000000.png"]


def test_synth_rejects_bad_options(tmp_path):
    result = runner.invoke(app, ["synth", "--out", str(tmp_path), "--frames", "0"])
    assert result.exit_code == 2
    assert not (tmp_path / "raw").exists()
