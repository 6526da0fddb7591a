"""What dcslam reproduce prints before it runs: its stages and their cost from measured stage timings."""
import json
from pathlib import Path

import pytest

from dcslam.errors import DcslamError
from dcslam.stages.experiments.table_5_2 import PROFILES
from dcslam.stages.reproduce import ReproduceConfig
from dcslam.stages.reproduce_cost import (CALIBRATION, SLAM_KINDS, DriveFrames, UnitCosts, estimate, measure,
                                          plan_text, planned_drives, read_costs, run_fills, shipped_costs,
                                          stage_work, unit_costs, unit_of)
from dcslam.stages.reproduce_plan import planned_splits, planned_stages
from dcslam.workspace import Workspace

DRIVES = DriveFrames({"a": 30, "b": 30, "c": 20, "t1": 32, "t2": 12},
                     {"train": ["a", "b"], "val": ["c"], "test": ["t1", "t2"]})


def test_work_of_each_stage_kind():
    assert stage_work("synth", {"drives": 4, "frames": 42}, DRIVES, 0) == ("synth", 168.0)
    assert stage_work("prepare-kitti", {}, DRIVES, 0) == ("prepare-kitti", 124.0)
    train = {"loss": "chamfer", "epochs": 2, "max_frames": 25, "stride": 1, "scale": 0.5}
    # training steps: a step's cost at the profile's scale is what its unit cost measures
    assert stage_work("train-chamfer-8", train, DRIVES, 0) == ("train-chamfer", 2 * (25 + 25 + 20))
    assert stage_work("predict-nconv", {"run": "nconv", "model": None}, DRIVES, 0) == ("predict", 44.0)
    assert stage_work("predict-ip-basic-fast", {"run": None, "model": "ip-basic-fast"}, DRIVES, 0)[0] == \
        "predict-classical"
    # every other classical completer a kind of its own (planefit costs ten times scanline)
    assert stage_work("predict-planefit-sparse16", {"run": None, "model": "planefit"}, DRIVES, 0) == \
        ("predict-planefit", 44.0)
    assert stage_work("slam-sparse-t1", {"depth": "sparse", "drive": ["t1"], "frames": 30}, DRIVES, 0) == \
        ("slam-sparse", 30.0)
    assert stage_work("slam-sparse@8-t2", {"depth": "sparse@8", "drive": ["t2"], "frames": 30}, DRIVES, 0) == \
        ("slam-sparse", 12.0)
    # a SLAM stage's kind is its input's: LiDAR-like, annotated, or a full image (a frame costs about 4x a sparse one)
    assert stage_work("slam-dense-t1", {"depth": "dense", "drive": ["t1"], "frames": 30}, DRIVES, 0)[0] == "slam-dense"
    for depth in ("predicted/planefit-sparse16", "exact", "predicted/mse-dense+edges"):
        assert stage_work("slam-x-t1", {"depth": depth, "drive": ["t1"], "frames": 30}, DRIVES, 0)[0] == \
            "slam-completed"
    assert stage_work("slam-long-sparse-t1", {"drive": ["t1"], "frames": 0}, DRIVES, 0) == ("slam-long", 32.0)
    assert stage_work("score-tables", {}, DRIVES, 70) == ("score", 70.0)  # the SLAM frames of the runs it scores
    with pytest.raises(DcslamError, match="not a stage"):
        stage_work("bake-bread", {}, DRIVES, 0)


def test_a_network_on_a_classical_fill_is_a_kind_of_its_own_and_so_are_its_predictions():
    """A network that corrects a fill computes it for every frame it trains on and predicts (the study's scaffold
    networks cost 3.4x and 2.4x a plain network's units): its kinds name the fill."""
    scaffold = {"loss": "mse", "epochs": 1, "max_frames": 25, "stride": 1, "correct_fill": True, "fill": "planefit",
                "name": "net"}
    assert stage_work("train-net", scaffold, DRIVES, 0) == ("train-mse+planefit", 70.0)
    assert stage_work("train-net", scaffold | {"correct_fill": False}, DRIVES, 0)[0] == "train-mse"
    plain = {**scaffold, "correct_fill": False, "name": "plain"}
    fills = run_fills([("train-net", scaffold), ("train-plain", plain), ("slam-x-t1", {"depth": "exact"})])
    assert fills == {"net": "planefit"}
    assert stage_work("predict-net-sparse16", {"run": "net", "model": None}, DRIVES, 0, fills) == \
        ("predict+planefit", 44.0)
    assert stage_work("predict-plain", {"run": "plain", "model": None}, DRIVES, 0, fills)[0] == "predict"
    assert stage_work("predict-net-sparse16", {"run": "net", "model": None}, DRIVES, 0)[0] == "predict"  # unknown run
    assert unit_of("predict+planefit") == "predicted frames" and unit_of("train-mse+planefit").startswith("training")


