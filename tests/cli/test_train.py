import json

import pytest

from tests.fixtures import depth as fixtures


@pytest.fixture
def ws(tmp_path):
    return fixtures.write_workspace(tmp_path / "ws", n=4)


def test_train_mse_dense_writes_the_run(cli, ws):
    result = cli("train", "-w", ws, "--loss", "mse", "--mask", "dense", "--batch-size", "2", "--device", "cpu")
    assert result.exit_code == 0, result.output
    run = ws / "runs" / "mse-dense"
    assert {p.name for p in run.iterdir()} >= {"model.pt", "last.pt", "config.json", "metrics.jsonl", "curves.png"}
    settings = json.loads((run / "config.json").read_text())["settings"]
    assert (settings["loss"], settings["mask"], settings["model"], settings["map_frames"]) == \
        ("mse", "dense", "sparse-conv", 1)
    assert "best validation" in result.stdout

    again = cli("train", "-w", ws, "--batch-size", "2")
    assert again.exit_code == 1 and "--force" in again.output
    resumed = cli("train", "-w", ws, "--batch-size", "2", "--epochs", "2", "--resume")
    assert resumed.exit_code == 0, resumed.output
    rows = [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]
    assert [r["epoch"] for r in rows if r["kind"] == "val"] == [0, 1]
    record = json.loads((run / "config.json").read_text())
    assert record["settings"]["epochs"] == 2 and record["resumed"][0]["settings"]["epochs"] == 2

    other = cli("train", "-w", ws, "--batch-size", "2", "--epochs", "3", "--resume", "--lr", "0.01",
                "--name", "mse-dense", "--loss", "chamfer")
    assert other.exit_code == 1
    assert other.stderr.strip().splitlines() == [
        f"error: cannot resume {run} with other options: --loss 'chamfer' (the run has 'mse'); --lr 0.01 (the run "
        "has 0.001); resume with the run's own options (only --epochs and --device may change), or start again "
        "with --force"]
    assert [r["epoch"] for r in rows if r["kind"] == "val"] == [0, 1]
    assert json.loads((run / "config.json").read_text()) == record


def test_train_chamfer_and_sparse_names(cli, ws):
    result = cli("train", "-w", ws, "--loss", "chamfer", "--map-frames", "8", "--crop", "24",
                 "--scale", "0.5")
    assert result.exit_code == 0, result.output
    assert (ws / "runs" / "chamfer-8" / "model.pt").exists()
    result = cli("train", "-w", ws, "--mask", "sparse", "--max-frames", "2", "--name", "mine")
    assert result.exit_code == 0, result.output
    assert json.loads((ws / "runs" / "mine" / "config.json").read_text())["settings"]["mask"] == "sparse"


def test_train_errors(cli, ws, tmp_path):
    assert cli("train", "-w", tmp_path / "empty").exit_code == 1
    result = cli("train", "-w", ws, "--loss", "l1")
    assert result.exit_code == 2 and "l1" in result.output  # an unknown choice is a usage error
    assert cli("train", "-w", ws, "--scale", "0.3").exit_code == 1
    assert not (ws / "runs" / "mse-dense" / "model.pt").exists()


@pytest.mark.parametrize("args, line", [
    (["--lr", "-1"], "error: --lr must be a positive number, got -1.0"),
    (["--nproc", "0"], "error: --nproc must be >= 1, got 0"),
    (["--weight-decay", "nan"], "error: --weight-decay must be a non-negative number, got nan"),
])
def test_bad_numbers_give_one_line(cli, ws, args, line):
    result = cli("train", "-w", ws, *args)
    assert result.exit_code == 1 and result.stderr.strip().splitlines() == [line]
    assert not (ws / "runs").exists()


def test_train_with_density_mix_l1_cosine_and_filled_holes(cli, tmp_path):
    ws = fixtures.write_workspace(tmp_path / "mix", n=2, extra=True)
    result = cli("train", "-w", ws, "--device", "cpu", "--input-mix", "sparse", "--input-mix", "sparse@16",
                 "--l1-weight", "1", "--lr-schedule", "cosine", "--fill-holes", "--scale", "0.5")
    assert result.exit_code == 0, result.output
    settings = json.loads((ws / "runs" / "mse-dense-mix" / "config.json").read_text())["settings"]
    assert (settings["input_mix"], settings["l1_weight"], settings["lr_schedule"], settings["model_hparams"]) == \
        (["sparse", "sparse@16"], 1.0, "cosine", {"fill_holes": True})
    bad = cli("train", "-w", ws, "--device", "cpu", "--lr-schedule", "step")
    assert bad.exit_code == 2


def test_train_correcting_the_fill(cli, tmp_path):
    ws = fixtures.write_workspace(tmp_path / "cf", n=2)
    result = cli("train", "-w", ws, "--device", "cpu", "--model", "nconv", "--correct-fill", "--scale", "0.5",
                 "--name", "nconv-cf")
    assert result.exit_code == 0, result.output
    run_dir = ws / "runs" / "nconv-cf"
    assert json.loads((run_dir / "config.json").read_text())["settings"]["model_hparams"] == {"correct_fill": True}
    assert (run_dir / "model.pt").is_file()
    bad = cli("train", "-w", ws, "--device", "cpu", "--model", "dncnn", "--correct-fill")
    assert bad.exit_code == 1 and "--correct-fill is an option of" in bad.stderr
