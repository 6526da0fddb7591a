"""The robust columns of the beams table from hand-built rows (no SLAM run): the signed-rank p-value, the bootstrap
interval of the median paired difference and its verdict, the gap closed between medians, and the drives every row
fails on, left out of those columns and named in the notes."""
import csv
import io

import pytest

from dcslam.eval.depth import DepthErrors
from dcslam.report.results import LayerResult, SeedResults
from dcslam.report.robust_rows import compare, drive_localisation, robust_columns
from dcslam.report.table_beams import per_drive_table, table_beams
from tests.fixtures.trajectories import offset_pair

DRIVES = [f"d{i}" for i in range(7)]
SETTINGS = {"frames": 5, "odometry": "icp", "mapper": "pointfusion", "voxel_size": 0.2}
SPARSE = [0.40, 0.42, 0.38, 0.41, 0.39, 0.43, 5.0]       # d6: SLAM fails (localisation > 1 m + rad)
IP_BASIC = [s + d for s, d in zip(SPARSE, [-0.05, -0.06, -0.07, -0.08, -0.09, -0.10])] + [6.0]
NCONV = [s + d for s, d in zip(SPARSE, [0.05, -0.04, 0.03, -0.02, 0.01, -0.06])] + [7.0]
EXACT = [0.02] * 6 + [4.0]



def _result(label: str, layer: str, offsets: list[float], seed=None) -> LayerResult:
    drives = DRIVES[:len(offsets)]
    errors = DepthErrors(mae_mm=100.0, rmse_mm=200.0, imae_per_km=1.0, irmse_per_km=2.0, pixels=10, coverage=1.0)
    return LayerResult(label=label, layer=layer, depth={d: errors for d in drives},
                       pairs={d: offset_pair(o) for d, o in zip(drives, offsets)},
                       settings={d: dict(SETTINGS, suspect=False) for d in drives}, seed=seed)


def _results(n: int = 7, exact=EXACT) -> dict:
    return {(16, "sparse"): _result("sparse", "sparse@16", SPARSE[:n]),
            (16, "IP-Basic"): _result("IP-Basic", "ip-basic-fast-sparse16", IP_BASIC[:n]),
            (16, "nconv"): _result("nconv", "nconv-sparse16", NCONV[:n]),
            (None, "exact"): _result("exact", "exact", exact[:n])}


def test_known_answers_with_the_drive_every_row_fails_on_left_out():
    fields, left_out = robust_columns(_results(), [16])
    assert left_out == {16: ["d6"]}  # every row fails there, exact included
    ip = fields[(16, "IP-Basic")]
    assert ip["robust_drives"] == 6 and ip["signed_rank_n"] == 6
    assert ip["signed_rank_p"] == pytest.approx(2 / 2 ** 6)  # every difference negative: the exact two-sided p
    assert ip["signed_rank_p_text"] == "0.031"
    assert ip["median_diff"] == pytest.approx(-0.075)
    assert -0.10 - 1e-9 <= ip["median_diff_ci_low"] <= ip["median_diff_ci_high"] <= -0.05 + 1e-9
    assert ip["robust_vs_sparse"] == "better"
    # medians over d0 … d5: sparse 0.405, IP-Basic 0.33, exact 0.02
    assert ip["gap_closed_median"] == pytest.approx((0.405 - 0.33) / (0.405 - 0.02))
    assert ip["gap_closed_median_text"] == "19 %"
    nconv = fields[(16, "nconv")]
    assert nconv["median_diff"] == pytest.approx(-0.005) and nconv["robust_vs_sparse"] == "within"
    assert nconv["signed_rank_p"] > 0.5
    assert fields[(16, "sparse")] == {"robust_vs_sparse": "reference", "robust_drives": 6}
    exact = fields[(None, "exact")]
    assert exact["gap_closed_median"] is None and exact["robust_vs_sparse"] == "better"


def test_fewer_than_six_drives_say_so_instead_of_a_p_value():
    fields, left_out = robust_columns(_results(n=4), [16])
    assert left_out == {16: []}
    ip = fields[(16, "IP-Basic")]
    assert ip["signed_rank_p_text"] == "n<6" and ip["robust_drives"] == 4 and ip["robust_vs_sparse"] == "better"


def test_a_drive_exact_localises_on_is_kept():
    fields, left_out = robust_columns(_results(exact=[0.02] * 7), [16])
    assert left_out == {16: []}
    assert fields[(16, "IP-Basic")]["robust_drives"] == 7
    # the failing drive moves the mean beyond the others but the median by one place: IP-Basic's 6.0 vs sparse's 5.0
    assert fields[(16, "IP-Basic")]["median_diff"] == pytest.approx(-0.07)


def test_no_gap_when_exact_is_no_better_than_sparse():
    comparison = compare({"a": 1.0, "b": 2.0}, {"a": 1.0, "b": 1.0}, {"a": 1.5, "b": 1.5})
    assert comparison.gap_closed is None and comparison.drives == 2
    assert compare({"a": 1.0}, {"b": 1.0}, None) is None
    assert compare({"a": 1.0}, {"a": 2.0}, None).verdict == "one drive"


def test_a_row_over_seeds_is_paired_by_drive_through_its_seed_mean():
    seeds = SeedResults("nconv", [_result("nconv", "nconv-sparse16", NCONV, seed=0),
                                  _result("nconv", "nconv-sparse16-s1", [v + 0.02 for v in NCONV], seed=1)])
    assert drive_localisation(seeds)["d0"] == pytest.approx(NCONV[0] + 0.01)
    results = _results()
    results[(16, "nconv")] = seeds
    fields, _ = robust_columns(results, [16])
    assert fields[(16, "nconv")]["median_diff"] == pytest.approx(-0.005 + 0.01)


def test_the_table_and_the_per_drive_table_carry_the_robust_columns():
    table = table_beams(_results(), [16], DRIVES)
    rows = {(r["beams"], r["input"]): r for r in table.rows}
    assert rows[(16, "IP-Basic")]["robust_vs_sparse"] == "better" and rows[(16, "IP-Basic")]["median_diff_text"] \
        .startswith("-0.0750 [")
    # the t-interval over every drive, kept beside them, is swamped by the drive on which IP-Basic fails worse
    assert rows[(16, "IP-Basic")]["vs_sparse"] == "within spread"
    text = table.to_markdown()
    assert "| signed-rank p | median Δ vs sparse | robust vs sparse | gap closed (medians) |" in text
    assert "left out of the robust columns and kept in the means: 16 beams: d6" in text
    assert "by the median interval: IP-Basic" in text
    header = next(csv.reader(io.StringIO(table.to_csv())))
    assert {"signed_rank_p", "median_diff_ci_low", "robust_vs_sparse", "gap_closed_median", "gap_closed"} <= set(header)
    per_drive = {(r["input"], r["drive"]): r for r in per_drive_table(_results()).rows}
    assert per_drive[("IP-Basic", "d6")]["failed_by_all"] and not per_drive[("IP-Basic", "d0")]["failed_by_all"]
    assert per_drive[("IP-Basic", "d0")]["vs_sparse_m"] == pytest.approx(-0.05)
    assert per_drive[("exact", "d1")]["vs_sparse_m"] == pytest.approx(0.02 - 0.42)
