"""Every write fails cleanly: a full disk, a read-only filesystem, a file-size limit or an I/O error at a write of a
drive or layer file, a PNG, a JSON or text file, or a set of files is one DcslamError line naming the file and the
reason, with no temporary or partial file left; a failed HDF5 write exits 1, not with a segmentation fault.

Faults are injected by a patched write, by ``ulimit -f`` (RLIMIT_FSIZE) in a subprocess and, where this process
may mount (root), by a tiny tmpfs that fills up or is remounted read-only.
"""
from __future__ import annotations

import errno
import os
import subprocess
import sys
import textwrap
import uuid
from pathlib import Path

import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.io.atomic import AtomicSet, atomic_output, write_json_atomic, write_text_atomic

pytestmark = pytest.mark.faults
ROOT = Path(__file__).parents[2]
NO_SPACE = "no space left on device"


def _files(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir()) if folder.exists() else []


def _enospc(*args, **kwargs):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def test_a_failed_rename_is_one_line_and_leaves_no_temporary(tmp_path, monkeypatch):
    monkeypatch.setattr(os, "replace", _enospc)
    with pytest.raises(DcslamError, match=rf"^could not write {tmp_path / 'a.json'}: {NO_SPACE}$"):
        write_json_atomic(tmp_path / "a.json", {"a": 1})
    assert _files(tmp_path) == []


@pytest.mark.parametrize("number, reason", [(errno.EROFS, "read-only file system"), (errno.EIO, "input/output error"),
                                            (errno.EDQUOT, "disk quota exceeded"), (errno.EACCES, "permission denied")])
def test_each_write_errno_is_named(tmp_path, monkeypatch, number, reason):
    def fail(self, *args, **kwargs):
        raise OSError(number, os.strerror(number))

    monkeypatch.setattr(Path, "write_text", fail)
    with pytest.raises(DcslamError, match=rf"^could not write {tmp_path / 'a.txt'}: {reason}$"):
        write_text_atomic(tmp_path / "a.txt", "x")
    assert _files(tmp_path) == []


def test_an_error_reading_another_file_inside_the_block_keeps_its_own_type(tmp_path):
    with pytest.raises(FileNotFoundError):
        with atomic_output(tmp_path / "out.txt") as tmp:
            tmp.write_text((tmp_path / "missing-input.txt").read_text())
    assert _files(tmp_path) == []


def test_a_failed_write_of_a_set_member_names_the_member_and_leaves_nothing(tmp_path):
    with pytest.raises(DcslamError, match=rf"^could not write {tmp_path / 'b.txt'}: {NO_SPACE}$"):
        with AtomicSet() as files:
            files.stage(tmp_path / "a.txt").write_text("a")
            files.stage(tmp_path / "b.txt")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    assert _files(tmp_path) == []


def test_a_png_write_names_the_reason(tmp_path, monkeypatch):
    from dcslam.io import atomic
    from dcslam.io.png import write_depth_png, write_rgb_png

    real_open = open

    class Full:
        def __init__(self, path, mode):
            self._f = real_open(path, mode)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self._f.close()

        def write(self, data):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(atomic, "open", Full, raising=False)
    with pytest.raises(DcslamError, match=rf"^could not write {tmp_path / 'd.png'}: {NO_SPACE}$"):
        write_depth_png(tmp_path / "d.png", np.ones((4, 5)), 256)
    with pytest.raises(DcslamError, match=rf"^could not write {tmp_path / 'c.png'}: {NO_SPACE}$"):
        write_rgb_png(tmp_path / "c.png", np.zeros((4, 5, 3), np.uint8))
    assert _files(tmp_path) == []


WRITE_HDF5 = textwrap.dedent("""
    import resource, signal, sys
    import numpy as np
    from dcslam.errors import DcslamError
    from dcslam.io.drive import DriveFrame, DriveWriter, Layer, write_layer

    kind, path, limit = sys.argv[1], sys.argv[2], int(sys.argv[3])
    if limit:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG instead
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    rng = np.random.default_rng(0)
    try:
        if kind == "layer":
            write_layer(path, Layer(rng.random((6, 48, 64)).astype(np.float32) * 10, "d", "test"), force=True)
        else:
            with DriveWriter(path, np.array([[50.0, 0, 32], [0, 50, 24], [0, 0, 1]]), 48, 64, source="synthetic",
                             date="2011_09_26", drive="d", force=True) as writer:
                for i in range(6):
                    writer.append(DriveFrame(rng.integers(0, 255, (48, 64, 3), dtype=np.uint8),
                                             (rng.random((48, 64)) * 10).astype(np.float32),
                                             (rng.random((48, 64)) * 10).astype(np.float32), np.eye(4), 0.1 * i, i))
    except DcslamError as error:
        print(error, file=sys.stderr)
        sys.exit(1)
""")


