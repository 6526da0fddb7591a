"""The synth stage: KITTI-layout drives (or indoor sequences) under the workspace, with their settings."""
import pytest

from dcslam.errors import DcslamError
from dcslam.stages.synth import SynthConfig, run


def test_drives_too_short_for_depth_are_refused_indoor_sequences_are_not():
    with pytest.raises(DcslamError, match="--frames 10 gives no frame a depth map"):
        SynthConfig(drives=1, frames=10)
    assert SynthConfig(indoor=True, frames=2).frames == 2


def test_indoor_sequences(tmp_path):
    from dcslam.workspace import Workspace

    result = run(Workspace(tmp_path), SynthConfig(indoor=True, drives=1, frames=2, scale=0.1))
    assert result.indoor and result.root == tmp_path / "tum" and (tmp_path / "tum" / "synth_indoor.json").exists()


def test_bad_values():
    with pytest.raises(DcslamError, match="scale"):
        SynthConfig(scale=9.0)
