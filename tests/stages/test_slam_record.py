"""``dcslam slam --record``: the recording read back with Rerun's own reader (rerun.chunk.RrdReader) holds the
entity paths, one row per frame on the ``frame`` timeline, and the trajectory the TUM file holds."""
import importlib.util
import sys

import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.io.drive import DriveFile
from dcslam.io.tum import read_tum
from dcslam.stages.slam import SlamStageConfig, run

needs_rerun = pytest.mark.skipif(importlib.util.find_spec("rerun") is None,
                                 reason="rerun-sdk not installed (pip install 'dcslam[viz]', Python >= 3.11)")

PER_FRAME = ("/world/camera", "/world/camera/image/rgb", "/world/camera/image/depth", "/world/frame/points",
             "/world/frame/sources", "/steps/verdict", "/steps/verdict_level")


def read_recording(path) -> dict:
    """{entity path: [pyarrow record batches]} of the first recording in an .rrd file."""
    from rerun.chunk import RrdReader

    chunks: dict = {}
    for chunk in RrdReader(path).stream():
        chunks.setdefault(chunk.entity_path, []).append(chunk.to_record_batch())
    return chunks


def decode_png(blob) -> np.ndarray:
    import cv2

    return cv2.imdecode(np.asarray(blob, np.uint8), cv2.IMREAD_UNCHANGED).astype(np.float64)


def column(batches, name: str) -> list:
    return [value for batch in batches if name in batch.schema.names for value in batch.column(name).to_pylist()]


@needs_rerun
def test_a_recorded_run_reads_back_with_its_frames_and_trajectory(ws):
    (result,) = run(ws, SlamStageConfig(frames=4, voxel_size=0.1, record=True))
    out = ws.slam / "dense"
    assert result.written["recording"] == out / "drive_d.rrd" and (out / "drive_d.rrd").is_file()
    assert not list(out.glob(".*tmp*"))  # written under a temporary name, renamed when complete
    chunks = read_recording(out / "drive_d.rrd")
    for entity in (*PER_FRAME, "/world/camera/image", "/world/map", "/world/trajectory/estimated",
                   "/world/trajectory/ground_truth", "/world/trajectory/companion", "/steps/pairs"):
        assert entity in chunks, entity
    for entity in PER_FRAME:  # one row per frame, frames 0..3
        assert sorted(column(chunks[entity], "frame")) == [0, 1, 2, 3], entity
    assert sorted(set(column(chunks["/world/map"], "frame"))) == [0, 3]  # every MAP_EVERY frames and the last
    assert sorted(column(chunks["/steps/pairs"], "frame")) == [1, 2, 3]  # the first frame pairs nothing
    (strip,) = column(chunks["/world/trajectory/estimated"], "LineStrips3D:strips")[0]
    _, T = read_tum(out / "drive_d.txt")
    np.testing.assert_allclose(np.array(strip), T[:, :3, 3].astype(np.float32), rtol=0, atol=1e-6)
    (truth,) = column(chunks["/world/trajectory/ground_truth"], "LineStrips3D:strips")[0]
    assert len(truth) == 4
    (companion,) = column(chunks["/world/trajectory/companion"], "LineStrips3D:strips")[0]
    (corrected,) = column(chunks["/world/trajectory/companion_road_corrected"], "LineStrips3D:strips")[0]
    assert len(corrected) == len(companion) == 4 and np.allclose(corrected[0], companion[0])
    (blob, *_), meter = column(chunks["/world/camera/image/depth"], "EncodedDepthImage:blob")[1], \
        column(chunks["/world/camera/image/depth"], "EncodedDepthImage:meter")[1]
    with DriveFile(ws.drives / "drive_d.h5") as drive:
        np.testing.assert_allclose(decode_png(blob) / meter[0], drive.depth("dense", 1), rtol=0, atol=0.5 / 256)
    texts = [text for (text,) in column(chunks["/steps/verdict"], "TextLog:text")]
    assert texts[0] == "frame 0: accepted" and all(t.startswith(f"frame {i}: ") for i, t in enumerate(texts))
    with pytest.raises(DcslamError, match=r"drive_d\.(txt|rrd) exists; pass --force"):
        run(ws, SlamStageConfig(frames=4, voxel_size=0.1, record=True))


@needs_rerun
def test_the_recording_is_checked_before_any_work(ws):
    (ws.slam / "dense").mkdir(parents=True)
    (ws.slam / "dense" / "drive_d.rrd").write_bytes(b"not ours")
    with pytest.raises(DcslamError, match=r"drive_d\.rrd exists; pass --force"):
        run(ws, SlamStageConfig(odometry="gt", frames=2, record=True))
    assert not (ws.slam / "dense" / "drive_d.txt").exists()
    run(ws, SlamStageConfig(odometry="gt", frames=2, record=False))  # without --record the file is not ours


def test_without_rerun_record_fails_in_one_line_naming_the_extra(ws, monkeypatch):
    monkeypatch.setitem(sys.modules, "rerun", None)  # import rerun raises ImportError
    expected = r"pip install 'dcslam\[viz\]'" if sys.version_info >= (3, 11) else r"Python >= 3\.11"
    with pytest.raises(DcslamError, match=expected):
        run(ws, SlamStageConfig(odometry="gt", frames=2, record=True))
    assert not ws.slam.exists() or not any(ws.slam.rglob("*.txt"))


@needs_rerun
def test_the_command_writes_the_recording_beside_the_summary(cli, ws):
    result = cli("slam", "-w", ws.root, "--odometry", "gt", "--frames", "2", "--voxel-size", "0.1", "--record")
    assert result.exit_code == 0, result.output
    out = ws.slam / "dense"
    assert {p.name for p in out.iterdir()} == {"drive_d.txt", "drive_d.kitti.txt", "drive_d.ply", "drive_d.json",
                                               "drive_d.done", "drive_d.rrd"}
    assert sorted(column(read_recording(out / "drive_d.rrd")["/world/camera"], "frame")) == [0, 1]


def test_the_command_without_rerun_exits_1_in_one_line(cli, ws, monkeypatch):
    monkeypatch.setitem(sys.modules, "rerun", None)
    result = cli("slam", "-w", ws.root, "--odometry", "gt", "--frames", "2", "--record")
    assert result.exit_code == 1 and result.stderr.count("\n") == 1 and "--record" in result.stderr
