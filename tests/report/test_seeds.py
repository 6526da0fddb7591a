"""Training seeds as a dimension of the tables: run names, grouping, and rows over seeds × drives (constructed
trajectories whose localisation is known, no SLAM run here)."""
import csv
import io
from types import SimpleNamespace

import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.report.layers import TrajectoryPair
from dcslam.report.scores import per_drive_table
from dcslam.report.seeds import paired, seed_base, seed_groups, seed_run_name
from dcslam.report.spread import two_level_interval
from dcslam.report.results import LayerResult, SeedResults
from dcslam.report.table_5_2 import table_5_2

DRIVES = ["d1", "d2", "d3"]
FRAMES = 11  # a straight drive of 1 m per frame: an estimate `scale` times too long errs (scale − 1) · i m at frame i


def pair(scale: float) -> TrajectoryPair:
    T_gt = np.tile(np.eye(4), (FRAMES, 1, 1))
    T_gt[:, 2, 3] = np.arange(FRAMES)
    T_est = T_gt.copy()
    T_est[:, :3, 3] *= scale
    return TrajectoryPair(timestamps=0.1 * np.arange(FRAMES), T_gt=T_gt, T_est=T_est)


def localisation(scale: float) -> float:
    return (scale - 1) * (FRAMES - 1) / 2  # the mean over frames 0 … 10 of (scale − 1) · i


def result(label, layer, scales, seed=None, suspect=False) -> LayerResult:
    settings = {"frames": 11, "odometry": "icp", "voxel_size": 0.2, "suspect": suspect}
    return LayerResult(label=label, layer=layer, pairs={d: pair(s) for d, s in zip(DRIVES, scales)},
                       settings={d: dict(settings) for d in DRIVES}, seed=seed)


def test_seed_run_names_and_their_inverse():
    assert [seed_run_name("chamfer-8", k) for k in range(3)] == ["chamfer-8", "chamfer-8-s1", "chamfer-8-s2"]
    assert [seed_base(n) for n in ("chamfer-8", "chamfer-8-s2", "nconv-sparse16", "x-s0")] == [
        ("chamfer-8", 0), ("chamfer-8", 2), ("nconv-sparse16", 0), ("x-s0", 0)]
    with pytest.raises(ValueError):
        seed_run_name("x", -1)


def test_runs_group_by_seed_when_only_their_seed_differs():
    def run(name, **settings):
        return SimpleNamespace(name=name, settings={"loss": "mse", "epochs": 2, "seed": 0, "name": name,
                                                    **settings})

    runs = [run("mse-dense"), run("mse-dense-s1", seed=1), run("mse-dense-s2", seed=2, epochs=5),
            run("pose-s1", seed=1, init="runs/chamfer-8-s1/model.pt"), run("pose", init="runs/chamfer-8/model.pt")]
    groups = [[r.name for r in g] for g in seed_groups(runs)]
    assert groups == [["mse-dense", "mse-dense-s1"], ["mse-dense-s2"], ["pose", "pose-s1"]]  # by k within a group


