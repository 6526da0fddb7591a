"""`dcslam demo-icl`: exit codes, files written, bad input (one line on stderr, exit code 1)."""
import json
import shutil

import pytest

from tests.fixtures import depth as fixtures

RESULTS = {"model.pt", "results.json", "results.csv", "results.md", "denoising.png"}
TINY = ["--steps", "2", "--batch-size", "2", "--features", "4", "--layers", "3", "--device", "cpu"]


def _one_error_line(result, *words):
    assert result.exit_code == 1, result.output
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    for word in words:
        assert word in lines[0], lines[0]


@pytest.fixture
def drives(tmp_path):
    """A drives folder with splits.json (train a, b; val c; test d): small analytic street drives."""
    return fixtures.write_workspace(tmp_path / "data", n=4) / "drives"


def test_demo_on_given_drives_writes_results(cli, drives, tmp_path):
    ws = tmp_path / "ws"
    result = cli("demo-icl", "-w", ws, "--drives", drives, "--scale", "0.5", "--patch", "0", "--sigma", "0.1", *TINY)
    assert result.exit_code == 0, result.output
    out = ws / "results" / "demo-icl"
    assert {p.name for p in out.iterdir()} == RESULTS
    assert "noisy input" in result.stdout and "DnCNN (chamfer only)" in result.stdout and str(out) in result.stdout
    record = json.loads((out / "results.json").read_text())
    assert record["settings"]["sigma_m"] == 0.1 and record["settings"]["scale"] == 0.5
    assert list(record["frames"]["test"]) == ["drive_d"]  # the test split is held out
    assert set(record["frames"]["train"]) == {"drive_a", "drive_b", "drive_c"}
    assert (out / "results.csv").read_text().splitlines()[0] == "depth,mae_mm,rmse_mm,psnr_db,chamfer_m2"

    again = cli("demo-icl", "-w", ws, "--drives", drives, *TINY)
    _one_error_line(again, "--force")  # the --force run that then overwrites: test_demo_generates_indoor_rooms_once


def test_demo_generates_indoor_rooms_once(cli, tmp_path):
    ws = tmp_path / "ws"
    result = cli("demo-icl", "-w", ws, "--sequences", "2", "--frames", "2", "--scale", "0.125", *TINY)
    assert result.exit_code == 0, result.output
    splits = json.loads((ws / "demo-icl" / "drives" / "splits.json").read_text())
    assert len(splits["train"]) == 1 and len(splits["test"]) == 1
    assert {p.name for p in (ws / "results" / "demo-icl").iterdir()} == RESULTS
    record = json.loads((ws / "results" / "demo-icl" / "results.json").read_text())
    assert record["scores"]["frames"] == 2

    made = (ws / "demo-icl" / "data.json").stat().st_mtime_ns
    written = (ws / "results" / "demo-icl" / "results.json").stat().st_mtime_ns
    kept = cli("demo-icl", "-w", ws, "--sequences", "2", "--frames", "2", "--scale", "0.125", "--force", *TINY)
    assert kept.exit_code == 0, kept.output
    assert (ws / "demo-icl" / "data.json").stat().st_mtime_ns == made  # same settings: the data is reused
    assert (ws / "results" / "demo-icl" / "results.json").stat().st_mtime_ns > written  # --force rewrote it
    shutil.rmtree(ws / "results")
    _one_error_line(cli("demo-icl", "-w", ws, "--sequences", "2", "--frames", "3", *TINY), "other settings", "--force")


def test_bad_input(cli, drives, tmp_path):
    ws = tmp_path / "ws"
    _one_error_line(cli("demo-icl", "-w", ws, "--drives", tmp_path / "nowhere", *TINY), "not found")
    _one_error_line(cli("demo-icl", "-w", ws, "--drives", drives, "--sigma", "-0.1", *TINY), "--sigma")
    _one_error_line(cli("demo-icl", "-w", ws, "--scale", "0.3", *TINY), "--scale")
    _one_error_line(cli("demo-icl", "-w", ws, "--sequences", "1", *TINY), "at least 2 sequences")
    (tmp_path / "bad.h5").write_text("not a drive")
    _one_error_line(cli("demo-icl", "-w", ws, "--drives", tmp_path / "bad.h5", *TINY), "bad.h5")
    assert not (ws / "results").exists()


def test_print_config_maps_each_option_to_its_key(cli, tmp_path):
    import tomllib

    args = ["--sigma", "0.02", "--steps", "5", "--lr", "0.01", "--batch-size", "2", "--patch", "0", "--map-frames",
            "2", "--scale", "0.5", "--features", "4", "--layers", "3", "--seed", "9", "--device", "cpu", "--frames",
            "6", "--sequences", "3", "--drives", str(tmp_path / "d.h5")]
    result = cli("demo-icl", "-w", tmp_path / "ws", *args, "--print-config")
    assert result.exit_code == 0, result.output
    printed = tomllib.loads(result.stdout)
    assert printed == {"sigma": 0.02, "steps": 5, "lr": 0.01, "batch_size": 2, "patch": 0, "map_frames": 2,
                       "scale": 0.5, "features": 4, "layers": 3, "seed": 9, "device": "cpu", "frames": 6,
                       "sequences": 3, "drives": str(tmp_path / "d.h5")}
    path = tmp_path / "demo.toml"
    path.write_text(result.stdout)
    from dcslam.stages.config import from_mapping
    from dcslam.stages.demo_icl import DemoIclConfig

    experiment = from_mapping(DemoIclConfig, tomllib.loads(path.read_text())).denoise_config()
    assert (experiment.sigma_m, experiment.steps, experiment.lr, experiment.patch, experiment.seed) == \
        (0.02, 5, 0.01, 0, 9)
    again = cli("demo-icl", "-w", tmp_path / "ws", "--config", path, "--sigma", "0.03", "--print-config")
    assert tomllib.loads(again.stdout) == {**printed, "sigma": 0.03}


@pytest.mark.parametrize("option, value, line", [
    ("--sigma", "0", "sigma = 0"), ("--steps", "0", "steps = 0"), ("--patch", "-1", "patch = -1"),
    ("--lr", "0", "lr = 0.0"), ("--layers", "0", "layers = 0"), ("--scale", "0.3", "scale = 0.3")])
def test_a_wrong_value_fails_with_one_line_naming_the_option(cli, option, value, line, tmp_path):
    result = cli("demo-icl", "-w", tmp_path / "ws", option, value, "--print-config")
    _one_error_line(result, option)
    assert result.stderr.startswith(f"error: {option} ")
    path = tmp_path / "bad.toml"  # the same value from a configuration file: the same line
    path.write_text(line + "\n")
    assert cli("demo-icl", "-w", tmp_path / "ws", "--config", path).stderr == result.stderr
