"""prepare_tum: TUM RGB-D / ICL-NUIM sequences (generated here) → drive files, splits.json, config."""
import json
from pathlib import Path

import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.io import tum_rgbd as tr
from dcslam.io.drive import DriveFile, read_splits
from dcslam.io.tum import read_tum, write_tum
from dcslam.stages.prepare_tum import prepare_tum, sparse_subsample
from dcslam.synth.indoor import generate_indoor

SCALE = 0.1  # 64 x 48 images


@pytest.fixture(scope="module")
def tum_root(tmp_path_factory) -> Path:
    """Two generated ICL-NUIM sequences of 5 frames."""
    root = tmp_path_factory.mktemp("tum")
    generate_indoor(root, sequences=2, frames=5, seed=1, scale=SCALE)
    return root


def _files(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir()) if folder.exists() else []


def write_tum_format(root: Path, n: int = 4, size=(6, 8)) -> Path:
    """A TUM RGB-D folder (rgb.txt, depth.txt, groundtruth.txt at 100 Hz) of n tiny frames."""
    rng = np.random.default_rng(0)
    rgb_t = 100.0 + 0.1 * np.arange(n)
    depth_t = rgb_t + 0.005
    for kind, times in (("rgb", rgb_t), ("depth", depth_t)):
        names = [f"{kind}/{t:.6f}.png" for t in times]
        for name in names:
            if kind == "rgb":
                tr.write_rgb_png(root / name, rng.integers(0, 255, (*size, 3), dtype=np.uint8))
            else:
                tr.write_depth_png(root / name, rng.uniform(0.5, 3.0, size))
        tr.write_list(root / f"{kind}.txt", times, names)
    gt_t = np.arange(99.9, 100.0 + 0.1 * n, 0.01)
    T = np.tile(np.eye(4), (len(gt_t), 1, 1))
    T[:, 0, 3] = gt_t - 100.0
    write_tum(root / "groundtruth.txt", gt_t, T)
    return root


def test_sparse_subsample():
    depth = np.arange(1, 101, dtype=np.float32).reshape(10, 10)
    sparse = sparse_subsample(depth, 5)
    assert np.flatnonzero(sparse.ravel()).tolist() == [22, 27, 72, 77] and sparse[2, 2] == depth[2, 2]
    assert depth[0, 0] == 1  # input untouched
    assert np.array_equal(sparse_subsample(depth, 1), depth)
    with pytest.raises(DcslamError, match="--sparse-stride"):
        sparse_subsample(depth, 0)


def test_generated_sequences(tum_root, tmp_path):
    out = tmp_path / "drives"
    result = prepare_tum(tum_root, out)
    names = ["living_room_traj0_frei_png", "living_room_traj1_frei_png"]
    assert result.source == "tum" and [(d.name, d.split, d.frames) for d in result.drives] == [
        (names[0], "train", 5), (names[1], "test", 5)]
    assert _files(out) == [f"{names[0]}.h5", f"{names[1]}.h5", "prepare-tum.json", "splits.json"]
    assert read_splits(out / "splits.json") == {"train": [names[0]], "val": [], "test": [names[1]]}
    seq = tum_root / names[1]
    times, T_gt = read_tum(seq / "livingRoom1.gt.freiburg")
    with DriveFile(out / f"{names[1]}.h5") as drive:
        assert drive.attrs["source"] == "tum" and drive.attrs["format"] == "icl-nuim" and drive.attrs["split"] == "test"
        assert drive.attrs["sparse_stride"] == 5 and drive.shape == (5, 48, 64)
        assert drive.K[1, 1] < 0 and np.allclose(drive.K, tr.read_intrinsics(seq / "intrinsics.txt"))
        assert drive.timestamps.tolist() == times.tolist() and drive.frame_ids.tolist() == [0, 1, 2, 3, 4]
        assert np.allclose(drive.poses[0], np.eye(4)) and np.allclose(drive.poses, np.linalg.inv(T_gt[0]) @ T_gt)
        dense = drive.depth("dense", 3)
        assert np.array_equal(dense, tr.read_depth_png(seq / "depth" / "3.png"))
        assert np.array_equal(drive.depth("sparse", 3), sparse_subsample(dense, 5))
        assert np.array_equal(drive.rgb(3), tr.read_rgb_png(seq / "rgb" / "3.png"))
        assert 0.03 < np.mean(drive.depth("sparse", 0) > 0) < 0.05  # the default stride 5 keeps 4 %
    config = json.loads((out / "prepare-tum.json").read_text())
    assert config["stage"] == "prepare-tum" and config["settings"]["drives"][names[0]]["format"] == "icl-nuim"


