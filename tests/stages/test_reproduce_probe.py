"""``dcslam reproduce --calibrate``: the probe's samples, the fit of each kind's unit costs, the calibration file and
the command (the probe itself runs in the smoke-profile test of tests/stages/test_reproduce.py)."""
import json

import pytest

from dcslam.stages.experiments.table_5_2 import PROFILES
from dcslam.stages.reproduce_cost import CALIBRATION, read_costs
from dcslam.stages.reproduce_probe import (FILL_PROBES, NEAREST_PROBE, PROBE_SIZES, PROBE_SLAM, SCAFFOLD_PROBE,
                                          _fill_config, _wanted, fit, probe_profile)


def test_fit_is_the_line_through_the_two_samples_per_stage():
    small = {"synth": (4.0, 4.0, 1), "slam": (3.0, 4.0, 2), "score": (2.0, 3.0, 1), "only-small": (1.0, 1.0, 1)}
    large = {"synth": (6.0, 8.0, 1), "slam": (8.0, 16.0, 4), "score": (2.2, 3.0, 1), "only-large": (3.0, 12.0, 1)}
    fitted = fit(small, large)
    assert set(fitted) == {"synth", "slam", "score", "only-large"}  # not a kind the small sample alone measured
    # a kind of the large sample alone (synth: the small one reuses its drives) is priced per unit
    assert fitted["only-large"] == {"stage_s": 0.0, "unit_s": 0.25, "samples": [[3.0, 12.0, 1]]}
    assert (fitted["synth"]["stage_s"], fitted["synth"]["unit_s"]) == (2.0, 0.5)  # 2 s + 0.5 s per unit
    assert (fitted["slam"]["stage_s"], fitted["slam"]["unit_s"]) == (1.0, 0.25)  # per stage: (2, 1.5) and (4, 2)
    assert fitted["score"] == {"stage_s": 2.1, "unit_s": 0.0, "samples": [[2.0, 3.0, 1], [2.2, 3.0, 1]]}


def test_fit_of_noisy_samples_keeps_both_parts_non_negative():
    cheaper_when_larger = fit({"k": (5.0, 2.0, 1)}, {"k": (4.0, 4.0, 1)})["k"]
    assert cheaper_when_larger["unit_s"] == 0.0 and cheaper_when_larger["stage_s"] == 4.5
    steeper_than_total = fit({"k": (1.0, 2.0, 1)}, {"k": (9.0, 4.0, 1)})["k"]  # the line would cross below 0
    assert steeper_than_total["stage_s"] == 0.0 and steeper_than_total["unit_s"] == pytest.approx(10 / 6, abs=1e-4)


def test_probe_profile_shrinks_the_counts_and_keeps_the_settings():
    smoke, quick = (probe_profile(PROFILES[name], PROBE_SIZES[1]) for name in ("smoke", "quick"))
    assert (quick.drives, quick.frames, quick.split, quick.slam_frames, quick.seeds) == (3, 14, (1, 1, 1), 4, 1)
    assert quick.train["scale"] == 0.5 and quick.train["lr"] == 3e-3  # the profile's own settings
    assert quick.train["max_frames"] == 4 and quick.train["epochs"] == 1 and quick.pose["max_frames"] == 4
    assert quick.pose["pose_grad_iterations"] == 2 and smoke.train["scale"] == 0.25
    assert smoke.slam["voxel_size"] == 0.2
    assert all({"sparse", "dense"} < set(layers) for layers in PROBE_SLAM)  # every SLAM kind in both samples
    wanted = _wanted(quick, ("sparse", "mse-dense"))
    assert wanted("train-chamfer-8") and wanted("filter-mse-dense+edges") and wanted("score-tables")
    assert wanted("slam-sparse-2011_09_26_drive_1002_sync") and wanted("slam-long-sparse-2011_09_26_drive_1002_sync")
    assert not wanted("slam-mse-sparse-2011_09_26_drive_1002_sync") and not wanted("train-chamfer-1")
    assert not wanted("slam-mse-dense+edges-2011_09_26_drive_1002_sync") and not wanted("predict-pose")
    assert wanted("predict-planefit") and wanted("predict-scanline") and wanted("predict-ip-basic-fast")
    assert all(wanted(f"train-{name}") and wanted(f"predict-{name}") for name in FILL_PROBES)  # networks on a fill


