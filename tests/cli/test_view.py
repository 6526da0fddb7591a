"""``dcslam view``: without a display it prints the exact command that opens the recording and exits 0; with one it
starts the ``rerun`` on PATH on the recording; a folder with several recordings needs --drive."""
import os
import stat
import time

import pytest


@pytest.fixture
def recordings(tmp_path):
    """A workspace whose slam/dense/ holds two recordings (their content is not read by ``view``)."""
    out = tmp_path / "ws" / "slam" / "dense"
    out.mkdir(parents=True)
    for name in ("drive_c", "drive_d"):
        (out / f"{name}.rrd").write_bytes(b"RRF2")
    return tmp_path / "ws"


@pytest.fixture
def no_display(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)


def fake_rerun(folder, log):
    """A ``rerun`` executable that writes its arguments to ``log``."""
    folder.mkdir()
    script = folder / "rerun"
    script.write_text(f"#!/bin/sh\necho \"$@\" > {log}\n")
    script.chmod(script.stat().st_mode | stat.S_IEXEC)
    return folder


def test_without_a_display_it_prints_the_command(cli, recordings, no_display, tmp_path, monkeypatch):
    monkeypatch.setenv("PATH", f"{fake_rerun(tmp_path / 'bin', tmp_path / 'log')}{os.pathsep}{os.environ['PATH']}")
    path = recordings / "slam" / "dense" / "drive_d.rrd"
    result = cli("view", "dense", "--drive", "drive_d", "-w", recordings)
    assert result.exit_code == 0, result.output
    assert result.stdout.splitlines() == [
        "no display here (neither DISPLAY nor WAYLAND_DISPLAY is set); open the recording with",
        f"  rerun {path}", "or in a browser (it prints the address):", f"  rerun --web-viewer {path}"]
    assert not (tmp_path / "log").exists()
    result = cli("view", path, "-w", recordings)  # the file itself
    assert result.exit_code == 0 and f"  rerun {path}\n" in result.stdout


def test_without_rerun_on_path_it_names_the_extra(cli, recordings, monkeypatch, tmp_path):
    monkeypatch.setenv("DISPLAY", ":0")
    monkeypatch.setenv("PATH", str(tmp_path / "nothing"))
    result = cli("view", recordings / "slam" / "dense" / "drive_c.rrd", "-w", recordings)
    assert result.exit_code == 0
    assert result.stdout.startswith("rerun is not on PATH (pip install 'dcslam[viz]'); open the recording with\n")


def test_with_a_display_it_starts_the_viewer(cli, recordings, monkeypatch, tmp_path):
    monkeypatch.setenv("DISPLAY", ":0")
    monkeypatch.setenv("PATH", f"{fake_rerun(tmp_path / 'bin', tmp_path / 'log')}{os.pathsep}{os.environ['PATH']}")
    path = recordings / "slam" / "dense" / "drive_c.rrd"
    result = cli("view", recordings / "slam" / "dense", "--drive", "drive_c", "-w", recordings)
    assert result.exit_code == 0 and result.stdout == f"opened {path} in the Rerun viewer\n"
    for _ in range(100):  # the viewer is started detached
        if (tmp_path / "log").exists() and (tmp_path / "log").read_text():
            break
        time.sleep(0.05)
    assert (tmp_path / "log").read_text().strip() == str(path)


def test_what_cannot_be_opened_fails_in_one_line(cli, recordings, no_display, tmp_path):
    result = cli("view", "dense", "-w", recordings)
    assert result.exit_code == 1
    assert result.stderr == f"error: {recordings / 'slam' / 'dense'} holds 2 recordings (drive_c, drive_d); " \
                            "pass --drive\n"
    result = cli("view", "dense", "--drive", "drive_x", "-w", recordings)
    assert result.exit_code == 1 and "drive_x.rrd not found; record it with `dcslam slam --record --drive drive_x`" \
        in result.stderr
    (tmp_path / "map.ply").write_text("ply\n")
    result = cli("view", tmp_path / "map.ply", "-w", recordings)
    assert result.exit_code == 1 and "is not a Rerun recording (.rrd)" in result.stderr
    result = cli("view", "sparse", "-w", recordings)
    assert result.exit_code == 1 and "sparse not found" in result.stderr
