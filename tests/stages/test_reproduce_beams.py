"""``dcslam reproduce --table beams`` at the smoke profile: exit code, files, skipping on a rerun, and the refusal of
rows made with different SLAM settings. The drives are the tiny analytic ones of the stage tests (with ``sparse@16``
and ``exact``) in place of generated KITTI drives, so that the whole experiment runs in seconds; every other stage
(training, prediction, confidence filter, SLAM, scoring) runs for real."""
import csv
import json

import pytest

from dcslam.errors import DcslamError
from dcslam.stages.experiments import beams as reproduce_beams
from dcslam.stages.experiments.beams import PROFILES, BeamsProfile
from tests.fixtures import depth as depth_fixtures
from tests.fixtures.slam_outputs import commit_slam

ARGS = ["reproduce", "--table", "beams", "--profile", "smoke"]


@pytest.fixture
def tiny_drives(monkeypatch):
    """synth and prepare-kitti replaced by the tiny drive files (4 drives of 6 frames, 32 × 64; 64 and 16 beams)."""
    def synth(ws, config, *, force=False):
        ws.kitti.mkdir(parents=True, exist_ok=True)
        (ws.kitti / "SYNTHETIC").write_text("tiny drives of the beams test\n")

    def prepare(ws, config, *, force=False):
        assert list(config.beams) == [16]  # the profile's beam counts other than 64
        depth_fixtures.write_workspace(ws.root, n=6, extra=True)

    monkeypatch.setattr("dcslam.stages.synth.run", synth)
    monkeypatch.setattr("dcslam.stages.prepare.run", prepare)


@pytest.mark.slow  # every completer at every beam count, end to end
def test_smoke_profile_writes_the_table_the_per_drive_csv_and_the_plot(cli, tmp_path, tiny_drives):
    result = cli(*ARGS, "--workspace", tmp_path)
    assert result.exit_code == 0, result.output
    results = tmp_path / "results"
    for name in ("table_beams.md", "table_beams.csv", "table_beams_per_drive.csv", "table_beams_correlation.csv",
                 "beams_localisation.png"):
        assert (results / name).stat().st_size > 0, name
    assert "The beams experiment" in result.stdout and "depth metrics against localisation" in result.stdout
    with open(results / "table_beams.csv") as f:
        rows = list(csv.DictReader(f))
    depth_rows = ("sparse", "IP-Basic", "SparseConvNet", "SparseConvNet → exact", "SparseConvNet geometry", "nconv",
                  "nconv masked", "nconv-guided", "nconv pose")
    measured_rows = tuple(f"{label}, measured sources" for label in (
        "IP-Basic", "SparseConvNet", "SparseConvNet → exact", "SparseConvNet geometry", "nconv", "nconv-guided",
        "nconv pose", "exact"))
    assert [(r["beams"], r["input"]) for r in rows][:17] == [("64", label) for label in depth_rows + measured_rows]
    assert len(rows) == 2 * 17 + 2 and not any(r["missing"] for r in rows)
    assert {r["sources"] for r in rows if r["input"] in measured_rows} == {"measured"}
    assert all(r["drives"] == "1" and r["localisation"] for r in rows)
    for layer in ("sparse", "sparse@16", "nconv-sparse16+masked", "nconv-guided-sparse64", "nconv-pose-sparse16",
                  "exact", "dense", "sparse-conv-exact-sparse16", "sparse-conv-geometry-sparse64",
                  "ip-basic-fast-sparse16+measured", "nconv-pose-sparse64+measured", "exact+measured-sparse16",
                  "exact+measured-sparse64"):
        assert (tmp_path / "slam" / layer / "drive_d.txt").exists(), layer
    with open(results / "table_beams_per_drive.csv") as f:
        assert len(list(csv.DictReader(f))) == 2 * 17 + 2  # one test drive
    # the measured-source runs align the B-beam pixels against the map of their layer
    for name, depth, kind in (("exact+measured-sparse16", "exact", "sparse@16"),
                              ("nconv-sparse16+measured", "predicted/nconv-sparse16", "sparse@16"),
                              ("ip-basic-fast-sparse64+measured", "predicted/ip-basic-fast-sparse64", "sparse")):
        record = json.loads((tmp_path / "slam" / name / "drive_d.json").read_text())
        assert record["sources"] == {"mode": "measured", "kind": kind} and record["settings"]["depth"] == depth
    assert json.loads((tmp_path / "slam" / "nconv-sparse16" / "drive_d.json").read_text())["sources"] == {
        "mode": "depth"}
    geometry = json.loads((tmp_path / "runs" / "sparse-conv-geometry" / "config.json").read_text())["settings"]
    assert (geometry["model"], geometry["target"], geometry["normal_weight"], geometry["plane_weight"],
            geometry["edge_weight"]) == ("sparse-conv", "exact", 100.0, 7.0, 10.0)
    exact = json.loads((tmp_path / "runs" / "sparse-conv-exact" / "config.json").read_text())["settings"]
    assert (exact["model"], exact["target"], exact["normal_weight"]) == ("sparse-conv", "exact", 0.0)
    masked = json.loads((tmp_path / "filtered" / "nconv-sparse16+masked" / "config.json").read_text())
    keep = PROFILES["smoke"].confidence_keep
    assert masked["settings"]["filters"] == [{"filter": "confidence", "min": 0.0, "keep": keep}]
    guided = json.loads((tmp_path / "runs" / "nconv-guided" / "config.json").read_text())["settings"]
    assert (guided["model"], guided["model_hparams"]) == ("nconv-guided", {"correct_fill": True})
    # the pose-loss run fine-tunes nconv, its confidence as ICP weights, and its SLAM runs use that confidence
    pose = json.loads((tmp_path / "runs" / "nconv-pose" / "config.json").read_text())["settings"]
    assert (pose["loss"], pose["model"], pose["pose_weights"]) == ("pose", "nconv", "confidence")
    assert pose["init"].endswith("runs/nconv/model.pt")
    val = [json.loads(line) for line in (tmp_path / "runs" / "nconv-pose" / "metrics.jsonl").read_text().splitlines()
           if '"val"' in line]
    assert val and "pose_translation_m" in val[-1]
    slam_summary = json.loads((tmp_path / "slam" / "nconv-pose-sparse16" / "drive_d.json").read_text())
    assert slam_summary["settings"]["confidence"] == "weights"

    # the rows scored in worker processes give the same table
    from dcslam.report.table_beams import build_beams_report
    from dcslam.workspace import Workspace

    build_beams_report(Workspace(tmp_path), [64, 16], ["drive_d"], out_dir=tmp_path / "parallel", jobs=2)
    assert (tmp_path / "parallel" / "table_beams.csv").read_text() == (results / "table_beams.csv").read_text()

    again = cli(*ARGS, "--workspace", tmp_path)
    assert again.exit_code == 0, again.output
    assert "[run]" not in again.stderr and again.stderr.count("[skip]") >= 60

    # one row's SLAM run made with another setting: the table is refused, with exit code 1 and one line
    summary = tmp_path / "slam" / "nconv-sparse16" / "drive_d.json"
    record = json.loads(summary.read_text())
    record["settings"]["voxel_size"] = 0.5
    summary.write_text(json.dumps(record))
    commit_slam(summary.parent, "drive_d")  # a committed set, made otherwise: the settings check is what refuses it
    mixed = cli(*ARGS, "--workspace", tmp_path)
    assert mixed.exit_code == 1
    assert "different settings" in mixed.stderr and "voxel_size=0.5 for nconv at 16 beams" in mixed.stderr


