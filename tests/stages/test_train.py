"""The train stage: a run from a configuration, in process or through the distributed launcher."""
import dataclasses
import json

import pytest

from dcslam.errors import DcslamError
from dcslam.stages.config import from_mapping, read_config_file
from dcslam.stages.train import TrainStageConfig, run, run_name


def test_default_run_names():
    assert [run_name("mse", "dense", 1), run_name("mse", "sparse", 8), run_name("chamfer", "dense", 8)] == \
        ["mse-dense", "mse-sparse", "chamfer-8"]
    assert TrainStageConfig(name="mine").run_name == "mine"


def test_train_writes_the_run_with_its_config(ws):
    config = TrainStageConfig(max_frames=2, scale=0.5, device="cpu", batch_size=2)
    result = run(ws, config)
    assert result.run_dir == ws.runs / "mse-dense" and result.steps == 2 and result.best is not None
    settings = json.loads((result.run_dir / "config.json").read_text())["settings"]
    assert (settings["max_frames"], settings["scale"], settings["batch_size"]) == (2, 0.5, 2)


def test_several_processes_go_through_the_launcher_with_the_same_config(ws, monkeypatch):
    config = TrainStageConfig(max_frames=2, scale=0.5, device="cpu", batch_size=2, nproc=2, name="ddp")
    launched = []

    def fake_launch(nproc, module, args):  # stands in for torchrun: one process, same configuration file
        file = args[args.index("--config") + 1]
        launched.append((nproc, module, from_mapping(TrainStageConfig, read_config_file(file))))
        run(ws, dataclasses.replace(launched[-1][2], nproc=1), force="--force" in args)
        return 0

    monkeypatch.setattr("dcslam.depth.distributed.launch", fake_launch)
    result = run(ws, config)
    assert launched == [(2, "dcslam.stages.train", config)]
    assert result.run_dir == ws.runs / "ddp" and result.steps == 2 and result.epochs == 1
    assert result.best["step"] == 2


def test_input_of_fewer_beams_and_exact_target(tmp_path):
    import pytest

    from dcslam.errors import DcslamError
    from dcslam.stages.predict import PredictConfig
    from dcslam.stages.predict import run as predict
    from dcslam.io.drive import read_layer
    from dcslam.workspace import Workspace
    from tests.fixtures.depth import write_workspace

    assert TrainStageConfig(input="sparse@16", target="exact").run_name == "mse-dense-sparse16-to-exact"
    with pytest.raises(DcslamError, match="unknown depth kind"):
        TrainStageConfig(input="sparse16")
    ws = Workspace(write_workspace(tmp_path / "ws", extra=True))
    result = run(ws, TrainStageConfig(max_frames=2, scale=0.5, device="cpu", input="sparse@16", target="exact"))
    settings = json.loads((result.run_dir / "config.json").read_text())["settings"]
    assert (settings["input"], settings["input_beams"], settings["target"]) == ("sparse@16", 16, "exact")
    layer = read_layer(predict(ws, PredictConfig(run=result.run_dir.name, device="cpu")).layers[0])
    assert layer.config["input"] == "sparse@16"  # the run's own input by default
    bare = Workspace(write_workspace(tmp_path / "bare"))
    with pytest.raises(DcslamError, match="holds no sparse@16 depth"):
        run(bare, TrainStageConfig(max_frames=2, scale=0.5, device="cpu", input="sparse@16"))


def test_several_processes_on_an_existing_run_are_refused_before_any_worker_starts(ws, monkeypatch):
    (ws.runs / "ddp").mkdir(parents=True)
    (ws.runs / "ddp" / "model.pt").write_bytes(b"mine")
    launched = []
    monkeypatch.setattr("dcslam.depth.distributed.launch", lambda *args: launched.append(args) or 0)
    with pytest.raises(DcslamError, match=r"run .*ddp exists; pass --force to overwrite it or --resume"):
        run(ws, TrainStageConfig(nproc=2, name="ddp"))
    with pytest.raises(DcslamError, match=r"last.pt not found; nothing to resume"):
        run(ws, TrainStageConfig(nproc=2, name="ddp", resume=True))
    assert launched == [] and (ws.runs / "ddp" / "model.pt").read_bytes() == b"mine"


