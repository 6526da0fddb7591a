import numpy as np
import pytest

from dcslam.slam.evidence import EvidenceRules, evidence_line, judge, merge, position_gaps, unavailable


def _trajectory(xs):
    """Poses along x at the given positions. Shape: -> (N, 4, 4)."""
    T = np.tile(np.eye(4), (len(xs), 1, 1))
    T[:, 0, 3] = xs
    return T


GOOD = {"suspect": False, "reasons": [], "drift_sigma_m": 0.02}


def test_position_gaps_over_the_frames_both_have():
    assert np.allclose(position_gaps(_trajectory([0, 1, 2]), _trajectory([0, 1.5])), [0, 0.5])


def test_a_run_that_agrees_with_its_companion_is_ok():
    verdict = judge(_trajectory([0, 1, 2.1]), _trajectory([0, 1, 2]), GOOD, "sparse@16")
    assert verdict["verdict"] == "agrees" and not verdict["suspect"] and verdict["reason"] is None
    assert verdict["gap_m"] == pytest.approx(0.1) and verdict["bound_m"] == 0.48
    health = merge({"suspect": False, "reasons": []}, verdict)
    assert not health["suspect"] and health["evidence"] is verdict
    assert evidence_line(health) == "ends within 0.10 m of the sparse@16 companion (bound 0.48 m)"


def test_a_gap_beyond_the_bound_flags_the_run_and_says_why():
    verdict = judge(_trajectory([0, 1.2, 2.8, 3.9]), _trajectory([0, 1, 2, 3]), GOOD, "sparse")
    assert verdict["verdict"] == "departs" and verdict["suspect"] and verdict["gap_frame"] == 2
    assert verdict["gap_m"] == pytest.approx(0.9) and verdict["max_gap_m"] == pytest.approx(0.9)
    assert verdict["reason"] == ("ends 0.90 m from the sparse companion, past the bound from frame 2 (bound 0.48 m: "
                                 "3 x its sigma 0.020 m, at least 0.48 m)")
    health = merge({"suspect": False, "reasons": ["x"], "accepted": 3}, verdict)
    assert health["suspect"] and health["reasons"] == ["x", verdict["reason"]] and health["accepted"] == 3


def test_the_gap_that_counts_is_where_the_run_ends():
    back = judge(_trajectory([0, 1.9, 3.0, 3.1]), _trajectory([0, 1, 2, 3]), GOOD, "sparse")
    assert back["verdict"] == "agrees" and back["gap_m"] == pytest.approx(0.1) and back["gap_frame"] == 3
    assert back["max_gap_m"] == pytest.approx(1.0) and back["max_gap_frame"] == 2   # kept, not counted
    away = judge(_trajectory([0, 1.9, 2.1, 3.7]), _trajectory([0, 1, 2, 3]), GOOD, "sparse@8", road_corrected=True)
    assert away["verdict"] == "departs" and away["gap_frame"] == 3 and away["road_corrected"]
    assert away["reason"].startswith("ends 0.70 m from the sparse@8 companion (road-corrected), past the bound from "
                                     "frame 3")


def test_the_floor_sits_just_under_the_half_metre_asked_about():
    """A run that ends 0.49 m from its companion may end beyond 0.5 m from the truth: the default floor flags it, one of
    exactly 0.5 m (the rule before) did not."""
    near = judge(_trajectory([0, 1, 2.49]), _trajectory([0, 1, 2]), GOOD, "sparse")
    assert near["verdict"] == "departs" and near["suspect"] and near["bound_m"] == 0.48
    assert judge(_trajectory([0, 1, 2.47]), _trajectory([0, 1, 2]), GOOD, "sparse")["verdict"] == "agrees"
    assert judge(_trajectory([0, 1, 2.49]), _trajectory([0, 1, 2]), GOOD, "sparse",
                 EvidenceRules(floor_m=0.5))["verdict"] == "agrees"


def test_the_bound_grows_with_the_companions_own_uncertainty():
    rules = EvidenceRules(sigmas=3.0, floor_m=0.5)
    assert rules.bound_m(0.01) == 0.5 and rules.bound_m(0.3) == pytest.approx(0.9)
    loose = {"suspect": False, "reasons": [], "drift_sigma_m": 0.3}
    assert judge(_trajectory([0, 0.8]), _trajectory([0, 0]), loose, "sparse", rules)["verdict"] == "agrees"


