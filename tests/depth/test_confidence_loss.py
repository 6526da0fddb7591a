"""A learned confidence for the fill-correcting sparse-conv: what counts as a placed pixel, the binary cross-entropy
against it (known answers, float64 gradcheck, no gradient to the depth), the network that gives its head's gate only
when trained with it, the predictions that leave empty what it cannot place, and a tiny run that trains it."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from dcslam.depth.forward import gives_confidence
from dcslam.depth.losses import PLACED_ABSOLUTE_M, PLACED_RELATIVE, confidence_loss, placed
from dcslam.depth.models import build_model
from dcslam.depth.predict import NetworkCompleter
from dcslam.errors import DcslamError
from tests.fixtures import depth as fixtures


def _img(values) -> torch.Tensor:
    return torch.tensor(values, dtype=torch.float64).reshape(1, 1, 1, -1)


def test_a_pixel_is_placed_within_the_fusion_gate_of_its_target():
    target = _img([4.0, 4.0, 20.0, 20.0, 10.0, 0.0])
    pred = _img([4.09, 4.11, 20.39, 20.41, 0.0, 5.0])  # 0.1 m near, 2 % (0.4 m) at 20 m; no prediction; no target
    assert placed(pred, target).flatten().tolist() == [True, False, True, False, False, False]
    assert (PLACED_ABSOLUTE_M, PLACED_RELATIVE) == (0.1, 0.02)


def test_confidence_loss_known_answers():
    target = _img([4.0, 4.0, 0.0])
    pred = _img([4.0, 6.0, 3.0])                    # placed, not placed, no target (not counted)
    right = _img([1.0, 0.0, 0.5])
    assert float(confidence_loss(right, pred, target)) < 1e-5
    half = _img([0.5, 0.5, 0.9])
    assert float(confidence_loss(half, pred, target)) == pytest.approx(math.log(2))
    wrong = _img([0.2, 0.9, 0.0])                    # -(log 0.2 + log 0.1) / 2
    assert float(confidence_loss(wrong, pred, target)) == pytest.approx(-(math.log(0.2) + math.log(0.1)) / 2)
    nothing = confidence_loss(half, pred, torch.zeros_like(target))
    assert float(nothing) == 0.0


def test_confidence_loss_gradcheck_and_no_gradient_to_the_depth():
    torch.manual_seed(0)
    target = 5 + 10 * torch.rand(1, 1, 4, 5, dtype=torch.float64)
    target[0, 0, 0, :2] = 0
    pred = (target + 0.3 * torch.randn_like(target)).requires_grad_()
    confidence = (0.05 + 0.9 * torch.rand_like(target)).requires_grad_()
    assert torch.autograd.gradcheck(lambda c: confidence_loss(c, pred.detach(), target), (confidence,))
    confidence_loss(confidence, pred, target).backward()
    assert pred.grad is None and confidence.grad.abs().sum() > 0


def test_sparse_conv_gives_its_gate_as_confidence_only_when_trained_for_it():
    sparse = torch.zeros(1, 1, 16, 24)
    sparse[0, 0, ::4, ::3] = 8.0
    plain = build_model("sparse-conv", correct_fill=True)
    confident = build_model("sparse-conv", correct_fill=True, confidence=True)
    assert not gives_confidence(plain) and gives_confidence(confident)
    assert gives_confidence(build_model("nconv")) and not gives_confidence(build_model("sparse-conv"))
    assert confident.hparams["confidence"] is True and "confidence" not in plain.hparams  # old model files as were
    depth, conf = confident.forward_with_confidence(sparse)
    assert torch.equal(depth, confident(sparse))
    assert torch.allclose(conf, torch.full_like(conf, 1 / (1 + math.exp(-4.0))))  # the head's untrained gate
    with pytest.raises(DcslamError, match="needs correct_fill"):
        build_model("sparse-conv", confidence=True)


def test_a_prediction_leaves_empty_what_the_network_is_not_confident_of():
    model = build_model("sparse-conv", correct_fill=True, confidence=True)
    sparse = np.zeros((16, 24), np.float32)
    sparse[::4, ::3] = 8.0
    completer = NetworkCompleter(model, torch.device("cpu"))
    depth, conf = completer.complete(sparse)
    assert (depth > 0).all() and np.allclose(conf, 0.982, atol=1e-3)  # untrained: sure of every pixel
    with torch.no_grad():  # the gate says 0.0003 everywhere: nothing placed, nothing left
        model.correction.net[-1].bias[1] = -8.0
    depth, conf = completer.complete(sparse)
    assert (depth == 0).all() and (conf == 0).all()
    with torch.no_grad():  # 0.5 is placed
        model.correction.net[-1].bias[1] = 0.0
    assert (completer(sparse) > 0).all()
    plain = NetworkCompleter(build_model("sparse-conv", correct_fill=True), torch.device("cpu"))
    assert plain.complete(sparse)[1] is None and (plain(sparse) > 0).all()


def test_the_option_needs_a_network_with_a_confidence():
    from dcslam.stages.train import TrainStageConfig

    for config in ({"model": "sparse-conv"}, {"model": "dncnn"}):
        with pytest.raises(DcslamError, match="--confidence-weight needs a network that gives a confidence"):
            TrainStageConfig(confidence_weight=1.0, **config)
    with pytest.raises(DcslamError, match="--confidence-weight must be a non-negative number"):
        TrainStageConfig(model="nconv", confidence_weight=-1.0)
    assert TrainStageConfig(model="sparse-conv", correct_fill=True, confidence_weight=1.0).model_hparams() == {
        "correct_fill": True, "confidence": True}
    assert TrainStageConfig(model="nconv", confidence_weight=1.0).model_hparams() == {}  # its own confidence


def test_a_tiny_run_trains_the_confidence_and_predicts_with_it(cli, tmp_path):
    from dcslam.io.drive import read_layer

    ws = fixtures.write_workspace(tmp_path / "ws", n=2, extra=True)
    result = cli("train", "-w", ws, "--model", "sparse-conv", "--correct-fill", "--fill", "planefit",
                 "--fill-output", "inverse-residual", "--target", "exact", "--confidence-weight", "1",
                 "--max-frames", "2", "--epochs", "3", "--scale", "0.5", "--lr", "0.01", "--device", "cpu",
                 "--name", "sure")
    assert result.exit_code == 0, result.output
    run = ws / "runs" / "sure"
    rows = [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]
    losses = [r["confidence"] for r in rows if r["kind"] == "train"]
    assert len(losses) >= 3 and all(np.isfinite(losses)) and losses[-1] < losses[0]
    record = torch.load(run / "model.pt", weights_only=True)
    assert record["hparams"]["confidence"] is True
    assert record["state_dict"]["correction.net.6.bias"][1] != 4.0  # the gate learned
    predicted = cli("predict", "-w", ws, "--run", "sure", "--device", "cpu")
    assert predicted.exit_code == 0, predicted.output
    layer = read_layer(ws / "predictions" / "sure" / "drive_d.h5")
    assert layer.confidence is not None and np.isfinite(layer.confidence).all()
    assert ((layer.depth == 0) == (layer.confidence == 0)).all()  # empty exactly where it is not sure
    assert (layer.confidence[layer.depth > 0] >= 0.5).all()


def test_a_confidence_loss_is_refused_across_processes(tmp_path):
    """Its step runs the network outside DistributedDataParallel (as the pose loss's confidence weights do), so it
    would not share gradients: more than one process is refused before anything is trained."""
    from dcslam.depth.config import TrainConfig
    from dcslam.depth.train import train_loop

    config = TrainConfig(model="sparse-conv", confidence_weight=1.0,
                         model_hparams={"correct_fill": True, "confidence": True})
    with pytest.raises(DcslamError, match="runs in one process; pass --nproc 1"):
        train_loop(tmp_path, config, torch.device("cpu"), [], [], world=2)
    assert not list(tmp_path.iterdir())
