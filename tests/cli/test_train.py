import json

import pytest
from typer.testing import CliRunner

from dcslam.cli import app
from tests.fixtures import depth as fixtures


@pytest.fixture
def ws(tmp_path):
    return fixtures.write_workspace(tmp_path / "ws", n=4)


def _run(*args):
    return CliRunner().invoke(app, list(args))


def test_train_mse_dense_writes_the_run(ws):
    result = _run("train", "-w", str(ws), "--loss", "mse", "--mask", "dense", "--batch-size", "2", "--device", "cpu")
    assert result.exit_code == 0, result.output
    run = ws / "runs" / "mse-dense"
    assert {p.name for p in run.iterdir()} >= {"model.pt", "last.pt", "config.json", "metrics.jsonl", "curves.png"}
    settings = json.loads((run / "config.json").read_text())["settings"]
    assert (settings["loss"], settings["mask"], settings["model"], settings["map_frames"]) == \
        ("mse", "dense", "sparse-conv", 1)
    assert "best validation" in result.stdout

    again = _run("train", "-w", str(ws), "--batch-size", "2")
    assert again.exit_code == 1 and "--force" in again.output
    resumed = _run("train", "-w", str(ws), "--batch-size", "2", "--epochs", "2", "--resume")
    assert resumed.exit_code == 0, resumed.output
    rows = [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]
    assert [r["epoch"] for r in rows if r["kind"] == "val"] == [0, 1]
    record = json.loads((run / "config.json").read_text())
    assert record["settings"]["epochs"] == 2 and record["resumed"][0]["settings"]["epochs"] == 2

    other = _run("train", "-w", str(ws), "--batch-size", "2", "--epochs", "3", "--resume", "--lr", "0.01",
                 "--name", "mse-dense", "--loss", "chamfer")
    assert other.exit_code == 1
    assert other.stderr.strip().splitlines() == [
        f"error: cannot resume {run} with other options: --loss 'chamfer' (the run has 'mse'); --lr 0.01 (the run "
        "has 0.001); resume with the run's own options (only --epochs and --device may change), or start again "
        "with --force"]
    assert [r["epoch"] for r in rows if r["kind"] == "val"] == [0, 1]
    assert json.loads((run / "config.json").read_text()) == record


def test_train_chamfer_and_sparse_names(ws):
    result = _run("train", "-w", str(ws), "--loss", "chamfer", "--map-frames", "8", "--crop", "24",
                  "--scale", "0.5")
    assert result.exit_code == 0, result.output
    assert (ws / "runs" / "chamfer-8" / "model.pt").exists()
    result = _run("train", "-w", str(ws), "--mask", "sparse", "--max-frames", "2", "--name", "mine")
    assert result.exit_code == 0, result.output
    assert json.loads((ws / "runs" / "mine" / "config.json").read_text())["settings"]["mask"] == "sparse"


def test_train_errors(ws, tmp_path):
    assert _run("train", "-w", str(tmp_path / "empty")).exit_code == 1
    result = _run("train", "-w", str(ws), "--loss", "l1")
    assert result.exit_code == 2 and "l1" in result.output  # an unknown choice is a usage error
    assert _run("train", "-w", str(ws), "--scale", "0.3").exit_code == 1
    assert not (ws / "runs" / "mse-dense" / "model.pt").exists()


@pytest.mark.parametrize("args, line", [
    (["--lr", "-1"], "error: --lr must be a positive number, got -1.0"),
    (["--nproc", "0"], "error: --nproc must be >= 1, got 0"),
    (["--weight-decay", "nan"], "error: --weight-decay must be a non-negative number, got nan"),
])
def test_bad_numbers_give_one_line(ws, args, line):
    result = _run("train", "-w", str(ws), *args)
    assert result.exit_code == 1 and result.stderr.strip().splitlines() == [line]
    assert not (ws / "runs").exists()


def test_train_with_density_mix_l1_cosine_and_filled_holes(tmp_path):
    ws = fixtures.write_workspace(tmp_path / "mix", n=2, extra=True)
    result = _run("train", "-w", str(ws), "--device", "cpu", "--input-mix", "sparse", "--input-mix", "sparse@16",
                  "--l1-weight", "1", "--lr-schedule", "cosine", "--fill-holes", "--scale", "0.5")
    assert result.exit_code == 0, result.output
    settings = json.loads((ws / "runs" / "mse-dense-mix" / "config.json").read_text())["settings"]
    assert (settings["input_mix"], settings["l1_weight"], settings["lr_schedule"], settings["model_hparams"]) == \
        (["sparse", "sparse@16"], 1.0, "cosine", {"fill_holes": True})
    bad = _run("train", "-w", str(ws), "--device", "cpu", "--lr-schedule", "step")
    assert bad.exit_code == 2


def test_train_correcting_the_fill(tmp_path):
    ws = fixtures.write_workspace(tmp_path / "cf", n=2)
    result = _run("train", "-w", str(ws), "--device", "cpu", "--model", "nconv", "--correct-fill", "--scale", "0.5",
                  "--name", "nconv-cf")
    assert result.exit_code == 0, result.output
    run_dir = ws / "runs" / "nconv-cf"
    assert json.loads((run_dir / "config.json").read_text())["settings"]["model_hparams"] == {"correct_fill": True}
    assert (run_dir / "model.pt").is_file()
    bad = _run("train", "-w", str(ws), "--device", "cpu", "--model", "dncnn", "--correct-fill")
    assert bad.exit_code == 1 and "--correct-fill is an option of" in bad.stderr


