"""Every command takes --config FILE (options given override it) and --print-config (exit 0, nothing written);
unknown choices are usage errors (exit 2), known errors exit 1 with one line."""
import tomllib

import pytest
COMMANDS = {  # command → options it needs to make a valid configuration, and an option to override
    "synth": ([], ("--frames", "17", "frames", 17)),
    "prepare-kitti": ([], ("--max-frames", "3", "max_frames", 3)),
    "prepare-tum": ([], ("--stride", "2", "stride", 2)),
    "train": ([], ("--loss", "chamfer", "loss", "chamfer")),
    "predict": (["--model", "ip-basic"], ("--split", "val", "split", "val")),
    "filter": (["--filter", "edges", "--depth", "dense"], ("--name", "x", "name", "x")),
    "slam": ([], ("--odometry", "gt", "odometry", "gt")),
    "score depth": (["--layer", "dense"], ("--raw", None, "raw", True)),
    "score trajectory": ([], ("--layer", "dense", "layer", "dense")),
    "score map": ([], ("--gt-layer", "sparse", "gt_layer", "sparse")),
    "score tables": ([], ("--drive", "d", "drive", ["d"])),
    "demo-icl": ([], ("--steps", "5", "steps", 5)),
    "reproduce": ([], ("--profile", "smoke", "profile", "smoke")),
}


@pytest.mark.parametrize("command", COMMANDS)
def test_print_config_then_run_it_back_with_an_override(cli, command, tmp_path):
    needed, (flag, value, key, expected) = COMMANDS[command]
    ws = tmp_path / "ws"
    printed = cli(*command.split(), *needed, "--print-config", "-w", ws)
    assert printed.exit_code == 0, printed.output
    values = tomllib.loads(printed.stdout)
    assert key in values or f"# {key} = (unset)" in printed.stdout  # unset fields are written as comments
    assert not ws.exists()  # printing the configuration writes nothing

    path = tmp_path / "config.toml"
    path.write_text(printed.stdout)
    override = [flag] if value is None else [flag, value]
    again = cli(*command.split(), "--config", path, *override, "--print-config", "-w", ws)
    assert again.exit_code == 0, again.output
    assert tomllib.loads(again.stdout)[key] == expected
    assert {k: v for k, v in tomllib.loads(again.stdout).items() if k != key} == \
        {k: v for k, v in values.items() if k != key}


@pytest.mark.parametrize("command", COMMANDS)
def test_bad_config_file_exits_1_with_one_line(cli, command, tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("no_such_option = 1\n")
    result = cli(*command.split(), *COMMANDS[command][0], "--config", path, "-w", tmp_path / "ws")
    assert result.exit_code == 1
    assert result.stderr.strip().count("\n") == 0 and "unknown key 'no_such_option'" in result.stderr


def test_config_file_values_are_used(cli, tmp_path):
    path = tmp_path / "slam.toml"
    path.write_text('odometry = "gt"\nframes = 2\n')
    result = cli("slam", "--config", path, "-w", tmp_path / "ws")  # no drives there: a known error
    assert result.exit_code == 1 and "splits.json" in result.stderr


@pytest.mark.parametrize("args", [["train", "--loss", "l1"], ["predict", "--split", "nope", "--model", "ip-basic"],
                                  ["reproduce", "--profile", "huge"], ["slam", "--odometry", "ekf"],
                                  ["filter", "--filter", "median", "--depth", "dense"], ["train", "--bogus"]])
def test_usage_errors_exit_2(cli, args, tmp_path):
    assert cli(*args, "-w", tmp_path).exit_code == 2
