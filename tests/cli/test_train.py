"""`dcslam train`: options → configuration (``--print-config`` read back as TOML), exit codes, one-line errors, and
the files of one short run with its resume. The trainings themselves (each loss, model and option) are the stage's
and the library's tests (tests/stages/test_train.py, tests/depth/test_train.py)."""
import json
import tomllib

import pytest

from tests.fixtures import depth as fixtures

RUN_FILES = {"model.pt", "last.pt", "config.json", "metrics.jsonl", "curves.png"}
SHORT = ["--max-frames", "2", "--scale", "0.5", "--batch-size", "2", "--device", "cpu"]


@pytest.fixture
def ws(tmp_path):
    return fixtures.write_workspace(tmp_path / "ws", n=4)


def _config(cli, *options, ws):
    """The configuration `dcslam train OPTIONS` would run, as a dict; asserts it ran nothing."""
    result = cli("train", *options, "--print-config", "-w", ws)
    assert result.exit_code == 0, result.output
    assert not ws.exists()
    return tomllib.loads(result.stdout)


@pytest.mark.parametrize("options, changed", [
    (["--loss", "chamfer", "--map-frames", "8", "--crop", "24", "--scale", "0.5"],
     {"loss": "chamfer", "map_frames": 8, "crop": 24, "scale": 0.5}),
    (["--mask", "sparse", "--max-frames", "2", "--name", "mine"], {"mask": "sparse", "max_frames": 2, "name": "mine"}),
    (["--input-mix", "sparse", "--input-mix", "sparse@16", "--l1-weight", "1", "--lr-schedule", "cosine",
      "--fill-holes"],
     {"input_mix": ["sparse", "sparse@16"], "l1_weight": 1.0, "lr_schedule": "cosine", "fill_holes": True}),
    (["--model", "nconv", "--correct-fill", "--device", "cpu"],
     {"model": "nconv", "correct_fill": True, "device": "cpu"}),
    (["--input", "sparse@16", "--target", "exact", "--epochs", "3", "--lr", "0.01", "--resume"],
     {"input": "sparse@16", "target": "exact", "epochs": 3, "lr": 0.01, "resume": True}),
])
def test_options_set_their_fields_and_nothing_else(cli, tmp_path, options, changed):
    defaults = _config(cli, ws=tmp_path / "ws")
    assert not set(changed) - set(defaults) - {"name"}          # name is unset by default (a comment)
    assert _config(cli, *options, ws=tmp_path / "ws") == {**defaults, **changed}


def test_a_short_run_writes_its_files_then_resumes_only_with_its_own_options(cli, ws):
    result = cli("train", "-w", ws, "--loss", "mse", "--mask", "dense", *SHORT)
    assert result.exit_code == 0, result.output
    assert "best validation" in result.stdout
    run = ws / "runs" / "mse-dense"
    assert {p.name for p in run.iterdir()} == RUN_FILES
    settings = json.loads((run / "config.json").read_text())["settings"]
    assert (settings["loss"], settings["mask"], settings["model"], settings["map_frames"]) == \
        ("mse", "dense", "sparse-conv", 1)

    again = cli("train", "-w", ws, *SHORT)
    assert again.exit_code == 1 and "--force" in again.stderr and len(again.stderr.strip().splitlines()) == 1

    record, metrics = (run / "config.json").read_text(), (run / "metrics.jsonl").read_text()
    other = cli("train", "-w", ws, *SHORT, "--epochs", "3", "--resume", "--lr", "0.01", "--name", "mse-dense",
                "--loss", "chamfer")
    assert other.exit_code == 1
    assert other.stderr.strip().splitlines() == [
        f"error: cannot resume {run} with other options: --loss 'chamfer' (the run has 'mse'); --lr 0.01 (the run "
        "has 0.001); resume with the run's own options (only --epochs and --device may change), or start again "
        "with --force"]
    assert (run / "config.json").read_text() == record and (run / "metrics.jsonl").read_text() == metrics

    resumed = cli("train", "-w", ws, *SHORT, "--epochs", "2", "--resume")
    assert resumed.exit_code == 0, resumed.output
    rows = [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]
    assert [r["epoch"] for r in rows if r["kind"] == "val"] == [0, 1]
    resumed_record = json.loads((run / "config.json").read_text())
    assert resumed_record["settings"]["epochs"] == 2 and resumed_record["resumed"][0]["settings"]["epochs"] == 2


