"""``dcslam reproduce --table surface``: the plan's stages, the profiles, the cost estimate, and the smoke profile end
to end on the tiny analytic drives of the stage tests (with ``sparse@16`` and ``exact``) in place of generated
KITTI drives; prediction, SLAM and scoring run for real."""
import csv

import pytest

from dcslam.errors import DcslamError
from dcslam.stages.experiments import experiment
from dcslam.stages.experiments.surface import PROFILES, SurfaceProfile
from tests.fixtures import depth as depth_fixtures

#: Without the camera: the tiny drives' images are their depth in grey, so the camera measures every step and would
#: vouch for the 2-frame sparse and exact runs that the table's robust columns need flagged here.
ARGS = ["reproduce", "--table", "surface", "--profile", "smoke", "--no-camera"]
NETS = ("SparseConvNet on planefit", "SparseConvNet on planefit, sure")
DEPTH_ROWS = ("sparse", "IP-Basic", "scanline", "planefit", *NETS)
MEASURED_ROWS = tuple(f"{label}, measured sources" for label in ("IP-Basic", "scanline", "planefit", *NETS, "exact"))


@pytest.fixture
def tiny_drives(monkeypatch):
    """synth and prepare-kitti replaced by the tiny drive files (4 drives of 6 frames, 32 × 64; 64 and 16 beams)."""
    def synth(ws, config, *, force=False):
        ws.kitti.mkdir(parents=True, exist_ok=True)
        (ws.kitti / "SYNTHETIC").write_text("tiny drives of the surface test\n")

    def prepare(ws, config, *, force=False):
        assert list(config.beams) == [16]  # the profile's beam counts other than 64
        depth_fixtures.write_workspace(ws.root, n=6, extra=True)

    monkeypatch.setattr("dcslam.stages.synth.run", synth)
    monkeypatch.setattr("dcslam.stages.prepare.run", prepare)


@pytest.mark.slow  # two tiny trainings, five completers at two beam counts, 30 SLAM runs
def test_smoke_profile_writes_the_surface_table_and_rebuilds_it(cli, tmp_path, tiny_drives):
    result = cli(*ARGS, "--workspace", tmp_path)
    assert result.exit_code == 0, result.output
    results = tmp_path / "results"
    for name in ("table_surface.md", "table_surface.csv", "table_surface_per_drive.csv",
                 "table_surface_correlation.csv", "surface_localisation.png", "table_surface.json"):
        assert (results / name).stat().st_size > 0, name
    assert not (results / "table_beams.md").exists()
    assert "The surface experiment" in result.stdout
    with open(results / "table_surface.csv") as f:
        rows = list(csv.DictReader(f))
    per_beam = [("64", label) for label in DEPTH_ROWS + MEASURED_ROWS]
    assert [(r["beams"], r["input"]) for r in rows] == per_beam + [
        ("16", label) for _, label in per_beam] + [("any", "exact")]
    assert not any(r["missing"] for r in rows) and all(r["drives"] == "1" and r["localisation"] for r in rows)
    # SLAM over 2 frames of the tiny drive is flagged suspect in every row: the drive is left out of the robust
    # columns, named in the notes, and kept in the means
    assert all(r["failures"] == "1" for r in rows)
    assert rows[0]["robust_vs_sparse"] == "reference" and rows[1]["robust_vs_sparse"] == "no drive"
    assert rows[0]["robust_drives"] == "0" and rows[1]["signed_rank_p"] == ""
    assert "kept in the means: 64 beams: drive_d; 16 beams: drive_d" in (results / "table_surface.md").read_text()
    assert {"signed_rank_p", "median_diff", "gap_closed_median"} <= set(rows[0])
    for layer in ("scanline-sparse16", "planefit-sparse64+measured", "exact+measured-sparse16", "exact", "sparse@16"):
        assert (tmp_path / "slam" / layer / "drive_d.txt").exists(), layer
    # the networks on planefit's scaffold: trained once each (one seed), against exact depth, their layers predicted
    import json

    settings = json.loads((tmp_path / "runs" / "sparse-conv-planefit" / "config.json").read_text())["settings"]
    assert settings["model_hparams"] == {"correct_fill": True, "fill": "planefit", "fill_output": "inverse-residual"}
    assert settings["target"] == "exact" and settings["input_mix"] == ["sparse", "sparse@16"]
    assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == ["sparse-conv-planefit",
                                                                     "sparse-conv-planefit-sure"]
    sure = json.loads((tmp_path / "runs" / "sparse-conv-planefit-sure" / "config.json").read_text())["settings"]
    assert sure["model_hparams"]["confidence"] is True and sure["confidence_weight"] > 0
    assert (tmp_path / "slam" / "sparse-conv-planefit-sparse16+measured" / "drive_d.txt").exists()
    again = cli(*ARGS, "--workspace", tmp_path)
    assert again.exit_code == 0, again.output
    assert "[run]" not in again.stderr
    rebuilt = cli("score", "tables", "--table", "surface", "--out", tmp_path / "rebuilt", "--workspace", tmp_path)
    assert rebuilt.exit_code == 0, rebuilt.output
    assert (tmp_path / "rebuilt" / "table_surface.csv").read_text() == (results / "table_surface.csv").read_text()