def test_scoring_is_priced_by_the_slam_frames_of_the_whole_plan():
    """A scoring stage reads every run's trajectory, depths and surfaces: its units are the SLAM frames of every SLAM
    stage of the plan, also when those are up to date and only the scoring is to run."""
    plan = Workspace(Path("/nonexistent-plan"))
    stages = planned_stages(plan, PROFILES["smoke"])
    drives = planned_drives(plan, PROFILES["smoke"], None, planned_splits(plan, PROFILES["smoke"]))
    costs = UnitCosts({"score": 1.0}, "test")
    slam_frames = sum(units for kind, (_, units, _) in estimate(stages, drives, costs).rows.items()
                      if kind.startswith("slam-"))
    assert slam_frames == 14 * 2 + 3 * 2  # 14 runs of 2 frames, 3 over the whole (2-frame) test drive
    assert estimate(stages, drives, costs).rows["score"][1] == slam_frames
    score = [s for s in stages if s.name.startswith("score-")]
    assert estimate(score, drives, costs, planned=stages).rows["score"] == (1, slam_frames, slam_frames)
    assert estimate(score, drives, costs).rows["score"][1] == 0  # without the plan: nothing known to score


def test_unit_costs_are_measured_from_the_stamps_of_finished_stages(tmp_path):
    from tests.fixtures.depth import write_workspace

    root = write_workspace(tmp_path / "ws")  # drive files a, b (train), c (val), d (test); 6 frames each
    state = root / ".reproduce"
    state.mkdir()
    slam = {"depth": "sparse", "drive": ["drive_d"], "frames": 4}
    (state / "slam-sparse-drive_d.json").write_text(json.dumps({"config": slam, "complete": True, "seconds": 2.0}))
    (state / "slam-sparse@8-drive_d.json").write_text(json.dumps({"config": slam | {"depth": "sparse@8"},
                                                                  "complete": True, "seconds": 9.0,
                                                                  "cpu_seconds": 6.0}))  # CPU seconds where recorded
    (state / "slam-x-drive_d.json").write_text(json.dumps({"config": slam, "complete": False}))  # interrupted
    (state / "broken.json").write_text("{")
    assert measure(root) == {"slam-sparse": (8.0, 8.0, 2)}  # 2 runs of 4 frames in 8 s: 1 s per SLAM frame
    costs = unit_costs(root)
    assert costs.per_unit["slam-sparse"] == 1.0 and costs.per_stage["slam-sparse"] == 0.0
    assert str(state) in costs.source and "slam-completed" in costs.source  # the kinds it lacks named, then shipped
    assert costs.per_unit["synth"] == shipped_costs().per_unit["synth"]  # the kinds it lacks: the shipped ones
    assert unit_costs(tmp_path / "empty", profile="smoke").source == shipped_costs("smoke").source
    with pytest.raises(DcslamError, match="--costs-from .* no finished stage"):
        unit_costs(root, costs_from=tmp_path / "empty")
    plan = Workspace(tmp_path / "plan")
    stages = planned_stages(plan, PROFILES["smoke"])
    drives = planned_drives(plan, PROFILES["smoke"], None, planned_splits(plan, PROFILES["smoke"]))
    assert set(drives.frames.values()) == {12 - 10}  # the frames of a generated drive that have depth
    rows = estimate(stages, drives, costs).rows
    assert rows["slam-sparse"][:2] == (1, 2.0) and rows["slam-sparse"][2] == 2.0  # one sparse run of 2 frames, 1 s
    assert rows["slam-dense"][:2] == (1, 2.0) and rows["slam-completed"][:2] == (12, 24.0)  # the other 13 runs
    fixed = UnitCosts({"slam-completed": 1.0}, "test", {"slam-completed": 0.5})
    assert estimate(stages, drives, fixed).rows["slam-completed"][2] == 12 * 0.5 + 24.0  # fixed part, then units


