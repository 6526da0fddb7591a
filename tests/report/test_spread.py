"""Spread of a row across drives: mean, sample std, 95 % t-interval, median, failures; paired differences."""
import math

import pytest

from dcslam.errors import DcslamError
from dcslam.report.spread import differs, spread, t_quantile


def test_t_quantiles_match_printed_tables():
    # two-sided 95 %: 12.706 (1 dof), 4.303 (2), 3.182 (3), 2.776 (4), 2.262 (9), from any statistics table
    for dof, value in ((1, 12.706), (2, 4.303), (3, 3.182), (4, 2.776), (9, 2.262)):
        assert t_quantile(0.95, dof) == pytest.approx(value, abs=5e-4)
    with pytest.raises(DcslamError, match="degree of freedom"):
        t_quantile(0.95, 0)


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