def test_each_fill_probe_trains_its_experiments_recipe_on_the_sparse_input():
    from dcslam.stages.config import to_dict
    from dcslam.stages.experiments.beams import PROFILES as BEAMS
    from dcslam.stages.experiments.surface import PROFILES as SURFACE, SCAFFOLD_RUN
    from dcslam.stages.reproduce_cost import stage_kind

    small = probe_profile(PROFILES["quick"], PROBE_SIZES[1])
    made = {name: to_dict(_fill_config(small, name)) for name in FILL_PROBES}
    experiments = {SCAFFOLD_PROBE: SURFACE["study"].train[SCAFFOLD_RUN],
                   NEAREST_PROBE: BEAMS["quick"].train["sparse-conv"]}
    for name, config in made.items():
        recipe = {k: v for k, v in experiments[name].items() if k not in ("input_mix", "epochs", "max_frames", "scale")}
        assert {k: config[k] for k in recipe} == recipe, name     # the experiment's recipe ...
        assert config["max_frames"] == PROBE_SIZES[1] and config["input_mix"] == []  # ... at probe size, sparse only
    # the kinds the probe prices are those the experiments' trainings are priced by
    assert stage_kind(f"train-{SCAFFOLD_PROBE}", made[SCAFFOLD_PROBE]) == "train-mse+planefit"
    assert stage_kind(f"train-{NEAREST_PROBE}", made[NEAREST_PROBE]) == "train-mse+nearest"


def test_calibrate_writes_the_fit_the_dry_run_then_estimates_with(cli, tmp_path, monkeypatch):
    samples = iter([{"synth": (8.0, 36.0, 1), "slam": (2.0, 4.0, 2)}, {"synth": (9.0, 42.0, 1), "slam": (4.0, 8.0, 2)},
                    {"synth": (8.0, 36.0, 1)}, {"synth": (9.0, 42.0, 1)}])
    monkeypatch.setattr("dcslam.stages.reproduce_probe.sample", lambda *args, **kwargs: next(samples))
    ws = tmp_path / "ws"
    result = cli("reproduce", "--profile", "smoke", "--dry-run", "--calibrate", "-w", ws)
    assert result.exit_code == 0, result.output
    path = ws / ".reproduce" / CALIBRATION
    costs = read_costs(path, "smoke")
    assert costs.per_unit["slam"] == 0.5 and costs.per_stage["slam"] == 0.0
    assert costs.per_unit["synth"] == pytest.approx(1 / 6, abs=1e-4) and costs.per_stage["synth"] == pytest.approx(2.0)
    assert "dcslam reproduce --calibrate --profile smoke on" in costs.source and "CPU cores, load" in costs.source
    assert "unit costs measured from dcslam reproduce --calibrate --profile smoke" in result.stdout
    assert "[calibrate]" in result.stderr and not (ws / "kitti").exists()  # the probe ran in a folder of its own
    again = cli("reproduce", "--profile", "quick", "--dry-run", "--calibrate", "-w", ws)  # another profile: added
    assert again.exit_code == 0, again.output
    assert set(json.loads(path.read_text())["profiles"]) == {"smoke", "quick"}


def test_a_probe_that_measured_nothing_fails_with_one_line(cli, tmp_path, monkeypatch):
    monkeypatch.setattr("dcslam.stages.reproduce_probe.sample", lambda *args, **kwargs: {})
    result = cli("reproduce", "--profile", "smoke", "--dry-run", "--calibrate", "-w", tmp_path / "ws")
    assert result.exit_code == 1 and "the probe measured no stage" in result.stderr
    assert not (tmp_path / "ws" / ".reproduce" / CALIBRATION).exists()