def test_plan_counts_stages_per_seed_and_writes_nothing(tmp_path):
    ws = Workspace(tmp_path / "ws")
    one = plan_text(ws, ReproduceConfig(profile="smoke"))
    two = plan_text(ws, ReproduceConfig(profile="smoke", seeds=2))
    assert "39 stages" in one and "1 training seed(s)" in one and "(seeds 0)" in one
    # twice the 7 trainings, 7 predictions, 4 filters and 11 + 0 SLAM runs of trained layers; the rest once
    assert "68 stages" in two and "2 training seed(s)" in two and "(seeds 0, 1)" in two
    assert "CPU-hours" in two and "unit costs measured from" in two and not (tmp_path / "ws").exists()


def test_dry_run_prints_the_plan_and_exits_0_without_writing(cli, tmp_path):
    result = cli("reproduce", "--profile", "study", "--dry-run", "-w", str(tmp_path / "ws"))
    assert result.exit_code == 0, result.output
    assert "--profile study: 8 test drive(s), 3 training seed(s)" in result.stdout and "total" in result.stdout
    assert not (tmp_path / "ws").exists()
    beams = cli("reproduce", "--table", "beams", "--profile", "study", "--dry-run", "-w", tmp_path / "ws")
    assert beams.exit_code == 0 and "--table beams --profile study" in beams.stdout
    bad = cli("reproduce", "--dry-run", "--costs-from", str(tmp_path), "-w", str(tmp_path / "ws"))
    assert bad.exit_code == 1 and "--costs-from" in bad.stderr
    assert cli("reproduce", "--seeds", "0", "--dry-run", "-w", str(tmp_path)).exit_code == 2


def _costs_file(path, profile="smoke", kinds=None):
    kinds = kinds or {"slam": {"stage_s": 0.5, "unit_s": 0.25}, "synth": {"stage_s": 1.0, "unit_s": 0.75}}
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"profiles": {profile: {"source": "a probe", "kinds": kinds}}}))
    return path


def test_costs_file_round_trip_and_malformed_files(tmp_path):
    costs = read_costs(_costs_file(tmp_path / "costs.json"), "smoke")
    assert costs.per_unit == {"slam": 0.25, "synth": 0.75} and costs.per_stage == {"slam": 0.5, "synth": 1.0}
    assert costs.source == "a probe" and costs.seconds("slam", 2, 8.0) == 2 * 0.5 + 8 * 0.25
    assert costs.seconds("filter", 1, 1.0) is None  # a kind not measured
    assert read_costs(tmp_path / "costs.json", "quick") is None  # no figures for that profile
    for text in ("{", "[]", '{"profiles": {"smoke": {"kinds": {}}}}', '{"profiles": {"smoke": {"source": "x", '
                 '"kinds": {"slam": {"unit_s": "fast"}}}}}'):
        (tmp_path / "bad.json").write_text(text)
        with pytest.raises(DcslamError, match="bad.json: cannot read the unit costs"):
            read_costs(tmp_path / "bad.json", "smoke")
    shipped = shipped_costs("smoke")  # the packaged figures: measured by the probe, a fixed and a unit part per kind
    assert {"synth", "train-chamfer", "score", *SLAM_KINDS} <= set(shipped.per_unit) and "probe" in shipped.source
    assert "not thesis's" in shipped_costs("thesis").source  # measured at another profile's settings, and says so
    without = shipped_costs("study+no-camera")  # a profile without the camera: quick's without the camera
    assert without.per_unit == shipped_costs("quick+no-camera").per_unit
    assert "profile quick+no-camera's" in without.source
    camera_pass = shipped.per_unit["slam-sparse"] - shipped_costs("smoke+no-camera").per_unit["slam-sparse"]
    assert camera_pass > 0  # the camera is priced in SLAM on sparse depth
    (tmp_path / "none.json").write_text('{"profiles": {}}')
    with pytest.raises(DcslamError, match="none.json: cannot read the unit costs"):
        shipped_costs("thesis", path=tmp_path / "none.json")


def test_a_calibration_is_the_estimate_of_its_profile(tmp_path):
    ws = Workspace(tmp_path / "ws")
    _costs_file(ws.root / ".reproduce" / CALIBRATION)
    costs = unit_costs(ws.root, profile="smoke")
    assert costs.per_unit["slam"] == 0.25 and costs.per_stage["synth"] == 1.0 and costs.source.startswith("a probe")
    assert costs.per_unit["train-mse"] == shipped_costs("smoke").per_unit["train-mse"]  # the rest: shipped
    assert unit_costs(ws.root, profile="quick").source == shipped_costs("quick").source  # not quick's
    assert "unit costs measured from a probe" in plan_text(ws, ReproduceConfig(profile="smoke"))
