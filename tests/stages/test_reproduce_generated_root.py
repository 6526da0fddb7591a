"""A generated root given as ``--kitti`` (drives ``dcslam synth`` made before, e.g. another workspace's ``kitti/``) is
split as the profile splits the drives it generates itself; a real KITTI root keeps the thesis's split."""
from __future__ import annotations

import json

from dcslam.stages.prepare import THESIS_SPLITS
from dcslam.stages.experiments.common import generated_names, make_drives
from dcslam.stages.experiments.table_5_2 import PROFILES
from dcslam.stages.pipeline import Pipeline
from dcslam.stages.reproduce_plan import planned_splits
from dcslam.workspace import Workspace
from tests.fixtures.kitti import write_tiny_drive

NAMES = [f"2011_09_26_drive_{1000 + i:04d}_sync" for i in range(8)]


def _root(tmp_path, generated: bool):
    root = tmp_path / "kitti"
    for i, name in enumerate(NAMES):
        write_tiny_drive(root, name=name, n_frames=12, size=(16, 24), seed=i)
    if generated:
        (root / "SYNTHETIC").write_text("generated\n")
    return root


def test_a_generated_root_takes_the_profile_split(tmp_path):
    root = _root(tmp_path, generated=True)
    quick = PROFILES["quick"]
    assert generated_names(root, quick.split) == NAMES
    assert generated_names(root, (1, 1, 1)) is None  # another number of drives: the thesis's proportion
    ws = Workspace(tmp_path / "ws")
    assert planned_splits(ws, quick, root)["test"] == NAMES[4:]
    test, learn = make_drives(Pipeline(ws), drives=quick.drives, frames=quick.frames, split=quick.split,
                              kitti_root=root)
    assert [p.stem for p in test] == NAMES[4:] and [p.stem for p in learn] == NAMES[:4]
    assert json.loads(ws.splits.read_text())["val"] == [NAMES[3]]


def test_a_real_root_keeps_the_thesis_split_in_the_plan(tmp_path):
    root = _root(tmp_path, generated=False)
    assert generated_names(root, PROFILES["quick"].split) is None
    assert planned_splits(Workspace(tmp_path / "ws"), PROFILES["quick"], root) == THESIS_SPLITS
