"""Robust paired statistics: the signed-rank test against an exact enumeration, the bootstrap interval of the median
difference, the gap closed by medians and the drives every input fails on, on hand-computed cases."""
import itertools

import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.report.robust import failed_by_all, gap_closed_by_medians, median_difference, signed_rank
from dcslam.report.spread import differs


def _exact_signed_rank_p(d) -> float:
    """Two-sided exact p-value of the signed-rank statistic by enumerating all 2^n sign patterns of the ranks
    (distinct magnitudes, no zeros): 2 x the smaller tail of the positive rank sum, at most 1."""
    ranks = np.argsort(np.argsort(np.abs(d))) + 1
    observed = ranks[np.asarray(d) > 0].sum()
    sums = np.array([sum(r for r, s in zip(ranks, signs) if s) for signs in itertools.product((0, 1), repeat=len(d))])
    return min(1.0, 2 * min((sums <= observed).mean(), (sums >= observed).mean()))


@pytest.mark.parametrize("d, p_hand", [
    ([1.0, 2, 3, 4, 5, 6], 2 / 64),          # all positive: only one pattern as extreme on each side
    ([1.0, -2, 3, 4, 5, 6], 6 / 64),         # negative rank sum 2: {}, {1}, {2} on each side
    ([0.5, 1, 1.5, 2, 2.5], 2 / 32),         # five drives: the smallest p there is, above 0.05
])
def test_signed_rank_matches_the_exact_enumeration(d, p_hand):
    reference = np.linspace(1, 2, len(d))
    result = signed_rank(reference + np.asarray(d), reference)
    assert _exact_signed_rank_p(d) == pytest.approx(p_hand)
    assert result.p_value == pytest.approx(p_hand) and result.n == len(d)
    assert result.can_reject == (len(d) >= 6)


def test_signed_rank_drops_zero_differences():
    result = signed_rank([1.0, 2.0, 3.5, 4.0], [1.0, 2.0, 3.0, 5.0])
    assert result.n == 2 and not result.can_reject
    assert result.p_value == pytest.approx(_exact_signed_rank_p([0.5, -1.0]))
    none = signed_rank([1.0, 2.0], [1.0, 2.0])
    assert none.n == 0 and none.p_value is None and none.statistic is None


def test_one_failing_drive_swamps_the_mean_not_the_median():
    """Eight drives 0.05-0.4 m better than sparse, one failed (50 m worse): the mean difference is +5.4 m and the
    paired t-interval cannot tell the rows apart; the median difference is -0.2 m with an interval below zero."""
    reference = np.array([1.0, 1.2, 0.8, 1.5, 0.9, 1.1, 1.3, 0.7, 1.0])
    d = -np.array([0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, -50.0])
    values = reference + d
    assert d.mean() > 5 and differs(values, reference) is False
    median = median_difference(values, reference)
    assert median.median == pytest.approx(-0.2) and median.ci_high < 0 and median.excludes_zero
    assert signed_rank(values, reference).p_value == pytest.approx(_exact_signed_rank_p(d))


def test_median_difference_interval_by_hand():
    """Differences 1, 2, 3: a resample's median is 1 with probability 7/27 (two or three draws of 1), 3 likewise,
    so the 95 % interval is [1, 3] around the median 2; the same seed gives the same interval."""
    median = median_difference([2.0, 4.0, 6.0], [1.0, 2.0, 3.0])
    assert (median.n, median.median, median.ci_low, median.ci_high) == (3, 2.0, 1.0, 3.0)
    assert median == median_difference([2.0, 4.0, 6.0], [1.0, 2.0, 3.0])
    assert median.text("{:.1f}") == "2.0 [1.0, 3.0]"
    single = median_difference([3.0], [1.0])
    assert single.ci_low is None and single.excludes_zero is None and single.text("{:.1f}") == "2.0"
    with pytest.raises(DcslamError, match="shapes"):
        median_difference([1.0, 2.0], [1.0])
    with pytest.raises(DcslamError, match="finite"):
        median_difference([1.0, np.nan], [1.0, 2.0])
    with pytest.raises(DcslamError, match="no drives"):
        median_difference([], [])


def test_gap_closed_by_medians():
    sparse, exact = [2.0, 4.0, 6.0], [1.0, 1.0, 1.0]                    # medians 4 and 1: a gap of 3
    assert gap_closed_by_medians([3.0, 3.0, 100.0], sparse, exact) == pytest.approx(1 / 3)  # the failure ignored
    assert gap_closed_by_medians([1.0, 1.0, 0.5], sparse, exact) == pytest.approx(1.0)
    assert gap_closed_by_medians([5.0, 7.0, 9.0], sparse, exact) == pytest.approx(-1.0)   # worse than sparse
    assert gap_closed_by_medians([1.0, 2.0, 3.0], [1.0, 2.0, 3.0], [2.0, 2.0, 2.0]) is None
    with pytest.raises(DcslamError, match="same drives"):
        gap_closed_by_medians([1.0], sparse, exact)


def test_failed_by_all():
    rows = {"sparse": {"a": 5.0, "b": 0.2, "c": 3.0, "e": 2.0},
            "exact": {"a": 2.0, "b": 0.1, "c": 0.5, "e": 1.0},
            "scanline": {"a": 1.5, "b": 0.3, "c": 4.0, "d": 9.0, "e": 3.0}}
    assert failed_by_all(rows) == ["a"]                     # e: exact at the threshold itself has not failed
    assert failed_by_all(rows, threshold=0.9) == ["a", "e"]
    assert failed_by_all(rows, flagged={"exact": {"c"}}) == ["a", "c"]
    with pytest.raises(DcslamError, match="not among the rows"):
        failed_by_all(rows, flagged={"dense": {"a"}})
    with pytest.raises(DcslamError, match="no rows"):
        failed_by_all({})


def test_default_threshold_is_the_tables():
    from dcslam.report.results import FAILURE_THRESHOLD

    rows = {"sparse": {"a": FAILURE_THRESHOLD * 1.01}, "exact": {"a": FAILURE_THRESHOLD * 1.01}}
    assert failed_by_all(rows) == ["a"] and failed_by_all({"x": {"a": FAILURE_THRESHOLD}}) == []
