"""dcslam export and dcslam import on the command line: exit codes and the files they wrote; the imported layer
taken by score, filter and slam like any other; a refused folder: exit 1, one line, nothing written."""
import json

import numpy as np
import pytest
from PIL import Image

from tests.fixtures import depth as depth_fixtures


@pytest.fixture
def ws(tmp_path):
    return depth_fixtures.write_workspace(tmp_path / "ws", n=4)


def test_export_then_import_then_score_filter_and_slam(cli, ws):
    out = ws / "devkit"
    result = cli("export", "-w", ws, "--depth", "dense", "--out", out)
    assert result.exit_code == 0, result.output
    pngs = sorted(out.rglob("*.png"))
    assert [p.relative_to(out).as_posix() for p in pngs] == [
        f"drive_d/proj_depth/groundtruth/image_02/{i:010d}.png" for i in range(4)]
    assert all(np.array(Image.open(p)).dtype == np.uint16 for p in pngs)
    assert "4 PNG(s) of layer dense" in result.stdout

    result = cli("import", "-w", ws, "--src", out, "--name", "method")
    assert result.exit_code == 0, result.output
    assert "imported 4 frame(s) of 1 drive(s) as layer method" in result.stdout
    assert sorted(p.name for p in (ws / "predictions" / "method").iterdir()) == ["config.json", "drive_d.h5"]
    assert json.loads((ws / "predictions" / "method" / "config.json").read_text())["stage"] == "import"

    result = cli("score", "depth", "-w", ws, "--layer", "method")
    assert result.exit_code == 0, result.output
    assert (ws / "results" / "depth_method.csv").is_file()
    result = cli("filter", "-w", ws, "--depth", "predicted", "--run", "method", "--filter", "range:max=30")
    assert result.exit_code == 0, result.output
    assert (ws / "filtered" / "method+range" / "drive_d.h5").is_file()
    result = cli("slam", "-w", ws, "--depth", "method", "--frames", "3")
    assert result.exit_code == 0, result.output
    assert (ws / "slam" / "method" / "drive_d.txt").is_file()
    result = cli("score", "tables", "-w", ws)
    assert result.exit_code == 0, result.output
    row = next(line for line in (ws / "results" / "table_5_2.md").read_text().splitlines() if "(imported)" in line)
    assert row.startswith("| method (imported) |") and "—" not in row.split("|")[2], row

    again = cli("export", "-w", ws, "--depth", "predicted/method", "--out", ws / "again", "--layout", "index")
    assert again.exit_code == 0, again.output
    assert sorted(p.name for p in (ws / "again").iterdir()) == [f"{i:010d}.png" for i in range(4)] + ["list.txt"]
    for exported, reexported in zip(pngs, sorted((ws / "again").glob("*.png"))):
        np.testing.assert_array_equal(np.array(Image.open(exported)), np.array(Image.open(reexported)))


def test_a_refused_import_exits_1_in_one_line_and_writes_nothing(cli, ws):
    out = ws / "devkit"
    assert cli("export", "-w", ws, "--depth", "sparse", "--out", out).exit_code == 0
    bad = out / "drive_d" / "proj_depth" / "velodyne_raw" / "image_02" / "0000000002.png"
    Image.fromarray(np.zeros((32, 64), np.uint8)).save(bad)
    result = cli("import", "-w", ws, "--src", out, "--name", "method")
    assert result.exit_code == 1
    assert result.stderr.count("\n") == 1 and str(bad) in result.stderr and "16-bit" in result.stderr
    assert not (ws / "predictions").exists()


def test_refused_exports_exit_1_and_usage_errors_exit_2(cli, ws):
    result = cli("export", "-w", ws, "--depth", "predicted/none", "--out", ws / "x")
    assert result.exit_code == 1 and "dcslam predict" in result.stderr and not (ws / "x").exists()
    assert cli("export", "-w", ws, "--depth", "dense", "--out", ws / "x", "--layout", "flat").exit_code == 2
    assert cli("import", "-w", ws, "--src", ws, "--crop", "7").exit_code == 2
    result = cli("import", "-w", ws, "--src", ws / "nowhere")
    assert result.exit_code == 1 and "not a folder" in result.stderr


def test_the_command_lines_of_the_page_parse(cli, tmp_path):
    """Every `dcslam ...` line of docs/bring-your-own-completer.md is a configuration its command accepts."""
    import re
    import shlex
    from pathlib import Path

    page = (Path(__file__).parents[2] / "docs" / "bring-your-own-completer.md").read_text()
    lines = [line.split("#")[0] for block in re.findall(r"```\n(.*?)```", page, re.S) for line in block.splitlines()
             if line.startswith("dcslam ")]
    assert len(lines) >= 8
    for line in lines:
        result = cli(*shlex.split(line)[1:], "--print-config", "-w", tmp_path / "ws")
        assert result.exit_code == 0, (line, result.output)