def test_the_plan_lists_the_completers_and_both_icp_modes_and_trains_the_network_per_seed(tmp_path):
    from dcslam.stages.reproduce_plan import planned_stages
    from dcslam.workspace import Workspace

    stages = {s.name: s for s in planned_stages(Workspace(tmp_path / "ws"), PROFILES["quick"], "surface")}
    names = list(stages)
    assert names[:2] == ["synth", "prepare-kitti"] and names[-1] == "score-surface"
    assert [n for n in names if n.startswith(("train-", "filter-"))] == ["train-sparse-conv-planefit",
                                                                         "train-sparse-conv-planefit-sure"]
    assert stages["train-sparse-conv-planefit-sure"].config.confidence_weight > 0
    assert stages["train-sparse-conv-planefit"].config.confidence_weight == 0
    net = stages["train-sparse-conv-planefit"].config
    assert (net.model, net.correct_fill, net.fill, net.fill_output, net.target) == (
        "sparse-conv", True, "planefit", "inverse-residual", "exact")
    assert net.input_mix == ["sparse", "sparse@16", "sparse@8"] and net.normal_weight > 0
    completers = ("ip-basic-fast", "scanline", "planefit", "sparse-conv-planefit", "sparse-conv-planefit-sure")
    predictions = {n for n in names if n.startswith("predict-")}
    assert predictions == {f"predict-{c}-sparse{b}" for c in completers for b in (64, 16, 8)}
    assert stages["predict-planefit-sparse8"].config.model == "planefit"
    assert stages["predict-sparse-conv-planefit-sparse8"].config.run == "sparse-conv-planefit"
    slam_layers = {n.rsplit("-", 1)[0].removeprefix("slam-") for n in names if n.startswith("slam-")}
    completions = {f"{c}-sparse{b}" for c in completers for b in (64, 16, 8)}
    assert slam_layers == ({"sparse", "sparse@16", "sparse@8", "exact"} | completions
                           | {f"{c}+measured" for c in completions}
                           | {f"exact+measured-sparse{b}" for b in (64, 16, 8)})
    test_drives = len([n for n in names if n.startswith("slam-scanline-sparse16+measured-")])
    assert test_drives == PROFILES["quick"].split[2] >= 4
    measured = next(s for n, s in stages.items() if n.startswith("slam-scanline-sparse16+measured-"))
    assert (measured.config.sources, measured.config.measured) == ("measured", "sparse@16")
    assert stages["score-surface"].config.beams == [64, 16, 8]
    # the study: the network with 3 training seeds, each its own run, predictions and SLAM runs
    study = [s.name for s in planned_stages(Workspace(tmp_path / "ws"), PROFILES["study"], "surface", seeds=3)]
    assert [n for n in study if n.startswith("train-")] == [
        f"train-{run}{k}" for k in ("", "-s1", "-s2") for run in ("sparse-conv-planefit", "sparse-conv-planefit-sure")]
    assert "predict-sparse-conv-planefit-s2-sparse16" in study
    assert any(n.startswith("slam-sparse-conv-planefit-s1-sparse8+measured-") for n in study)


def test_a_kitti_root_plans_no_exact_row_and_trains_nothing(tmp_path):
    from dcslam.stages.reproduce_plan import planned_stages
    from dcslam.workspace import Workspace

    names = [s.name for s in planned_stages(Workspace(tmp_path / "ws"), PROFILES["quick"], "surface",
                                            kitti_root=tmp_path)]
    assert not [n for n in names if "exact" in n] and any(n.startswith("slam-planefit-sparse8-") for n in names)
    assert not [n for n in names if "sparse-conv" in n]  # the network's target is exact depth


def test_profiles_test_on_enough_drives_and_refuse_what_cannot_run():
    study = PROFILES["study"]
    assert study.split[2] >= 8 and study.slam_frames >= 30 and study.beams == (64, 16, 8)
    assert PROFILES["quick"].split[2] >= 4
    # the study's test drives are the beams study's: the same generated drives, split the same way
    from dcslam.stages.experiments.beams import PROFILES as BEAMS

    assert (study.drives, study.frames, study.split) == (BEAMS["study"].drives, BEAMS["study"].frames,
                                                         BEAMS["study"].split)
    assert experiment("surface").profile("smoke") is PROFILES["smoke"]
    with pytest.raises(DcslamError, match="must include 64"):
        SurfaceProfile(name="bad", drives=3, frames=12, slam_frames=2, beams=(16, 8))
    with pytest.raises(DcslamError, match="seeds must be 1 without a trained row"):
        SurfaceProfile(name="bad", drives=3, frames=12, slam_frames=2, seeds=3)
    with pytest.raises(DcslamError, match="nconv, not a run of the surface table"):
        SurfaceProfile(name="bad", drives=3, frames=12, slam_frames=2, train={"nconv": {}})
    with pytest.raises(DcslamError, match="profile surface bad: train"):
        SurfaceProfile(name="bad", drives=3, frames=12, slam_frames=2, train={"sparse-conv-planefit": {"epoks": 1}})
    assert PROFILES["study"].seeds == 3 and PROFILES["quick"].train == PROFILES["study"].train
    with pytest.raises(DcslamError, match="add up"):
        SurfaceProfile(name="bad", drives=3, frames=12, slam_frames=2, split=(1, 1, 2))
    with pytest.raises(DcslamError, match="profile surface bad: slam"):
        SurfaceProfile(name="bad", drives=3, frames=12, slam_frames=2, slam={"voxel_sise": 0.2})


def test_the_study_cost_estimate_and_the_print_config_run_nothing(cli, tmp_path):
    ws = tmp_path / "ws"
    dry = cli("reproduce", "--table", "surface", "--profile", "study", "--dry-run", "-w", ws)
    assert dry.exit_code == 0, dry.output
    assert "--table surface --profile study: 8 test" in dry.stdout
    plan = cli("reproduce", "--table", "surface", "--print-config", "--workspace", ws)
    assert plan.exit_code == 0, plan.output
    assert "score-surface" in plan.stdout and not ws.exists()