def test_density_mix_l1_cosine_and_hole_filling_are_recorded(tmp_path):
    from dcslam.depth.models import load_model
    from dcslam.workspace import Workspace
    from tests.fixtures.depth import write_workspace

    ws = Workspace(write_workspace(tmp_path / "ws", extra=True))
    config = TrainStageConfig(max_frames=4, scale=0.5, device="cpu", epochs=2, input_mix=["sparse", "sparse@16"],
                              l1_weight=0.5, lr_schedule="cosine", fill_holes=True, lr=1e-2)
    assert config.run_name == "mse-dense-mix"
    result = run(ws, config)
    assert result.steps == 16 and result.epochs == 2
    files = sorted(p.name for p in result.run_dir.iterdir())
    assert files == ["config.json", "curves.png", "last.pt", "metrics.jsonl", "model.pt"]
    settings = json.loads((result.run_dir / "config.json").read_text())["settings"]
    assert settings["input_mix"] == ["sparse", "sparse@16"] and settings["input_beams"] == [64, 16]
    assert (settings["l1_weight"], settings["lr_schedule"]) == (0.5, "cosine")
    assert settings["model_hparams"] == {"fill_holes": True}
    model, _ = load_model(result.run_dir / "model.pt")
    assert model.fill_holes
    rates = [json.loads(line)["lr"] for line in (result.run_dir / "metrics.jsonl").read_text().splitlines()
             if json.loads(line)["kind"] == "train"]
    assert rates[0] == pytest.approx(1e-2) and all(a > b for a, b in zip(rates, rates[1:])) and rates[-1] < 1e-3


def test_fill_correcting_nconv_trains_from_the_fill_and_is_recorded(tmp_path):
    import torch

    from dcslam.depth.models import build_model, load_model
    from dcslam.workspace import Workspace
    from tests.fixtures.depth import write_workspace

    ws = Workspace(write_workspace(tmp_path / "ws", extra=True))
    config = TrainStageConfig(model="nconv", correct_fill=True, max_frames=4, scale=0.5, device="cpu", lr=1e-2)
    result = run(ws, config)
    settings = json.loads((result.run_dir / "config.json").read_text())["settings"]
    assert settings["model_hparams"] == {"correct_fill": True}
    model, _ = load_model(result.run_dir / "model.pt")
    start = build_model("nconv", correct_fill=True)
    assert model.hparams["correct_fill"] and model.correction is not None
    # training moved the correction head off zero (untrained, the network is the fill itself)
    assert not torch.equal(model.correction.net[-1].weight, start.correction.net[-1].weight)


def test_new_options_are_checked():
    with pytest.raises(DcslamError, match="--fill-holes is an option of sparse-conv"):
        TrainStageConfig(model="nconv", fill_holes=True)
    with pytest.raises(DcslamError, match="--correct-fill is an option of sparse-conv, nconv, nconv-guided, not of "
                                          "dncnn"):
        TrainStageConfig(model="dncnn", correct_fill=True)
    with pytest.raises(DcslamError, match="--l1-weight"):
        TrainStageConfig(l1_weight=-1.0)
    with pytest.raises(DcslamError, match="unknown --lr-schedule"):
        TrainStageConfig(lr_schedule="step")
    with pytest.raises(DcslamError, match="unknown depth kind"):
        TrainStageConfig(input_mix=["sparse", "sparse16"])


def test_an_input_mix_the_drives_lack_fails_with_one_line(ws):
    with pytest.raises(DcslamError, match="holds no sparse@16 depth"):
        run(ws, TrainStageConfig(max_frames=2, scale=0.5, device="cpu", input_mix=["sparse", "sparse@16"]))


def test_the_stage_declares_only_what_the_training_does_not():
    from dcslam.depth.config import TrainConfig, TrainSettings
    from dcslam.stages.config import options_of

    own = {f.name for f in dataclasses.fields(TrainStageConfig)} - {f.name for f in dataclasses.fields(TrainSettings)}
    assert own == {"fill_holes", "correct_fill", "fill", "fill_output", "name", "resume", "log", "nproc", "init"}
    assert not own & {f.name for f in dataclasses.fields(TrainConfig)}
    assert {f.name for f in dataclasses.fields(TrainSettings)} <= {f.name for f in options_of(TrainStageConfig)}
    config = TrainStageConfig(loss="pose", lr=0.02, pose_frames=3, input_mix=["sparse"], correct_fill=True,
                              model="nconv", init="nconv", name="tuned")
    made = config.train_config(["a.h5"], ["b.h5"], init_model="runs/nconv/model.pt")
    assert type(made) is TrainConfig
    assert {f.name: getattr(made, f.name) for f in dataclasses.fields(TrainSettings)} == \
        {f.name: getattr(config, f.name) for f in dataclasses.fields(TrainSettings)}
    assert (made.model_hparams, made.train_drives, made.val_drives, made.init_model) == \
        ({"correct_fill": True}, ["a.h5"], ["b.h5"], "runs/nconv/model.pt")


