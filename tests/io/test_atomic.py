"""Atomic writes: the file appears whole or not at all, and is not replaced without force."""
import json
import os

import pytest

from dcslam.errors import DcslamError
from dcslam.io.atomic import atomic_output, write_json_atomic, write_text_atomic


def test_text_and_json_round_trip(tmp_path):
    write_text_atomic(tmp_path / "a" / "b.txt", "hello\n")
    assert (tmp_path / "a" / "b.txt").read_text() == "hello\n"
    write_json_atomic(tmp_path / "c.json", {"path": tmp_path, "n": 3})
    assert json.loads((tmp_path / "c.json").read_text()) == {"path": str(tmp_path), "n": 3}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a", "c.json"]


def test_existing_file_needs_force(tmp_path):
    write_text_atomic(tmp_path / "x.txt", "old")
    with pytest.raises(DcslamError, match="--force"):
        write_text_atomic(tmp_path / "x.txt", "new", force=False)
    assert (tmp_path / "x.txt").read_text() == "old"


def test_interrupted_write_leaves_the_old_file_and_no_temporary(tmp_path):
    (tmp_path / "x.txt").write_text("old")
    with pytest.raises(KeyboardInterrupt):
        with atomic_output(tmp_path / "x.txt", force=True) as tmp:
            tmp.write_text("half")
            raise KeyboardInterrupt
    assert [p.name for p in tmp_path.iterdir()] == ["x.txt"]
    assert (tmp_path / "x.txt").read_text() == "old"


def test_json_refuses_objects_it_cannot_write(tmp_path):
    with pytest.raises(TypeError, match="object"):
        write_json_atomic(tmp_path / "y.json", {"x": object()})
    assert not list(tmp_path.iterdir())


def test_json_never_holds_bare_nan(tmp_path):
    import numpy as np

    path = write_json_atomic(tmp_path / "s.json", {"drift": float("nan"), "poses": np.array([1.0, np.inf]),
                                                    "nested": [{"x": -np.inf}], "ok": 2.5})
    assert json.loads(path.read_text(), parse_constant=lambda c: pytest.fail(f"bare {c}")) == {
        "drift": None, "poses": [1.0, None], "nested": [{"x": None}], "ok": 2.5}


def test_atomic_set_appears_together_or_not_at_all(tmp_path):
    from dcslam.io.atomic import AtomicSet

    (tmp_path / ".b.txt.set-1").write_text("left by an interrupted run")
    with pytest.raises(KeyboardInterrupt):
        with AtomicSet() as files:
            files.stage(tmp_path / "a.txt").write_text("a")
            files.stage(tmp_path / "b.txt").write_text("b")
            raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []
    with AtomicSet() as files:
        files.stage(tmp_path / "a.txt").write_text("a")
        files.stage(tmp_path / "b.txt").write_text("b")
        assert not (tmp_path / "a.txt").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.txt"]


def _dead_pid() -> int:
    """The id of a process that has exited."""
    import subprocess
    import sys

    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_every_kind_of_temporary_a_killed_writer_left_is_removed_by_the_next_write(tmp_path):
    """A SIGKILL runs no cleanup: the next write of the same files removes what the killed process left."""
    from dcslam.io.atomic import AtomicSet, atomic_output

    dead = _dead_pid()
    left = [tmp_path / f".d.h5.tmp-{dead}", tmp_path / f".d.h5.set-{dead}", tmp_path / f"..d.h5.set-{dead}.tmp-{dead}"]
    for path in left:
        path.write_text("left by a killed run")
    with AtomicSet() as files, atomic_output(files.stage(tmp_path / "d.h5"), force=True) as tmp:
        tmp.write_text("new")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.h5"]
    (tmp_path / f".e.txt.tmp-{dead}").write_text("left by a killed run")
    live = tmp_path / f".e.txt.tmp-{os.getppid()}"  # a writer that still runs keeps its temporary file
    live.write_text("being written")
    with atomic_output(tmp_path / "e.txt") as tmp:
        tmp.write_text("e")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["d.h5", "e.txt", live.name])


def test_a_writer_that_died_but_was_not_yet_reaped_leaves_a_temporary_the_next_write_removes(tmp_path):
    """A zombie (ended, its parent has not waited for it yet) answers signal 0 but writes nothing any more."""
    import subprocess
    import sys
    import time

    from dcslam.locks import process_alive

    child = subprocess.Popen([sys.executable, "-c", "pass"])
    try:
        deadline = time.monotonic() + 30
        while process_alive(child.pid) and time.monotonic() < deadline:  # ended, never waited for: a zombie
            time.sleep(0.05)
        os.kill(child.pid, 0)  # the pid is still taken
        left = tmp_path / f".f.txt.tmp-{child.pid}"
        left.write_text("left by a writer that died")
        with atomic_output(tmp_path / "f.txt") as tmp:
            tmp.write_text("f")
        assert sorted(p.name for p in tmp_path.iterdir()) == ["f.txt"]
    finally:
        child.wait()
