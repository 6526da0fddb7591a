"""`dcslam synth`: exit codes and the files it writes."""
import json


def test_synth_writes_drives_into_the_workspace(cli, tmp_path):
    result = cli("synth", "--workspace", tmp_path, "--drives", 1, "--frames", 11, "--seed", 9)
    assert result.exit_code == 0, result.output
    assert "wrote 1 drives" in result.stdout
    kitti = tmp_path / "kitti"
    raw = kitti / "raw" / "2011_09_26" / "2011_09_26_drive_1000_sync"
    assert len(list((raw / "image_02" / "data").iterdir())) == 11
    assert len(list((raw / "velodyne_points" / "data").glob("*.bin"))) == 11
    assert len(list((raw / "oxts" / "data").glob("*.txt"))) == 11
    depth = kitti / "depth_completion" / "train" / "2011_09_26_drive_1000_sync" / "proj_depth" / "groundtruth"
    assert [p.name for p in (depth / "image_02").iterdir()] == ["0000000005.png"]
    assert (kitti / "raw" / "2011_09_26" / "calib_cam_to_cam.txt").exists()
    assert (kitti / "SYNTHETIC").exists()
    config = json.loads((kitti / "synth_config.json").read_text())
    assert config["stage"] == "synth" and config["settings"]["seed"] == 9

    again = cli("synth", "--out", kitti, "--drives", 1, "--frames", 12)
    assert again.exit_code == 1
    assert "exists; pass --force to replace it" in again.stderr   # its own drives: no foreign data found


def test_synth_rejects_bad_options(cli, tmp_path):
    result = cli("synth", "--out", tmp_path, "--frames", 0)
    assert result.exit_code == 2
    assert not (tmp_path / "raw").exists()


def test_synth_refuses_drives_too_short_for_depth_before_any_work(cli, tmp_path):
    result = cli("synth", "--out", tmp_path / "k", "--frames", 5)
    assert result.exit_code == 1
    assert result.stderr.strip().splitlines() == [
        "error: --frames 5 gives no frame a depth map (KITTI skips 5 frames at each end); pass --frames 11 or more"]
    assert not (tmp_path / "k").exists()


def test_synth_never_writes_beside_data_it_did_not_generate(cli, tmp_path):
    """Real KITTI in kitti/: generated drives beside it would make prepare-kitti read both as one synthetic root."""
    from tests.fixtures.kitti import link_real_drive

    kitti = link_real_drive(tmp_path / "kitti")
    before = sorted(str(p.relative_to(kitti)) for p in kitti.rglob("*"))
    result = cli("synth", "--workspace", str(tmp_path), "--drives", "1", "--frames", "11")
    assert result.exit_code == 1
    assert f"{kitti} holds data dcslam synth did not write" in result.stderr
    assert "2011_09_26_drive_0001_sync" in result.stderr and "--force" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert sorted(str(p.relative_to(kitti)) for p in kitti.rglob("*")) == before


def test_synth_indoor_never_writes_beside_data_it_did_not_generate(cli, tmp_path):
    (tmp_path / "tum" / "rgbd_dataset_freiburg1_xyz").mkdir(parents=True)
    result = cli("synth", "--indoor", "--workspace", str(tmp_path), "--drives", "1", "--frames",
                                 "2", "--scale", "0.1")
    assert result.exit_code == 1 and "rgbd_dataset_freiburg1_xyz" in result.stderr and "--force" in result.stderr
    assert [p.name for p in (tmp_path / "tum").iterdir()] == ["rgbd_dataset_freiburg1_xyz"]


def test_a_dead_worker_is_one_line_and_publishes_nothing(cli, tmp_path, monkeypatch):
    """A drive worker the system killed (``--jobs 2``; the pool then raises BrokenProcessPool): exit 1, one line, no
    generated root left half-written."""
    from concurrent.futures.process import BrokenProcessPool

    from dcslam.synth.street import generate

    def killed(*args, **kwargs):
        raise BrokenProcessPool("A process in the process pool was terminated abruptly")

    monkeypatch.setattr(generate, "_write_drives", killed)
    result = cli("synth", "--out", tmp_path / "k", "--drives", 2, "--frames", 11, "--jobs", 2)
    assert result.exit_code == 1 and "Traceback" not in result.stderr
    assert result.stderr.strip().splitlines() == [
        "error: a worker process of this command died (killed by the system, most often for want of memory, or a "
        "crash); rerun it with fewer --jobs or more memory"]
    assert not (tmp_path / "k").exists()