def test_profiles_hold_the_training_options_of_every_completer_and_the_full_beam_count():
    quick = PROFILES["quick"]
    assert quick.beams == (64, 32, 16, 8) and quick.split[2] >= 4 and set(quick.train) == {
        "sparse-conv", "sparse-conv-exact", "sparse-conv-geometry", "nconv", "nconv-guided", "nconv-pose"}
    assert quick.stages_of_training() == [["sparse-conv", "sparse-conv-exact", "sparse-conv-geometry", "nconv",
                                           "nconv-guided"], ["nconv-pose"]]
    # drives without exact depth: not the runs trained against it
    assert quick.stages_of_training(exact=False) == [["sparse-conv", "nconv", "nconv-guided"], ["nconv-pose"]]
    for name, profile in PROFILES.items():  # the exact and geometry recipes: SparseConvNet's, plus their target
        plain = profile.train_config("sparse-conv", seed=0)
        for run, extra in (("sparse-conv-exact", {}), ("sparse-conv-geometry", {
                "normal_weight": 100.0, "plane_weight": 7.0, "edge_weight": 10.0})):
            config = profile.train_config(run, seed=0)
            assert (config.model, config.target, config.name) == ("sparse-conv", "exact", run), name
            for field in ("epochs", "max_frames", "scale", "l1_weight", "lr", "input_mix", "model_hparams"):
                value = getattr(config, field)
                assert (value() if callable(value) else value) == (
                    getattr(plain, field)() if callable(getattr(plain, field)) else getattr(plain, field)), field
            for field in ("normal_weight", "plane_weight", "edge_weight"):
                assert getattr(config, field) == extra.get(field, 0.0), (name, run, field)
    tuned = quick.train_config("nconv-pose", seed=0)
    assert (tuned.loss, tuned.model, tuned.init, tuned.name) == ("pose", "nconv", "nconv", "nconv-pose")
    assert quick.train_config("nconv", seed=3).model == "nconv" and quick.train_config("nconv", 3).seed == 3
    for run in ("sparse-conv", "nconv", "nconv-guided"):  # each corrects a fill, on every beam count, 64 the most
        config = quick.train_config(run, seed=0)
        assert config.model_hparams() == {"correct_fill": True} and config.input_mix.count("sparse") == 3
        assert {"sparse@32", "sparse@16", "sparse@8"} < set(config.input_mix)
    with pytest.raises(DcslamError, match="exactly sparse-conv, sparse-conv-exact, sparse-conv-geometry, nconv, "
                                          "nconv-guided, nconv-pose"):
        BeamsProfile(name="bad", drives=3, frames=12, train={"nconv": {}}, slam_frames=2)
    for init in ("nconv-guided-x", "nconv-pose"):  # not a run of the profile; a run that is itself fine-tuned
        chained = {**quick.train, "nconv-pose": {**quick.train["nconv-pose"], "init": init}}
        with pytest.raises(DcslamError, match=f"starts from {init}"):
            BeamsProfile(name="bad", drives=3, frames=12, train=chained, slam_frames=2)
    with pytest.raises(DcslamError, match="must include 64"):
        BeamsProfile(name="bad", drives=3, frames=12, train=quick.train, slam_frames=2, beams=(32, 16))
    with pytest.raises(DcslamError, match="divisor"):
        BeamsProfile(name="bad", drives=3, frames=12, train=quick.train, slam_frames=2, beams=(64, 12))