def test_a_moved_workspace_resumes_its_run(ws, tmp_path):
    import shutil

    from dcslam.workspace import Workspace

    config = TrainStageConfig(max_frames=2, scale=0.5, device="cpu", batch_size=2)
    run(ws, config)
    record = json.loads((ws.runs / "mse-dense" / "config.json").read_text())
    assert record["paths_relative_to"] == "workspace"
    assert record["settings"]["train_drives"] == ["drives/drive_a.h5", "drives/drive_b.h5"]
    assert record["settings"]["val_drives"] == ["drives/drive_c.h5"] and record["settings"]["init"] == ""

    moved = Workspace(tmp_path / "elsewhere" / "ws")
    shutil.move(str(ws.root), str(moved.root))
    result = run(moved, dataclasses.replace(config, epochs=2, resume=True))
    assert result.epochs == 2 and result.steps == 4
    rows = [json.loads(line) for line in (moved.runs / "mse-dense" / "metrics.jsonl").read_text().splitlines()]
    assert [r["epoch"] for r in rows if r["kind"] == "val"] == [0, 1]
    assert json.loads((moved.runs / "mse-dense" / "config.json").read_text())["settings"]["epochs"] == 2
    with pytest.raises(DcslamError, match="--max-frames 3 \\(the run has 2\\)"):
        run(moved, dataclasses.replace(config, epochs=3, resume=True, max_frames=3))


def test_a_run_recorded_with_absolute_paths_still_resumes(ws):
    config = TrainStageConfig(max_frames=2, scale=0.5, device="cpu", batch_size=2)
    run(ws, config)
    path = ws.runs / "mse-dense" / "config.json"
    record = json.loads(path.read_text())  # as runs were recorded before: absolute paths, no marker
    del record["paths_relative_to"]
    for key in ("train_drives", "val_drives"):
        record["settings"][key] = [str((ws.root / p).absolute()) for p in record["settings"][key]]
    path.write_text(json.dumps(record))
    result = run(ws, dataclasses.replace(config, epochs=2, resume=True))
    assert result.epochs == 2 and result.steps == 4
    assert json.loads(path.read_text())["settings"]["train_drives"] == record["settings"]["train_drives"]


def test_a_fine_tuned_run_records_its_start_relative_to_the_workspace(ws):
    from dcslam.stages.train import recorded_config

    run(ws, TrainStageConfig(max_frames=2, scale=0.5, device="cpu", name="first"))
    tuned = run(ws, TrainStageConfig(max_frames=2, scale=0.5, device="cpu", loss="pose", pose_frames=2,
                                     pose_iterations=2, init="first"))
    assert tuned.run_dir == ws.runs / "pose-from-first"
    assert json.loads((tuned.run_dir / "config.json").read_text())["settings"]["init"] == "runs/first/model.pt"
    assert recorded_config(tuned.run_dir).init_model == ws.runs / "first" / "model.pt"


@pytest.mark.skipif(__import__("importlib").util.find_spec("tensorboard") is None,
                    reason="tensorboard not installed (pip install 'dcslam[tensorboard]')")
def test_log_tensorboard_writes_the_metrics_rows_as_they_come_and_a_resume_replaces_the_tail(ws):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    def curves():
        events = EventAccumulator(str(ws.runs / "mse-dense" / "tensorboard"))
        events.Reload()
        return {tag: [(e.step, e.value) for e in events.Scalars(tag)] for tag in events.Tags()["scalars"]}

    def rows(kind):
        lines = (ws.runs / "mse-dense" / "metrics.jsonl").read_text().splitlines()
        return [row for row in map(json.loads, lines) if row["kind"] == kind]

    config = TrainStageConfig(max_frames=2, scale=0.5, device="cpu", batch_size=2, log="tensorboard")
    run(ws, config)
    first = curves()
    assert first["train/loss"] == [(r["step"], pytest.approx(r["loss"])) for r in rows("train")]
    assert [step for step, _ in first["val/mae_mm"]] == [r["step"] for r in rows("val")]
    run(ws, dataclasses.replace(config, epochs=2, resume=True))
    resumed = curves()
    assert resumed["train/loss"] == [(r["step"], pytest.approx(r["loss"])) for r in rows("train")]
    assert [step for step, _ in resumed["train/loss"]] == [0, 1, 2, 3]  # no step plotted twice
    run(ws, config, force=True)  # a fresh run starts the folder empty
    assert curves()["train/loss"] == [(r["step"], pytest.approx(r["loss"])) for r in rows("train")]


def test_log_tensorboard_without_the_package_fails_before_any_work(ws, monkeypatch):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "tensorboard" else real(name, *a))
    with pytest.raises(DcslamError, match="dcslam\\[tensorboard\\]"):
        run(ws, TrainStageConfig(max_frames=2, scale=0.5, device="cpu", log="tensorboard"))
    assert not (ws.runs / "mse-dense").exists()