def test_train_errors(cli, ws, tmp_path):
    result = cli("train", "-w", tmp_path / "empty")
    assert result.exit_code == 1 and len(result.stderr.strip().splitlines()) == 1
    result = cli("train", "-w", ws, "--loss", "l1")
    assert result.exit_code == 2 and "l1" in result.output  # an unknown choice is a usage error
    assert cli("train", "-w", ws, "--lr-schedule", "step").exit_code == 2
    result = cli("train", "-w", ws, "--scale", "0.3")
    assert result.exit_code == 1 and "scale" in result.stderr
    result = cli("train", "-w", ws, "--model", "dncnn", "--correct-fill")
    assert result.exit_code == 1 and "--correct-fill is an option of" in result.stderr
    assert not (ws / "runs").exists()


def test_help_lists_the_geometry_terms(cli):
    result = cli("train", "--help")
    assert result.exit_code == 0
    assert all(flag in result.output for flag in ("--normal-weight", "--plane-weight", "--edge-weight"))
    summary = result.output.split("Examples:")[0]
    assert all(loss in summary for loss in ("MSE", "chamfer", "pose"))  # the summary names every --loss
    result = cli("train", "--edge-weight", "much")
    assert result.exit_code == 2 and "--edge-weight" in result.output  # not a number: a usage error


@pytest.mark.parametrize("args, line", [
    (["--edge-weight", "-0.5"], "error: --edge-weight must be a non-negative number, got -0.5"),
    (["--lr", "-1"], "error: --lr must be a positive number, got -1.0"),
    (["--nproc", "0"], "error: --nproc must be >= 1, got 0"),
    (["--weight-decay", "nan"], "error: --weight-decay must be a non-negative number, got nan"),
])
def test_bad_numbers_give_one_line(cli, ws, args, line):
    result = cli("train", "-w", ws, *args)
    assert result.exit_code == 1 and result.stderr.strip().splitlines() == [line]
    assert not (ws / "runs").exists()


# every option of `dcslam train` with a value other than its default, and the configuration key it sets
GIVEN = [("--loss", "pose", "loss", "pose"), ("--mask", "sparse", "mask", "sparse"),
         ("--map-frames", "3", "map_frames", 3), ("--chamfer-distance", "plane", "chamfer_distance", "plane"),
         ("--model", "nconv", "model", "nconv"), ("--epochs", "4", "epochs", 4),
         ("--lr", "0.02", "lr", 0.02), ("--weight-decay", "0.5", "weight_decay", 0.5),
         ("--max-frames", "9", "max_frames", 9), ("--stride", "2", "stride", 2), ("--scale", "0.5", "scale", 0.5),
         ("--crop", "8", "crop", 8), ("--batch-size", "3", "batch_size", 3), ("--seed", "7", "seed", 7),
         ("--device", "cpu", "device", "cpu"), ("--input", "sparse@16", "input", "sparse@16"),
         ("--input-mix", "sparse@8", "input_mix", ["sparse@8"]), ("--target", "exact", "target", "exact"),
         ("--l1-weight", "2", "l1_weight", 2.0), ("--lr-schedule", "cosine", "lr_schedule", "cosine"),
         ("--normal-weight", "0.5", "normal_weight", 0.5), ("--plane-weight", "3", "plane_weight", 3.0),
         ("--edge-weight", "1.5", "edge_weight", 1.5), ("--confidence-weight", "0.75", "confidence_weight", 0.75),
         ("--pose-frames", "5", "pose_frames", 5), ("--pose-weight", "2", "pose_weight", 2.0),
         ("--mse-weight", "0.5", "mse_weight", 0.5), ("--chamfer-weight", "0.25", "chamfer_weight", 0.25),
         ("--pose-translation-weight", "3", "pose_translation_weight", 3.0),
         ("--pose-rotation-weight", "4", "pose_rotation_weight", 4.0), ("--pose-iterations", "6", "pose_iterations", 6),
         ("--pose-grad-iterations", "2", "pose_grad_iterations", 2),
         ("--pose-max-sources", "100", "pose_max_sources", 100),
         ("--pose-source-voxel", "0.1", "pose_source_voxel", 0.1), ("--pose-weights", "none", "pose_weights", "none"),
         ("--correct-fill", None, "correct_fill", True), ("--fill", "planefit", "fill", "planefit"),
         ("--fill-output", "inverse-residual", "fill_output", "inverse-residual"), ("--name", "mine", "name", "mine"),
         ("--resume", None, "resume", True), ("--log", "tensorboard", "log", "tensorboard"),
         ("--nproc", "2", "nproc", 2), ("--init", "first", "init", "first")]