def test_drives_without_exact_depth_leave_the_exact_row_empty(tmp_path):
    drives = [depth_fixtures.write_drive(tmp_path / f"{n}.h5", n=2, extra=extra) for n, extra in (("a", True),
                                                                                                  ("b", False))]
    assert reproduce_beams.have_exact(drives[:1]) and not reproduce_beams.have_exact(drives)


def test_print_config_of_the_beams_table_lists_its_stages_and_runs_nothing(cli, tmp_path):
    from dcslam.stages.reproduce_plan import read_stage_configs

    ws = tmp_path / "ws"
    result = cli("reproduce", "--table", "beams", "--print-config", "--workspace", ws)
    assert result.exit_code == 0, result.output
    assert not ws.exists()
    stages = read_stage_configs(result.stdout)
    names = list(stages)
    assert names[:2] == ["synth", "prepare-kitti"] and names[-1] == "score-beams"
    assert sorted(stages["prepare-kitti"]["beams"]) == sorted(b for b in PROFILES["quick"].beams if b != 64)
    assert {n for n in names if n.startswith("train-")} == {f"train-{r}" for r in PROFILES["quick"].train}
    assert any(n.startswith("slam-exact-") for n in names)  # generated drives: the exact row is planned
    assert any(n.startswith("slam-exact+measured-sparse16-") for n in names)
    assert any(n.startswith("slam-nconv-pose-sparse8+measured-") for n in names)
    measured = next(v for n, v in stages.items() if n.startswith("slam-ip-basic-fast-sparse32+measured-"))
    assert (measured["sources"], measured["measured"]) == ("measured", "sparse@32")
    assert str(measured["out"]).endswith("slam/ip-basic-fast-sparse32+measured")


def test_a_kitti_root_plans_no_row_that_needs_exact_depth(tmp_path):
    """Real KITTI has no exact depth: exact, SparseConvNet → exact and SparseConvNet geometry (and their measured-
    source runs) are left out of the plan; the other measured-source runs stay."""
    from dcslam.stages.reproduce_plan import planned_stages
    from dcslam.workspace import Workspace

    names = [s.name for s in planned_stages(Workspace(tmp_path / "ws"), PROFILES["quick"], "beams",
                                            kitti_root=tmp_path)]
    assert not [n for n in names if "exact" in n or "geometry" in n]
    assert "train-sparse-conv" in names and any(n.startswith("slam-nconv-sparse16+measured-") for n in names)
    assert any(n.startswith("slam-ip-basic-fast-sparse8+measured-") for n in names)


def test_every_training_seed_has_its_measured_source_runs(tmp_path):
    from dcslam.report.seeds import seed_run_name
    from dcslam.stages.reproduce_plan import planned_stages
    from dcslam.workspace import Workspace

    stages = {s.name: s for s in planned_stages(Workspace(tmp_path / "ws"), PROFILES["smoke"], "beams", seeds=2)}
    for run in ("sparse-conv-geometry", "nconv-pose"):
        for k in range(2):
            name = f"{seed_run_name(run, k)}-sparse16+measured"
            stage = next(s for n, s in stages.items() if n.startswith(f"slam-{name}-"))
            assert (stage.config.sources, stage.config.measured, stage.config.out.name) == ("measured", "sparse@16",
                                                                                             name)
            assert stage.seed == k
    assert sum(n.startswith("slam-exact+measured-") for n in stages) == 2  # once per beam count, not per seed
