"""The verdict of a SLAM run read from the summary `dcslam slam` writes, and Table 5.2's failure count built on it.

The summaries are real: one generated drive (`dcslam synth`, 13 raw frames, 3 with depth; `dcslam prepare-kitti`)
run through `dcslam slam`. The runs flagged only for degraded steps, or only for their drift bound, are made by
running SLAM under health rules that make that one flag fire on this drive.
"""
import json
import math

import pytest
from typer.testing import CliRunner

from dcslam.cli import app
from dcslam.errors import DcslamError
from dcslam.io.slam_summary import RunVerdict, read_summary, read_verdict, run_verdict
from dcslam.slam import health

DRIVE = "2011_09_26_drive_1000_sync"

#: Rules under which every step of a run is degraded (no step has this many pairs) and neither the drift bound nor
#: the road figure fires.
ONLY_DEGRADED = health.HealthRules(min_pairs=10 ** 9, max_drift_m=0.0, max_road_drift_m=0.0)
#: Rules under which only the drift bound fires: any accumulated uncertainty exceeds it, and it counts (the whole
#: bound, ``prediction_bound`` off) because every step's weakest direction is taken as degenerate (a share is at most
#: 1/3, and any count of pairs is below inf).
ONLY_DRIFT = health.HealthRules(max_drift_m=1e-9, degenerate_share=1.0, degenerate_pairs=math.inf,
                                max_road_drift_m=0.0, prediction_bound=False)