def test_one_sequence_stride_max_frames_sparse_stride(tum_root, tmp_path):
    result = prepare_tum(tum_root / "living_room_traj0_frei_png", tmp_path, stride=2, max_frames=2, sparse_stride=3)
    assert [(d.split, d.frames) for d in result.drives] == [("test", 2)]
    with DriveFile(result.drives[0].path) as drive:
        assert drive.frame_ids.tolist() == [0, 2] and drive.timestamps.tolist() == [0, 2]
        assert drive.attrs["sparse_stride"] == 3 and drive.attrs["frame_stride"] == 2
        assert np.flatnonzero(drive.depth("sparse", 1)[:, 1])[:3].tolist() == [1, 4, 7]


def test_tum_format_needs_intrinsics_for_small_images(tmp_path):
    root = write_tum_format(tmp_path / "rgbd_dataset_tiny")
    with pytest.raises(DcslamError, match=r"images are 8x6 but the default tum-rgbd intrinsics are for 640x480"):
        prepare_tum(root, tmp_path / "drives")
    assert not (tmp_path / "drives").exists()
    K = tr.make_K(7.0, 7.0, 3.5, 2.5)
    result = prepare_tum(root, tmp_path / "drives", intrinsics=K)
    with DriveFile(result.drives[0].path) as drive:
        assert drive.attrs["format"] == "tum-rgbd" and np.array_equal(drive.K, K) and len(drive) == 4
        assert drive.timestamps == pytest.approx(100.005 + 0.1 * np.arange(4))
        assert drive.poses[:, 0, 3] == pytest.approx(0.1 * np.arange(4), abs=1e-9)  # interpolated at depth times


def test_splits_file_and_existing_outputs(tum_root, tmp_path):
    splits = tmp_path / "splits.json"
    splits.write_text(json.dumps({"train": ["living_room_traj1_frei_png"], "val": [], "test": []}))
    result = prepare_tum(tum_root, tmp_path / "a", splits_file=splits, max_frames=1)
    assert [(d.name, d.split) for d in result.drives] == [("living_room_traj1_frei_png", "train")]
    assert any("1 sequence(s) in no split" in n for n in result.notes)
    splits.write_text(json.dumps({"train": ["other"], "val": [], "test": []}))
    with pytest.raises(DcslamError, match="nothing to convert"):
        prepare_tum(tum_root, tmp_path / "b", splits_file=splits)
    with pytest.raises(DcslamError, match="living_room_traj1_frei_png.h5 exists; pass --force"):
        prepare_tum(tum_root, tmp_path / "a", max_frames=1)
    assert _files(tmp_path / "a") == ["living_room_traj1_frei_png.h5", "prepare-tum.json", "splits.json"]
    prepare_tum(tum_root, tmp_path / "a", max_frames=1, force=True)
    assert len(_files(tmp_path / "a")) == 4


def test_bad_sequence_writes_nothing(tum_root, tmp_path):
    broken = tmp_path / "src"
    for name in ("living_room_traj0_frei_png", "living_room_traj1_frei_png"):
        (broken / name).mkdir(parents=True)
        for item in (tum_root / name).iterdir():
            (broken / name / item.name).symlink_to(item)
    (broken / "living_room_traj1_frei_png" / "associations.txt").unlink()
    (broken / "living_room_traj1_frei_png" / "associations.txt").write_text("0 depth/0.png 0 rgb/0.png\n"
                                                                         "1 depth/9.png 1 rgb/9.png\n")
    with pytest.raises(DcslamError, match=r"depth/9.png not found"):
        prepare_tum(broken, tmp_path / "drives")
    assert not (tmp_path / "drives").exists()
    with pytest.raises(DcslamError, match="--stride"):
        prepare_tum(tum_root, tmp_path / "drives", stride=0)
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(DcslamError, match="no TUM RGB-D or ICL-NUIM sequence"):
        prepare_tum(empty, tmp_path)


def test_stage_run_reads_the_workspace_tum_folder(tum_root, tmp_path):
    import shutil

    from dcslam.stages.prepare_tum import PrepareTumConfig, run
    from dcslam.workspace import Workspace

    ws = Workspace(tmp_path / "ws")
    shutil.copytree(tum_root, ws.root / "tum")
    result = run(ws, PrepareTumConfig(max_frames=2, sparse_stride=2))
    assert result.splits_path == ws.splits and sorted(d.frames for d in result.drives) == [2, 2]
    assert json.loads((ws.drives / "prepare-tum.json").read_text())["settings"]["sparse_stride"] == 2
