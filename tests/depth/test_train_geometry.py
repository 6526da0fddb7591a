"""Geometry terms in training (``normal_weight``, ``plane_weight``, ``edge_weight``): each is added to the loss with
its weight and changes its gradient, is logged in metrics.jsonl (training and validation), combines with the MSE,
chamfer and pose losses, names its run and recipe, and refuses a bad weight naming the option; and the chamfer loss
with the point-to-plane distance (``chamfer_distance``)."""
import json
import math

import pytest
import torch

from dcslam.depth.data import DriveFrames
from dcslam.depth.losses import GeometryTerms
from dcslam.depth.maps import stacked_points_map
from dcslam.depth.recipes import GEOMETRY_TERMS, recipe_label
from dcslam.depth.train import Objective, TrainConfig, initial_model, run_model
from dcslam.errors import DcslamError
from dcslam.stages.train import TrainStageConfig, train
from tests.fixtures.depth import write_workspace


@pytest.fixture(scope="module")
def ws(tmp_path_factory):
    return write_workspace(tmp_path_factory.mktemp("geometry") / "ws", n=2, extra=True)


def _config(ws, **kw):
    drives = ws / "drives"
    base = dict(train_drives=[drives / "drive_a.h5"], val_drives=[drives / "drive_c.h5"], model="sparse-conv",
                model_hparams={"channels": 4}, batch_size=2, device="cpu", target="exact")
    base.update(kw)
    return TrainConfig(**base)


def _rows(run):
    return [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]


@pytest.fixture
def no_curves(monkeypatch):
    """Runs without curves.png (the plot costs more than these runs' training; one run here keeps it)."""
    monkeypatch.setattr("dcslam.report.plots.plot_training_curves", lambda *args: None)


def _checked_run(ws, name, weights, **kw):
    """The train and val rows of a 1-epoch run with ``weights``; asserts each term is logged, finite and added to
    the loss with its weight, and that the model file loads without pickled code."""
    run = ws / "runs" / name
    train(run, _config(ws, **{f"{t}_weight": w for t, w in weights.items()}, **kw), force=True)
    rows = _rows(run)
    first = next(r for r in rows if r["kind"] == "train")
    val = [r for r in rows if r["kind"] == "val"]
    for row in (first, *val):
        assert all(math.isfinite(row[t]) and row[t] >= 0 for t in weights), row
    assert not set(GEOMETRY_TERMS) - set(weights) & set(first)  # a term without weight is not computed
    assert torch.load(run / "model.pt", weights_only=True)["arch"] == "sparse-conv"
    return first, val


def test_mse_with_every_term(ws):
    weights = {"normal": 2.0, "plane": 0.5, "edge": 3.0}
    first, val = _checked_run(ws, "mse-geometry", weights)
    assert first["loss"] == pytest.approx(first["mse"] + sum(w * first[t] for t, w in weights.items()), rel=1e-5)
    assert len(val) == 1 and set(weights) <= set(val[0])
    assert (ws / "runs" / "mse-geometry" / "curves.png").stat().st_size > 0




def test_pose_with_a_term(ws, no_curves):
    first, val = _checked_run(ws, "pose-plane", {"plane": 0.5}, loss="pose", pose_frames=2, pose_iterations=2)
    assert first["loss"] == pytest.approx(first["pose"] + 0.5 * first["plane"], rel=1e-5)
    assert {"pose", "plane"} <= set(val[0])


def test_chamfer_with_a_term_and_either_distance(ws, no_curves):
    point, _ = _checked_run(ws, "chamfer-edge", {"edge": 2.0}, loss="chamfer")
    assert point["loss"] == pytest.approx(point["chamfer"] + 2.0 * point["edge"], rel=1e-5)
    plane, _ = _checked_run(ws, "chamfer-p2plane", {"edge": 2.0}, loss="chamfer", chamfer_distance="plane")
    assert 0 < plane["chamfer"] < point["chamfer"]  # the same maps: a distance along the normal is the shorter
    assert plane["edge"] == pytest.approx(point["edge"], rel=1e-6)
    with pytest.raises(DcslamError, match="maps have normals"):
        train(ws / "runs" / "no-normals", _config(ws, loss="chamfer", chamfer_distance="plane"),
              map_builder=stacked_points_map, force=True)
    with pytest.raises(DcslamError, match="--chamfer-distance"):
        _config(ws, chamfer_distance="line")