def test_print_config_shows_every_option_under_its_key(cli, tmp_path):
    from dcslam.stages.config import from_mapping, options_of
    from dcslam.stages.train import TrainStageConfig

    assert {key for _, _, key, _ in GIVEN} == {f.name for f in options_of(TrainStageConfig)} - {"fill_holes"}
    args = [a for flag, value, _, _ in GIVEN for a in ([flag] if value is None else [flag, value])]
    result = cli("train", "-w", tmp_path / "ws", *args, "--print-config")
    assert result.exit_code == 0, result.output
    printed = tomllib.loads(result.stdout)
    assert printed == {**{key: value for _, _, key, value in GIVEN}, "fill_holes": False}
    config = from_mapping(TrainStageConfig, printed).train_config([], [])  # what the training is given
    assert all(getattr(config, key) == value for _, _, key, value in GIVEN if hasattr(config, key))
    assert config.model_hparams == {"correct_fill": True, "fill": "planefit", "fill_output": "inverse-residual"}
    assert not (tmp_path / "ws").exists()
    sparse_conv = cli("train", "-w", tmp_path / "ws", "--fill-holes", "--print-config")
    assert tomllib.loads(sparse_conv.stdout)["fill_holes"] is True


@pytest.mark.parametrize("args, line", [
    (["--epochs", "0"], "epochs = 0"), (["--map-frames", "0"], "map_frames = 0"), (["--stride", "0"], "stride = 0"),
    (["--max-frames", "0"], "max_frames = 0"), (["--batch-size", "0"], "batch_size = 0"),
    (["--scale", "0.3"], "scale = 0.3"), (["--crop", "-1"], "crop = -1"), (["--l1-weight", "-1"], "l1_weight = -1"),
    (["--pose-frames", "1"], "pose_frames = 1"), (["--pose-weight", "-1"], "pose_weight = -1"),
    (["--mse-weight", "inf"], "mse_weight = inf"), (["--pose-iterations", "0"], "pose_iterations = 0"),
    (["--pose-max-sources", "-1"], "pose_max_sources = -1"),
    (["--pose-source-voxel", "nan"], "pose_source_voxel = nan"),
    (["--normal-weight", "-1"], "normal_weight = -1"), (["--plane-weight", "nan"], "plane_weight = nan"),
    (["--edge-weight", "inf"], "edge_weight = inf"),
    (["--name", "a/b"], 'name = "a/b"'), (["--init", ".."], 'init = ".."'),
    (["--fill-holes", "--model", "nconv"], 'fill_holes = true\nmodel = "nconv"')])
def test_a_wrong_value_fails_with_one_line_naming_the_option(cli, ws, args, line, tmp_path):
    result = cli("train", "-w", ws, *args)
    lines = result.stderr.strip().splitlines()
    assert result.exit_code == 1 and len(lines) == 1 and lines[0].startswith(f"error: {args[0]} "), result.stderr
    path = tmp_path / "bad.toml"  # the same value from a configuration file: the same line
    path.write_text(line + "\n")
    from_file = cli("train", "-w", ws, "--config", path)
    assert from_file.exit_code == 1 and from_file.stderr.strip().splitlines() == lines
    assert not (ws / "runs").exists()


def test_resume_after_the_workspace_moved(cli, ws, tmp_path):
    assert cli("train", "-w", ws, "--device", "cpu", "--max-frames", "2").exit_code == 0
    moved = tmp_path / "moved"
    ws.rename(moved)
    resumed = cli("train", "-w", moved, "--device", "cpu", "--max-frames", "2", "--epochs", "2", "--resume")
    assert resumed.exit_code == 0, resumed.output
    rows = [json.loads(line) for line in (moved / "runs" / "mse-dense" / "metrics.jsonl").read_text().splitlines()]
    assert [r["epoch"] for r in rows if r["kind"] == "val"] == [0, 1]
