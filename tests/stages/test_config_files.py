"""A configuration file that cannot be read is one line naming it: a directory, bytes that are not UTF-8 (TOML and
YAML), a missing file; through the library and through a command's ``--config`` (exit 1, nothing written)."""
from __future__ import annotations

import pytest

from dcslam.errors import DcslamError
from dcslam.stages.config import read_config_file


@pytest.mark.parametrize("suffix", [".toml", ".yaml"])
def test_a_configuration_file_that_is_not_utf8_is_one_line_naming_it(tmp_path, suffix):
    path = tmp_path / f"slam{suffix}"
    path.write_bytes("frames = 3\n# caf\u00e9\n".encode("latin-1"))
    with pytest.raises(DcslamError, match=r"^configuration file .*slam\.(toml|yaml) is not UTF-8 text \(byte 16: "
                                          r"0xe9\); save it as UTF-8$"):
        read_config_file(path)


def test_a_directory_given_as_the_configuration_file_says_so(tmp_path):
    (tmp_path / "conf.toml").mkdir()
    with pytest.raises(DcslamError, match=r"^configuration file .*conf\.toml is a directory; give a \.toml or "
                                          r"\.yaml file$"):
        read_config_file(tmp_path / "conf.toml")


def test_a_missing_configuration_file_is_not_found(tmp_path):
    with pytest.raises(DcslamError, match=r"^configuration file .*none\.toml not found$"):
        read_config_file(tmp_path / "none.toml")


def test_utf8_text_beyond_ascii_reads(tmp_path):
    path = tmp_path / "score.toml"
    path.write_text('name = "caf\u00e9"\n', encoding="utf-8")
    assert read_config_file(path) == {"name": "caf\u00e9"}


@pytest.mark.parametrize("kind", ["directory", "latin-1"])
def test_slam_with_an_unreadable_config_exits_1_with_one_line_and_writes_nothing(cli, tmp_path, kind):
    config = tmp_path / "slam.toml"
    if kind == "directory":
        config.mkdir()
    else:
        config.write_bytes("# r\u00e9glages\nframes = 3\n".encode("latin-1"))
    ws = tmp_path / "ws"
    result = cli("slam", "-w", ws, "--config", config)
    assert result.exit_code == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: configuration file {config} is ")
    assert not ws.exists()