@pytest.mark.parametrize("term", GEOMETRY_TERMS)
def test_each_weight_changes_the_loss_and_its_gradient(ws, term):
    frames = DriveFrames(ws / "drives" / "drive_a.h5", 2, 1, 1.0, 0, "sparse", "exact")
    try:
        batch = frames.load(range(2))
    finally:
        frames.close()
    results = []
    for weight in (0.0, 1.0):
        config = _config(ws, **{f"{term}_weight": weight})
        torch.manual_seed(0)
        model = initial_model(config)
        objective = Objective(config)
        loss = objective(run_model(model, batch), batch)
        loss.backward()
        gradient = torch.cat([p.grad.flatten() for p in model.parameters()])
        results.append((float(loss.detach()), gradient, objective.parts))
    (plain, g0, _), (weighted, g1, parts) = results
    assert parts[term] > 0 and weighted == pytest.approx(plain + parts[term], rel=1e-5)
    assert not torch.allclose(g0, g1)


def test_geometry_terms_gradcheck():
    # the weighted sum of the three terms, float64, on a depth step with a tilted side (normals, planes and an edge)
    K = torch.tensor([[30.0, 0, 7], [0, 30.0, 3], [0, 0, 1]], dtype=torch.float64)
    reference = torch.full((1, 1, 6, 14), 10.0, dtype=torch.float64)
    reference[..., :7] = 5.0 + 0.1 * torch.arange(7, dtype=torch.float64)
    pred = (reference + 0.05 * torch.randn(reference.shape, generator=torch.Generator().manual_seed(0),
                                           dtype=torch.float64)).requires_grad_()
    geometry = GeometryTerms(normal=1.0, plane=2.0, edge=0.5)
    assert set(geometry(pred, reference, K)) == set(GEOMETRY_TERMS)
    assert torch.autograd.gradcheck(lambda d: geometry.weighted(geometry(d, reference, K)), (pred,))


@pytest.mark.parametrize("term", GEOMETRY_TERMS)
@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf")])
def test_a_bad_weight_names_its_option(ws, term, bad):
    with pytest.raises(DcslamError, match=f"^--{term}-weight must be a non-negative number"):
        _config(ws, **{f"{term}_weight": bad})
    with pytest.raises(DcslamError, match=f"^--{term}-weight"):
        GeometryTerms(**{term: bad})


def test_run_names_and_recipe_labels():
    assert TrainStageConfig(normal_weight=1, edge_weight=0.5, target="exact").run_name == \
        "mse-dense-normal-edge-to-exact"
    assert TrainStageConfig(loss="chamfer", map_frames=8, plane_weight=1).run_name == "chamfer-8-plane"
    assert TrainStageConfig(normal_weight=0).run_name == "mse-dense"
    assert recipe_label({"loss": "mse", "mask": "dense", "normal_weight": 1, "plane_weight": 2, "edge_weight": 3}) \
        == "MSE dense mask + normal/plane/edge"
    assert recipe_label({"loss": "pose", "edge_weight": 1.0}) == "pose from scratch + edge"
    assert recipe_label({"loss": "chamfer", "map_frames": 8, "normal_weight": 0.0}) == "chamfer multi-frame"
    assert TrainStageConfig(loss="chamfer", map_frames=8, chamfer_distance="plane").run_name == "chamfer-p2plane-8"
    assert recipe_label({"loss": "chamfer", "map_frames": 1, "chamfer_distance": "plane"}) == \
        "chamfer single-frame, point-to-plane"