def test_a_row_over_seeds_is_the_mean_over_seeds_and_drives_with_a_two_level_interval():
    sparse = result("sparse depth", "sparse", [1.01, 1.02, 1.03])
    seeds = SeedResults("MSE dense mask", [result("MSE dense mask", "mse-dense", [1.03, 1.04, 1.06], seed=0),
                                           result("MSE dense mask", "mse-dense-s1", [1.05, 1.06, 1.07], seed=1,
                                                  suspect=True)])
    table = table_5_2([seeds, sparse], {}, DRIVES)
    row, reference = table.rows
    values = np.array([[localisation(s) for s in (1.03, 1.04, 1.06)], [localisation(s) for s in (1.05, 1.06, 1.07)]])
    assert row["seeds"] == 2 and row["drives"] == 3 and row["layer"] == "mse-dense (seeds 0, 1)"
    assert row["localisation"] == pytest.approx(values.mean())
    assert (row["localisation_ci_low"], row["localisation_ci_high"]) == pytest.approx(two_level_interval(values))
    assert row["localisation_seed_std"] == pytest.approx(np.std(values.mean(axis=1), ddof=1))
    assert row["localisation_median"] == pytest.approx(np.median(values))
    assert row["failures"] == 3  # every run of the second seed was flagged
    assert row["vs_sparse"] == "differs" and reference["vs_sparse"] == "reference"
    assert reference.get("seeds") is None and "±" in reference["localisation_text"]  # a row without seeds
    assert row["localisation_text"] == (f"{values.mean():.4f} [{row['localisation_ci_low']:.4f}, "
                                        f"{row['localisation_ci_high']:.4f}]")
    markdown = table.to_markdown()
    assert "| method | layer | drives | seeds | failed |" in markdown and "seed-to-seed std" in markdown
    assert any("two-level percentile bootstrap" in note for note in table.notes)
    columns = next(csv.reader(io.StringIO(table.to_csv())))
    assert {"seeds", "localisation_ci_low", "localisation_ci_high", "localisation_seed_std"} <= set(columns)
    per_drive = list(csv.DictReader(io.StringIO(per_drive_table([seeds, sparse]).to_csv())))
    assert [(r["layer"], r["seed"], r["drive"]) for r in per_drive][:4] == [
        ("mse-dense", "0", "d1"), ("mse-dense", "0", "d2"), ("mse-dense", "0", "d3"), ("mse-dense-s1", "1", "d1")]
    assert {r["seed"] for r in per_drive if r["layer"] == "sparse"} == {""}


def test_tables_without_seeds_keep_their_columns():
    table = table_5_2([result("MSE dense mask", "mse-dense", [1.03, 1.04, 1.06], seed=0),
                       result("sparse depth", "sparse", [1.01, 1.02, 1.03])], {}, DRIVES)
    assert "seeds" not in [c.key for c in table.columns] and "seed-to-seed" not in table.to_markdown()
    assert "localisation_seed_std" not in table.to_csv().splitlines()[0]


def test_paired_verdicts_over_seeds():
    sparse = result("sparse depth", "sparse", [1.01, 1.02, 1.03])
    same = SeedResults("x", [result("x", "x", [1.01, 1.02, 1.03], seed=0), result("x", "x-s1", [1.01, 1.02, 1.03],
                                                                                   seed=1)])
    assert paired(same, sparse) == (False, 0.0) and paired(sparse, same)[0] is False
    better = SeedResults("y", [result("y", "y", [1.005, 1.01, 1.02], seed=0),
                               result("y", "y-s1", [1.006, 1.012, 1.022], seed=1)])
    verdict, difference = paired(better, sparse)
    assert verdict is True and difference < 0
    one = SeedResults("z", [LayerResult("z", "z", pairs={"d1": pair(1.02)}, seed=0),
                            LayerResult("z", "z-s1", pairs={"d1": pair(1.03)}, seed=1)])
    assert paired(one, sparse)[0] is None  # one common drive
    with pytest.raises(DcslamError, match="at least 2 runs"):
        SeedResults("w", [sparse])


def test_beams_table_rows_over_seeds_and_their_verdicts():
    from dcslam.report.table_beams import per_drive_table as beams_per_drive, table_beams

    sparse = result("sparse", "sparse", [1.05, 1.06, 1.07])
    nconv = SeedResults("nconv", [result("nconv", "nconv-sparse64", [1.01, 1.02, 1.03], seed=0),
                                  result("nconv", "nconv-s1-sparse64", [1.012, 1.022, 1.032], seed=1)])
    results = {(64, "sparse"): sparse, (64, "nconv"): nconv}
    table = table_beams(results, [64], DRIVES)
    assert [r["vs_sparse"] for r in table.rows] == ["reference", "better"]
    assert table.rows[1]["seeds"] == 2 and "seeds" in table.to_csv().splitlines()[0]
    assert any("two-level" in note for note in table.notes)
    assert {r["seed"] for r in beams_per_drive(results).rows} == {None, 0, 1}