def _write_hdf5(kind: str, path: Path, limit: int = 0) -> subprocess.CompletedProcess:
    """Write a 6-frame layer or drive file in a subprocess (under a file-size limit of ``limit`` bytes, if any)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-c", WRITE_HDF5, kind, str(path), str(limit)], capture_output=True,
                          text=True, env=env, timeout=120)


@pytest.mark.parametrize("kind", ["layer", "drive"])
def test_an_hdf5_write_past_a_file_size_limit_exits_1_with_one_line(tmp_path, kind):
    out = tmp_path / "out"
    out.mkdir()
    done = _write_hdf5(kind, out / "x.h5", limit=16384)
    assert done.returncode == 1, (done.returncode, done.stderr)  # not 139, the crash of h5py's cleanup
    assert done.stderr.strip().splitlines() == [f"could not write {out / 'x.h5'}: file too large"]
    assert _files(out) == []


@pytest.mark.parametrize("kind", ["layer", "drive"])
def test_an_hdf5_write_within_the_limit_reads_back(tmp_path, kind):
    from dcslam.io.drive import DriveFile, read_layer

    out = tmp_path / "out"
    out.mkdir()
    done = _write_hdf5(kind, out / "x.h5")
    assert done.returncode == 0, done.stderr
    if kind == "layer":
        assert read_layer(out / "x.h5").depth.shape == (6, 48, 64)
    else:
        with DriveFile(out / "x.h5") as drive:
            assert len(drive) == 6 and drive.rgb(5).shape == (48, 64, 3)


@pytest.fixture
def tiny_fs(tmp_path):
    """A 64 KiB tmpfs (root only): ``(folder, remount)`` where ``remount("ro")`` makes it read-only."""
    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root")
    folder = tmp_path / f"fs-{uuid.uuid4().hex[:6]}"
    folder.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(folder)], capture_output=True)
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {mounted.stderr.decode().strip()}")

    def remount(mode: str) -> None:
        subprocess.run(["mount", "-o", f"remount,{mode}", str(folder)], check=True)

    try:
        yield folder, remount
    finally:
        subprocess.run(["umount", "-l", str(folder)], check=False)


@pytest.mark.parametrize("kind", ["layer", "drive"])
def test_an_hdf5_write_to_a_full_disk_exits_1_with_one_line(tiny_fs, kind):
    folder, _ = tiny_fs
    done = _write_hdf5(kind, folder / "x.h5")
    assert done.returncode == 1, (done.returncode, done.stderr)
    assert done.stderr.strip().splitlines() == [f"could not write {folder / 'x.h5'}: {NO_SPACE}"]
    assert _files(folder) == []


def test_png_json_and_set_writes_to_a_full_disk_are_one_line(tiny_fs):
    from dcslam.io.png import write_rgb_png

    folder, _ = tiny_fs
    noise = np.random.default_rng(0).integers(0, 255, (200, 200, 3), dtype=np.uint8)  # ~120 kB as PNG
    with pytest.raises(DcslamError, match=rf"^could not write {folder / 'c.png'}: {NO_SPACE}$"):
        write_rgb_png(folder / "c.png", noise)
    with pytest.raises(DcslamError, match=rf"^could not write {folder / 'a.json'}: {NO_SPACE}$"):
        write_json_atomic(folder / "a.json", {"values": list(range(40000))})
    with pytest.raises(DcslamError, match=rf"^could not write {folder / 'b.txt'}: {NO_SPACE}$"):
        with AtomicSet() as files:
            files.stage(folder / "a.txt").write_text("small")
            files.stage(folder / "b.txt").write_text("x" * 100_000)
    assert _files(folder) == []


def test_writes_and_locks_on_a_read_only_filesystem_are_one_line(tiny_fs):
    from dcslam.io.png import write_depth_png
    from dcslam.locks import output_lock

    folder, remount = tiny_fs
    remount("ro")
    reason = "read-only file system"
    with pytest.raises(DcslamError, match=rf"^could not write {folder / 'd.png'}: {reason}$"):
        write_depth_png(folder / "d.png", np.ones((4, 5)), 256)
    with pytest.raises(DcslamError, match=rf"^could not write {folder / 'sub' / 'a.json'}: {reason}$"):
        write_json_atomic(folder / "sub" / "a.json", {})
    with pytest.raises(DcslamError, match=rf"^could not create the lock file {folder / '.run.lock'}: Read-only file "
                                          "system; check that its folder is writable$"):
        with output_lock(folder / "run", "run"):
            pass
    done = _write_hdf5("layer", folder / "x.h5")
    assert done.returncode == 1 and done.stderr.strip().splitlines() == [f"could not write {folder / 'x.h5'}: {reason}"]
