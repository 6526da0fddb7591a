"""`dcslam reproduce` never overwrites what it did not make without its own --force, and an interrupted stage leaves
a stamp that claims nothing (it is redone on the next run)."""
import json
import os

import pytest

from dcslam.errors import DcslamError
from dcslam.stages.pipeline import Pipeline, Stage
from dcslam.stages.reproduce import ReproduceConfig
from dcslam.stages.slam import SlamStageConfig
from dcslam.workspace import Workspace


def _stage(calls, made, fail_with=None):
    def run(ws, config, *, force=False):
        calls.append(force)
        made.parent.mkdir(parents=True, exist_ok=True)
        made.write_text("made by the pipeline")
        if fail_with is not None:
            raise fail_with
    return Stage("train-mse-sparse", run, SlamStageConfig(frames=3), outputs=lambda: [made])


def test_hand_made_output_is_refused_with_the_stage_and_file_named_until_force(tmp_path):
    made = tmp_path / "runs" / "mse-sparse" / "model.pt"
    made.parent.mkdir(parents=True)
    made.write_text("trained by hand")
    calls = []
    with pytest.raises(DcslamError, match=r"stage train-mse-sparse would overwrite .*model.pt.*--force"):
        Pipeline(Workspace(tmp_path)).run(_stage(calls, made))
    assert calls == [] and made.read_text() == "trained by hand"
    assert not (tmp_path / ".reproduce" / "train-mse-sparse.json").exists()

    Pipeline(Workspace(tmp_path), force=True).run(_stage(calls, made))
    assert calls == [True] and made.read_text() == "made by the pipeline"


def test_output_changed_by_hand_after_the_pipeline_made_it_is_refused(tmp_path):
    made = tmp_path / "runs" / "r" / "model.pt"
    calls = []
    pipe = Pipeline(Workspace(tmp_path))
    pipe.run(_stage(calls, made))
    stamp = tmp_path / ".reproduce" / "train-mse-sparse.json"
    os.utime(stamp, (1_000_000, 1_000_000))  # the user retrained after the pipeline's stamp
    changed = Stage("train-mse-sparse", _stage(calls, made).run, SlamStageConfig(frames=4), outputs=lambda: [made])
    with pytest.raises(DcslamError, match="did not make"):
        pipe.run(changed)
    assert len(calls) == 1


def test_interrupted_stage_leaves_a_stamp_claiming_nothing_and_is_redone(tmp_path):
    made = tmp_path / "kitti" / "SYNTHETIC"
    calls = []
    pipe = Pipeline(Workspace(tmp_path))
    with pytest.raises(KeyboardInterrupt):
        pipe.run(_stage(calls, made, fail_with=KeyboardInterrupt()))
    stamp = json.loads((tmp_path / ".reproduce" / "train-mse-sparse.json").read_text())
    assert stamp["complete"] is False
    stage = _stage(calls, made)
    assert not pipe.up_to_date(stage)
    pipe.run(stage)  # its own half-made output: no refusal
    assert len(calls) == 2
    assert json.loads((tmp_path / ".reproduce" / "train-mse-sparse.json").read_text())["complete"] is True
    assert pipe.up_to_date(stage)


def test_reproduce_has_its_own_force_option():
    assert ReproduceConfig(force=True).force and not ReproduceConfig().force