# every option of `dcslam train` with a value other than its default, and the configuration key it sets
GIVEN = [("--loss", "pose", "loss", "pose"), ("--mask", "sparse", "mask", "sparse"),
         ("--map-frames", "3", "map_frames", 3), ("--model", "nconv", "model", "nconv"), ("--epochs", "4", "epochs", 4),
         ("--lr", "0.02", "lr", 0.02), ("--weight-decay", "0.5", "weight_decay", 0.5),
         ("--max-frames", "9", "max_frames", 9), ("--stride", "2", "stride", 2), ("--scale", "0.5", "scale", 0.5),
         ("--crop", "8", "crop", 8), ("--batch-size", "3", "batch_size", 3), ("--seed", "7", "seed", 7),
         ("--device", "cpu", "device", "cpu"), ("--input", "sparse@16", "input", "sparse@16"),
         ("--input-mix", "sparse@8", "input_mix", ["sparse@8"]), ("--target", "exact", "target", "exact"),
         ("--l1-weight", "2", "l1_weight", 2.0), ("--lr-schedule", "cosine", "lr_schedule", "cosine"),
         ("--pose-frames", "5", "pose_frames", 5), ("--pose-weight", "2", "pose_weight", 2.0),
         ("--mse-weight", "0.5", "mse_weight", 0.5), ("--chamfer-weight", "0.25", "chamfer_weight", 0.25),
         ("--pose-translation-weight", "3", "pose_translation_weight", 3.0),
         ("--pose-rotation-weight", "4", "pose_rotation_weight", 4.0), ("--pose-iterations", "6", "pose_iterations", 6),
         ("--pose-grad-iterations", "2", "pose_grad_iterations", 2),
         ("--pose-max-sources", "100", "pose_max_sources", 100),
         ("--pose-source-voxel", "0.1", "pose_source_voxel", 0.1), ("--pose-weights", "none", "pose_weights", "none"),
         ("--correct-fill", None, "correct_fill", True), ("--name", "mine", "name", "mine"),
         ("--resume", None, "resume", True), ("--nproc", "2", "nproc", 2), ("--init", "first", "init", "first")]


def test_print_config_shows_every_option_under_its_key(tmp_path):
    import tomllib

    from dcslam.stages.config import from_mapping, options_of
    from dcslam.stages.train import TrainStageConfig

    assert {key for _, _, key, _ in GIVEN} == {f.name for f in options_of(TrainStageConfig)} - {"fill_holes"}
    args = [a for flag, value, _, _ in GIVEN for a in ([flag] if value is None else [flag, value])]
    result = _run("train", "-w", str(tmp_path / "ws"), *args, "--print-config")
    assert result.exit_code == 0, result.output
    printed = tomllib.loads(result.stdout)
    assert printed == {**{key: value for _, _, key, value in GIVEN}, "fill_holes": False}
    config = from_mapping(TrainStageConfig, printed).train_config([], [])  # what the training is given
    assert all(getattr(config, key) == value for _, _, key, value in GIVEN if hasattr(config, key))
    assert config.model_hparams == {"correct_fill": True} and not (tmp_path / "ws").exists()
    sparse_conv = _run("train", "-w", str(tmp_path / "ws"), "--fill-holes", "--print-config")
    assert tomllib.loads(sparse_conv.stdout)["fill_holes"] is True


@pytest.mark.parametrize("args, line", [
    (["--epochs", "0"], "epochs = 0"), (["--map-frames", "0"], "map_frames = 0"), (["--stride", "0"], "stride = 0"),
    (["--max-frames", "0"], "max_frames = 0"), (["--batch-size", "0"], "batch_size = 0"),
    (["--scale", "0.3"], "scale = 0.3"), (["--crop", "-1"], "crop = -1"), (["--l1-weight", "-1"], "l1_weight = -1"),
    (["--pose-frames", "1"], "pose_frames = 1"), (["--pose-weight", "-1"], "pose_weight = -1"),
    (["--mse-weight", "inf"], "mse_weight = inf"), (["--pose-iterations", "0"], "pose_iterations = 0"),
    (["--pose-max-sources", "-1"], "pose_max_sources = -1"),
    (["--pose-source-voxel", "nan"], "pose_source_voxel = nan"),
    (["--name", "a/b"], 'name = "a/b"'), (["--init", ".."], 'init = ".."'),
    (["--fill-holes", "--model", "nconv"], 'fill_holes = true\nmodel = "nconv"')])
def test_a_wrong_value_fails_with_one_line_naming_the_option(ws, args, line, tmp_path):
    result = _run("train", "-w", str(ws), *args)
    lines = result.stderr.strip().splitlines()
    assert result.exit_code == 1 and len(lines) == 1 and lines[0].startswith(f"error: {args[0]} "), result.stderr
    path = tmp_path / "bad.toml"  # the same value from a configuration file: the same line
    path.write_text(line + "\n")
    from_file = _run("train", "-w", str(ws), "--config", str(path))
    assert from_file.exit_code == 1 and from_file.stderr.strip().splitlines() == lines
    assert not (ws / "runs").exists()


def test_resume_after_the_workspace_moved(ws, tmp_path):
    assert _run("train", "-w", str(ws), "--device", "cpu", "--max-frames", "2").exit_code == 0
    moved = tmp_path / "moved"
    ws.rename(moved)
    resumed = _run("train", "-w", str(moved), "--device", "cpu", "--max-frames", "2", "--epochs", "2", "--resume")
    assert resumed.exit_code == 0, resumed.output
    rows = [json.loads(line) for line in (moved / "runs" / "mse-dense" / "metrics.jsonl").read_text().splitlines()]
    assert [r["epoch"] for r in rows if r["kind"] == "val"] == [0, 1]
