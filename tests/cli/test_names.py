"""Names given on the command line or read from splits.json are plain names: nothing is written outside the
workspace or the given output."""
import json

import pytest

from tests.cli.test_filter import make_workspace



def _all_files(root):
    return sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_file())


@pytest.mark.parametrize("name", ["../../escape", "a/b", "..", ".hidden"])
def test_filter_name_that_is_not_plain_is_refused_and_nothing_is_written(cli, tmp_path, name):
    ws = make_workspace(tmp_path / "deep" / "ws")
    before = _all_files(tmp_path)
    result = cli("filter", "-w", ws, "--run", "mse-dense", "--filter", "edges", "--name", name)
    assert result.exit_code == 1
    assert result.stderr.strip().splitlines() == [
        f"error: --name {name!r} is not a plain name (no '/', '\\', and not starting with '.'); pass a name such "
        "as mse-dense+range"]
    assert _all_files(tmp_path) == before


def test_drive_name_from_splits_json_that_is_not_plain_is_refused(cli, tmp_path):
    ws = make_workspace(tmp_path / "ws")
    (ws / "drives" / "splits.json").write_text(json.dumps({"train": [], "val": [], "test": ["../../../escape"]}))
    before = _all_files(tmp_path)
    result = cli("filter", "-w", ws, "--run", "mse-dense", "--filter", "edges")
    assert result.exit_code == 1
    assert "drive name in" in result.stderr and "splits.json '../../../escape' is not a plain name" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert _all_files(tmp_path) == before


def test_train_name_that_is_not_plain_is_refused(cli, tmp_path):
    result = cli("train", "-w", tmp_path, "--name", "../outside")
    assert result.exit_code == 1 and "--name '../outside' is not a plain name" in result.stderr
    assert list(tmp_path.iterdir()) == []
