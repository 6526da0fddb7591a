"""Spread of a row across drives: mean, sample std, 95 % t-interval, median, failures; paired differences."""
import math

import numpy as np

import pytest

from dcslam.errors import DcslamError
from dcslam.report.spread import differs, spread, t_quantile


def test_t_quantiles_match_printed_tables():
    # two-sided 95 %: 12.706 (1 dof), 4.303 (2), 3.182 (3), 2.776 (4), 2.262 (9), from any statistics table
    for dof, value in ((1, 12.706), (2, 4.303), (3, 3.182), (4, 2.776), (9, 2.262)):
        assert t_quantile(0.95, dof) == pytest.approx(value, abs=5e-4)
    with pytest.raises(DcslamError, match="degree of freedom"):
        t_quantile(0.95, 0)


def test_t_quantiles_are_scipy_stats_ones():
    from scipy.stats import t

    for confidence in (0.5, 0.9, 0.95, 0.99):
        for dof in (1, 2, 3, 5, 8, 13, 30, 100):
            assert t_quantile(confidence, dof) == float(t.ppf(0.5 + confidence / 2, dof)), (confidence, dof)


def test_spread_of_four_drives_by_hand():
    s = spread([1.0, 2.0, 3.0, 4.0], failures=1)
    assert (s.n, s.mean, s.median, s.failures) == (4, 2.5, 2.5, 1)
    assert s.std == pytest.approx(math.sqrt(5 / 3))                 # sum of squares 5, over n - 1 = 3
    half = 3.182446 * math.sqrt(5 / 3) / 2                          # t(0.975, 3) · s / √n
    assert (s.ci_low, s.ci_high) == (pytest.approx(2.5 - half, abs=1e-5), pytest.approx(2.5 + half, abs=1e-5))
    assert s.text("{:.2f}") == "2.50 ± 2.05"


def test_one_failure_moves_the_mean_not_the_median():
    ok = spread([0.11, 0.12, 0.13, 0.12])
    failed = spread([0.11, 0.12, 0.13, 1.27])
    assert failed.mean - ok.mean == pytest.approx(0.2875)
    assert failed.median == pytest.approx(0.125) and ok.median == pytest.approx(0.12)


def test_single_drive_has_no_interval_and_bad_input_fails():
    s = spread([0.3])
    assert s.std is None and s.ci_low is None and s.text() == "0.300"
    for bad in ([], [1.0, float("nan")], [[1.0, 2.0]]):
        with pytest.raises(DcslamError):
            spread(bad)


def test_paired_difference_inside_or_beyond_the_spread():
    sparse = [0.11, 0.12, 0.13, 1.27]
    assert differs([v + 0.01 for v in sparse], sparse) is True      # steadily 1 cm worse on every drive
    assert differs([0.12, 0.11, 0.14, 0.80], sparse) is False       # better on one drive, worse on two: noise
    assert differs([0.5], [0.1]) is None                            # one drive tells nothing
    with pytest.raises(DcslamError, match="shapes"):
        differs([1.0, 2.0], [1.0])


def test_two_level_interval_known_answers():
    """Constructed cases whose bootstrap distribution is known exactly: the mean of 3 draws from {0, 1, 2} is 0 or 2
    with probability 1/27 each (> 2.5 %), so the 95 % percentile interval is exactly [0, 2]."""
    from dcslam.report.spread import seed_spread, two_level_interval

    seeds_only = [[0.0] * 3, [1.0] * 3, [2.0] * 3]  # (S=3, D=3): seeds differ, the drives do not
    assert two_level_interval(seeds_only) == (0.0, 2.0)
    # over drives alone (the per-drive means over seeds are all 1) the interval would be empty: the seeds count
    assert spread(np.mean(seeds_only, axis=0)).half_width == 0.0
    drives_only = np.transpose(seeds_only)
    assert two_level_interval(drives_only) == (0.0, 2.0)
    assert two_level_interval([[0.0], [1.0]]) == (0.0, 1.0)  # 2 seeds, 1 drive: 0, 0.5, 1 with 1/4, 1/2, 1/4
    assert two_level_interval([[0.4, 0.4], [0.4, 0.4]]) == (0.4, 0.4)
    # the drives are shared by every seed: resampling them once per sample keeps their effect. With
    # x[s, d] = 10 d, a sample mean is 10 × (mean of 3 drawn drives), so again exactly [0, 20]; drawing drives
    # per seed instead would average 3 independent draws and narrow it
    assert two_level_interval(10 * drives_only) == (0.0, 20.0)
    assert two_level_interval(np.random.default_rng(1).random((3, 5))) == \
        two_level_interval(np.random.default_rng(1).random((3, 5)))  # a fixed generator: reproducible tables
    sp = seed_spread([[0.0, 2.0], [4.0, 6.0]], failures=1)
    assert (sp.seeds, sp.drives, sp.mean, sp.median, sp.failures) == (2, 2, 3.0, 3.0, 1)
    assert sp.seed_std == pytest.approx(np.std([1.0, 5.0], ddof=1))  # the std of the per-seed means
    assert sp.ci_low <= sp.mean <= sp.ci_high and sp.text("{:.1f}") == f"3.0 [{sp.ci_low:.1f}, {sp.ci_high:.1f}]"
    assert seed_spread([[1.0, 2.0]]).seed_std is None


def test_two_level_interval_refuses_bad_input_and_verdicts_pair_by_drive():
    from dcslam.report.spread import differs_two_level, two_level_interval

    for bad in ([1.0, 2.0], [[]], [[1.0, np.nan]]):
        with pytest.raises(DcslamError):
            two_level_interval(bad)
    reference = [[0.1, 0.5, 0.9]]  # a row without seeds (1, D)
    shifted = [[0.2, 0.6, 1.0], [0.3, 0.7, 1.1]]  # every run 0.1 or 0.2 above it, drive by drive
    assert differs_two_level(shifted, reference) is True  # though the drives' own spread is much larger
    assert differs_two_level([[0.1, 0.5, 0.9], [0.1, 0.5, 0.9]], reference) is False
    assert differs_two_level([[0.2], [0.3]], [[0.1]]) is None  # one drive: nothing to tell
    with pytest.raises(DcslamError, match="paired values of shapes"):
        differs_two_level(shifted, [[0.1, 0.5]])