def test_a_suspect_companion_bounds_nothing():
    companion = {"suspect": True, "reasons": ["13 of 29 steps rejected"], "drift_sigma_m": 0.07}
    verdict = judge(_trajectory([0, 1]), _trajectory([0, 1]), companion, "sparse@8")
    assert verdict["verdict"] == "unbounded" and verdict["suspect"]
    assert verdict["reason"] == ("no evidence bounds the drift (the sparse@8 companion is itself suspect: "
                                 "13 of 29 steps rejected)")


def test_measured_depth_with_a_suspect_companion_is_judged_by_its_own_steps():
    """Dense or exact depth is no completion: when its sparse companion is suspect, its own steps judge it, as they
    judge a sparse run; a completion stays unbounded whatever its own steps say."""
    companion = {"suspect": True, "reasons": ["8 of 29 steps degraded (more than 10%)"], "drift_sigma_m": 0.07}
    verdict = judge(_trajectory([0, 1]), _trajectory([0, 3]), companion, "sparse", measured=True)
    assert verdict["verdict"] == "own" and not verdict["suspect"] and verdict["reason"] is None
    assert verdict["gap_m"] == pytest.approx(2.0) and verdict["companion"] == "sparse"
    assert verdict["note"] == "judged by its own steps, as measured depth: the sparse companion is itself suspect"
    assert verdict["companion_reasons"] == companion["reasons"]
    fine = merge({"suspect": False, "reasons": []}, verdict)
    assert not fine["suspect"] and evidence_line(fine) == verdict["note"]
    weak = merge({"suspect": True, "reasons": ["1 of 29 steps rejected"], "rejected": 1}, verdict)
    assert weak["suspect"] and weak["reasons"] == ["1 of 29 steps rejected"] and "overruled" not in weak
    completed = judge(_trajectory([0, 1]), _trajectory([0, 1]), companion, "sparse")
    assert completed["verdict"] == "unbounded" and merge({"suspect": False, "reasons": []}, completed)["suspect"]


def test_without_a_companion_the_summary_says_so_and_stays_unflagged():
    none = unavailable("layer.h5 does not say which measured depth it was made from")
    health = merge({"suspect": False, "reasons": []}, none)
    assert not health["suspect"] and health["reasons"] == []
    assert evidence_line(health) == ("no evidence bounds the drift (layer.h5 does not say which measured depth it "
                                     "was made from)")
    assert evidence_line(merge({"suspect": False, "reasons": []}, unavailable("x", "own"))) is None
    assert "--evidence none" in evidence_line(merge({"suspect": False}, unavailable("--evidence none", "off")))
    with pytest.raises(ValueError):
        unavailable("x", "agrees")


def test_an_agreeing_companion_outweighs_weak_steps_but_not_rejected_ones():
    agrees = judge(_trajectory([0, 1]), _trajectory([0, 1.1]), GOOD, "sparse")
    weak = {"suspect": True, "reasons": ["3 of 29 steps degraded (more than 10%)"], "rejected": 0}
    health = merge(weak, agrees)
    assert not health["suspect"] and health["reasons"] == [] and health["overruled"] == weak["reasons"]
    refused = {**weak, "rejected": 1, "reasons": ["1 of 29 steps rejected (pose predicted, not measured)"]}
    assert merge(refused, agrees)["suspect"] and "overruled" not in merge(refused, agrees)


def test_an_agreeing_companion_does_not_overrule_the_road():
    """The road figure measures the run's own vertical error from its depth: a companion that agrees within its floor
    overrules the weak-step reasons beside it, not the road's (a sinking run's own summary)."""
    from dcslam.slam.health import road_reason, summarise
    from tests.fixtures.road import seen, sinking, step_reports

    truth, estimated = sinking()
    own = summarise(step_reports(estimated, [seen(T) for T in truth]))
    road = road_reason(own["reasons"])
    assert own["suspect"] and road.startswith("the road says the run sank 0.63 m")
    agrees = judge(_trajectory([0, 1]), _trajectory([0, 1.1]), GOOD, "sparse")
    weak = "2 consecutive steps degraded"
    health = merge({**own, "reasons": [weak, road]}, agrees)
    assert health["suspect"] and health["reasons"] == [road] and health["overruled"] == [weak]
    alone = merge(own, agrees)
    assert alone["suspect"] and alone["reasons"] == [road] and "overruled" not in alone
    assert road_reason([weak]) is None