def _invoke(*args):
    result = CliRunner().invoke(app, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return result


def _slam(ws, rules, *args):
    """`dcslam slam --no-camera` with its SLAM judging steps and the run by ``rules`` (the depth's own evidence: the
    camera, which measures this drive's steps from its images, would vouch for every run here)."""
    from dcslam.slam import config

    def build(settings, build_slam=config.build_slam):
        slam = build_slam(settings)
        slam.health = rules
        return slam

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(config, "build_slam", build)
        return _invoke("slam", "-w", ws, "--frames", 3, "--no-camera", *args)


@pytest.fixture(scope="module")
def ws(tmp_path_factory):
    """A workspace with one generated test drive and four real SLAM runs of it: ``slam/dense`` (default rules),
    ``slam/sparse`` (flagged for its drift bound only), ``runs-by-rule/degraded`` and ``runs-by-rule/drift``."""
    ws = tmp_path_factory.mktemp("verdict")
    _invoke("synth", "-w", ws, "--drives", 1, "--frames", 13, "--seed", 3)
    _invoke("prepare-kitti", "-w", ws)
    _slam(ws, health.HealthRules(), "--depth", "dense")
    _slam(ws, ONLY_DRIFT, "--depth", "sparse")
    _slam(ws, ONLY_DEGRADED, "--depth", "sparse", "--out", ws / "runs-by-rule" / "degraded")
    _slam(ws, ONLY_DRIFT, "--depth", "sparse", "--out", ws / "runs-by-rule" / "drift")
    return ws


class TestRealSummaries:
    def test_a_run_that_tracked_is_not_flagged(self, ws):
        verdict = read_verdict(ws / "slam" / "dense" / f"{DRIVE}.json")
        assert verdict == RunVerdict(suspect=False, reasons=(), rejected=0, degraded=0)

    def test_a_run_flagged_only_for_degraded_steps(self, ws):
        path = ws / "runs-by-rule" / "degraded" / f"{DRIVE}.json"
        record = read_summary(path)
        assert record["rejected_steps"] == [] and record["health"]["suspect"]
        verdict = run_verdict(record, str(path))
        assert verdict.suspect and verdict.rejected == 0 and verdict.degraded == 2
        assert verdict.reasons and all("degraded" in r for r in verdict.reasons)

    def test_a_run_flagged_only_for_its_drift_bound(self, ws):
        path = ws / "runs-by-rule" / "drift" / f"{DRIVE}.json"
        record = read_summary(path)
        assert record["rejected_steps"] == [] and record["health"]["degraded"] == 0
        verdict = read_verdict(path)
        assert verdict.suspect and verdict.rejected == 0
        assert len(verdict.reasons) == 1 and "accumulated uncertainty" in verdict.reasons[0]

    def test_every_table_reads_the_verdict(self, ws):
        from dcslam.report.layers import slam_settings
        from dcslam.workspace import Workspace

        assert slam_settings(Workspace(ws), "sparse", DRIVE)["suspect"] is True
        assert slam_settings(Workspace(ws), "dense", DRIVE)["suspect"] is False

    def test_table_5_2_counts_a_flagged_drive_as_failed(self, ws):
        from dcslam.report.table_5_2 import table_5_2, table_5_2_results
        from dcslam.workspace import Workspace

        results = table_5_2_results(Workspace(ws), [], [DRIVE])
        sparse = next(r for r in results if r.layer == "sparse")
        dense = next(r for r in results if r.layer == "dense")
        assert sparse.scores[DRIVE].localisation < sparse.failure_threshold  # not failed by its error alone
        table = table_5_2(results, {}, [DRIVE])
        rows = {r["layer"]: r for r in table.rows}
        assert rows["sparse"]["failures"] == 1 and rows["dense"]["failures"] == 0
        assert sparse.per_drive()[DRIVE]["failed"] is True and dense.per_drive()[DRIVE]["failed"] is False


class TestMalformedSummaries:
    def test_not_json_names_the_file(self, tmp_path):
        path = tmp_path / "d.json"
        path.write_text("{not json")
        with pytest.raises(DcslamError, match=r"d\.json: not valid JSON; rerun `dcslam slam --force`"):
            read_verdict(path)

    def test_not_an_object(self, tmp_path):
        path = tmp_path / "d.json"
        path.write_text("[1, 2]")
        with pytest.raises(DcslamError, match=r"d\.json: not a SLAM summary"):
            read_verdict(path)

    def test_health_without_a_verdict(self):
        with pytest.raises(DcslamError, match=r"x\.json: 'health' has no true/false 'suspect'"):
            run_verdict({"health": {"suspect": "yes"}}, "x.json")

    def test_rejected_steps_flag_a_run_whatever_its_health_says(self):
        verdict = run_verdict({"rejected_steps": [{"frame": 2, "reason": "few points"}],
                               "health": {"suspect": False, "reasons": []}})
        assert verdict.suspect and verdict.rejected == 1 and verdict.reasons == ("1 steps rejected",)

    def test_rejected_steps_do_not_flag_a_run_the_camera_vouched_for(self):
        """``dcslam slam --camera``: a camera that agrees overrules the rejected steps (they stay counted); one that
        departs, or measured nothing, leaves them flagging the run."""
        rejected = [{"frame": 2, "reason": "few points"}]
        for verdict, suspect in (("agrees", False), ("departs", True), ("unmeasured", True)):
            health = {"suspect": verdict == "departs", "reasons": [], "camera": {"verdict": verdict}}
            got = run_verdict({"rejected_steps": rejected, "health": health})
            assert got.suspect is suspect and got.rejected == 1, verdict

    def test_a_summary_without_health_is_judged_by_its_rejected_steps(self):
        assert not run_verdict({"rejected_steps": []}).suspect
        assert run_verdict({"rejected_steps": [{"frame": 1}]}).suspect

    def test_round_trip_of_a_written_summary(self, tmp_path):
        from dcslam.io.atomic import write_json_atomic

        path = write_json_atomic(tmp_path / "d.json", {"rejected_steps": [], "health": {
            "suspect": True, "reasons": ["3 of 10 steps degraded (more than 10%)"], "degraded": 3, "rejected": 0}})
        assert read_verdict(path) == RunVerdict(True, ("3 of 10 steps degraded (more than 10%)",), 0, 3)
        assert json.loads(path.read_text())["health"]["degraded"] == 3
