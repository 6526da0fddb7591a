"""The synth stage: KITTI-layout drives (or indoor sequences) under the workspace, with their settings."""
import json

import pytest

from dcslam.errors import DcslamError
from dcslam.stages.synth import SynthConfig, run


def test_short_drive_is_noted_and_written_under_the_workspace(tmp_path):
    from dcslam.workspace import Workspace

    ws = Workspace(tmp_path / "ws")
    result = run(ws, SynthConfig(drives=1, frames=2, seed=3))
    assert result.root == ws.kitti and len(result.reports) == 1
    assert result.notes and "no frame gets depth" in result.notes[0]
    assert json.loads((ws.kitti / "synth_config.json").read_text())["stage"] == "synth"
    with pytest.raises(DcslamError, match="--force"):
        run(ws, SynthConfig(drives=1, frames=2, seed=3))


def test_indoor_sequences(tmp_path):
    from dcslam.workspace import Workspace

    result = run(Workspace(tmp_path), SynthConfig(indoor=True, drives=1, frames=2, scale=0.1))
    assert result.indoor and result.root == tmp_path / "tum" and (tmp_path / "tum" / "synth_indoor.json").exists()


def test_bad_values():
    with pytest.raises(DcslamError, match="scale"):
        SynthConfig(scale=9.0)
