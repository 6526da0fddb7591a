"""CommittedSet / is_committed: a set of files is complete or, for every reader, absent."""
from __future__ import annotations

import errno
import json
import os

import pytest

from dcslam.errors import DcslamError
from dcslam.io.atomic import COMMIT_SCHEMA, CommittedSet, committed_files, is_committed, write_json_atomic


def _write_set(out, text="0 0 0 0 0 0 0 1\n"):
    with CommittedSet(out / "d.done") as files:
        files.stage(out / "d.txt").write_text(text)
        write_json_atomic(files.stage(out / "d.json"), {"frames": 2})
    return out / "d.done"


def test_a_completed_set_is_committed_and_lists_its_files(tmp_path):
    marker = _write_set(tmp_path)
    assert is_committed(marker)
    assert committed_files(marker) == [tmp_path / "d.txt", tmp_path / "d.json"]
    record = json.loads(marker.read_text())
    assert record["schema"] == COMMIT_SCHEMA and record["files"][0] == {"name": "d.txt", "bytes": 16}


def test_a_failure_inside_the_set_leaves_no_marker_and_no_files(tmp_path):
    with pytest.raises(DcslamError, match="no space left on device"):
        with CommittedSet(tmp_path / "d.done") as files:
            files.stage(tmp_path / "d.txt").write_text("x")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    assert not is_committed(tmp_path / "d.done") and list(tmp_path.iterdir()) == []


def test_redoing_a_set_uncommits_the_old_one_until_the_new_one_is_complete(tmp_path):
    marker = _write_set(tmp_path)
    with pytest.raises(KeyboardInterrupt):
        with CommittedSet(marker) as files:
            files.stage(tmp_path / "d.txt").write_text("new")
            raise KeyboardInterrupt
    assert not marker.exists() and not is_committed(marker)


def test_a_failed_marker_write_leaves_the_set_uncommitted(tmp_path, monkeypatch):
    import dcslam.io.atomic as atomic

    def full(*args, **kwargs):
        raise DcslamError(f"could not write {tmp_path / 'd.done'}: no space left on device")

    monkeypatch.setattr(atomic, "write_json_atomic", full)
    with pytest.raises(DcslamError, match="d.done: no space left on device"):
        with CommittedSet(tmp_path / "d.done") as files:
            files.stage(tmp_path / "d.txt").write_text("x")
    assert (tmp_path / "d.txt").exists() and not is_committed(tmp_path / "d.done")


def test_a_missing_or_changed_file_or_a_malformed_marker_is_not_committed(tmp_path):
    marker = _write_set(tmp_path)
    (tmp_path / "d.txt").write_text("changed by hand, longer\n")
    with pytest.raises(DcslamError, match=r"d\.txt: changed since it was committed \(committed by .*d\.done\); rerun"):
        committed_files(marker)
    (tmp_path / "d.txt").unlink()
    with pytest.raises(DcslamError, match=r"d\.txt: missing"):
        committed_files(marker)
    marker.write_text("{not json")
    with pytest.raises(DcslamError, match=r"d\.done: not a readable commit marker"):
        committed_files(marker)
    marker.write_text(json.dumps({"schema": "other", "files": []}))
    with pytest.raises(DcslamError, match=r"not a dcslam\.commit/1 commit marker"):
        committed_files(marker)
    marker.unlink()
    with pytest.raises(DcslamError, match=r"d\.done not found: the output set was not completed"):
        committed_files(marker)
    assert not is_committed(marker)
