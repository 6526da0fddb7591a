"""A training run refused before its first epoch leaves nothing that blocks the corrected rerun."""
import pytest

from dcslam.depth.models import build_model, save_model
from dcslam.errors import DcslamError
from dcslam.stages.train import TrainStageConfig, run

TINY = dict(max_frames=2, scale=0.5, device="cpu", batch_size=2, epochs=1)


def test_a_rejected_init_leaves_no_run_and_the_corrected_rerun_trains(ws):
    save_model(ws.runs / "other" / "model.pt", build_model("nconv"), meta={"scale": 0.5})
    with pytest.raises(DcslamError, match=r"--init .*other/model\.pt is a nconv network, not sparse-conv"):
        run(ws, TrainStageConfig(init="other", name="tuned", **TINY))
    assert not (ws.runs / "tuned").exists()
    result = run(ws, TrainStageConfig(init="other", name="tuned", model="nconv", **TINY))
    assert (result.run_dir / "config.json").exists() and (result.run_dir / "model.pt").exists()


def test_a_forced_rerun_that_is_rejected_leaves_an_empty_run_folder_not_a_half_run(ws):
    run(ws, TrainStageConfig(name="r", **TINY))
    save_model(ws.runs / "other" / "model.pt", build_model("nconv"), meta={"scale": 0.5})
    with pytest.raises(DcslamError, match="is a nconv network"):
        run(ws, TrainStageConfig(init="other", name="r", **TINY), force=True)
    assert list((ws.runs / "r").iterdir()) == []   # its old files went with --force; no config.json of a non-run
    run(ws, TrainStageConfig(name="r", **TINY))     # no "run exists"


def test_a_gpu_asked_for_on_a_machine_without_one_makes_no_folder(ws):
    import torch

    if torch.cuda.is_available():
        pytest.skip("this machine has a GPU")
    with pytest.raises(DcslamError, match="cuda"):
        run(ws, TrainStageConfig(name="gpu", **{**TINY, "device": "cuda"}))
    assert not (ws.runs / "gpu").exists()
