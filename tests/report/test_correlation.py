import math

import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.report.correlation import _ranks, paired, rank_correlation, spearman_rho


def test_ranks_are_scipys_average_ranks_row_by_row_ties_included():
    from scipy.stats import rankdata  # here, not at the top: every pytest worker imports this file (1.6-2.0 CPU-s)

    rng = np.random.default_rng(5)
    for shape, values in (((6,), 2), ((9,), 100), ((4, 7), 3), ((300, 25), 6), ((30, 11), 10**9)):
        x = rng.integers(0, values, size=shape).astype(np.float64)
        assert np.array_equal(_ranks(x), rankdata(x, method="average", axis=-1)), (shape, values)
    assert _ranks(np.array([2.0, 2.0, 2.0])).tolist() == [2.0, 2.0, 2.0]
    assert _ranks(np.array([0.3, -1.0, 0.3, 7.0, -1.0])).tolist() == [3.5, 1.5, 3.5, 5.0, 1.5]


def test_rho_is_scipys_on_known_data():
    from scipy.stats import spearmanr

    rng = np.random.default_rng(0)
    x = rng.normal(size=40)
    y = 0.6 * x + rng.normal(size=40)
    assert spearman_rho(x, y) == pytest.approx(spearmanr(x, y).statistic, abs=1e-12)
    assert spearman_rho([1, 2, 3, 4, 5], [1, 4, 9, 16, 25]) == pytest.approx(1.0)     # monotone, not linear
    assert spearman_rho([1, 2, 3, 4, 5], [5, 4, 3, 2, 1]) == pytest.approx(-1.0)


def test_rho_is_scipys_on_ties():
    from scipy.stats import spearmanr

    x = [1.0, 2.0, 2.0, 3.0, 3.0, 3.0, 7.0, 8.0]
    y = [2.0, 1.0, 4.0, 4.0, 3.0, 9.0, 9.0, 9.0]
    assert spearman_rho(x, y) == pytest.approx(spearmanr(x, y).statistic, abs=1e-12)
    assert math.isnan(spearman_rho([1.0, 1.0, 1.0], [1.0, 2.0, 3.0]))


def test_interval_holds_rho_and_is_seeded():
    from scipy.stats import spearmanr

    rng = np.random.default_rng(1)
    x = rng.normal(size=30)
    y = x + rng.normal(size=30)
    r = rank_correlation(x, y, resamples=500, seed=3)
    assert r.rho == pytest.approx(spearmanr(x, y).statistic, abs=1e-12)
    assert -1 <= r.low < r.rho < r.high <= 1 and r.pairs == 30 and r.resamples == 500 and r.level == 0.95
    assert rank_correlation(x, y, resamples=500, seed=3) == r
    assert rank_correlation(x, y, resamples=500, seed=4) != r
    narrow = rank_correlation(x, y, resamples=500, seed=3, level=0.5)
    assert r.low < narrow.low < narrow.high < r.high


def test_interval_widens_with_fewer_pairs():
    rng = np.random.default_rng(2)
    x = rng.normal(size=200)
    y = x + rng.normal(size=200)
    few, many = rank_correlation(x[:12], y[:12], seed=0), rank_correlation(x, y, seed=0)
    assert few.high - few.low > many.high - many.low


def test_constant_side_has_no_interval():
    r = rank_correlation([1.0, 1.0, 1.0, 1.0], [1.0, 2.0, 3.0, 4.0], resamples=50)
    assert math.isnan(r.rho) and math.isnan(r.low) and r.resamples == 0


def test_perfect_order_gives_a_point_interval():
    r = rank_correlation(np.arange(10.0), np.arange(10.0) ** 3, resamples=200)
    assert r.rho == pytest.approx(1.0) and r.low == pytest.approx(1.0) and r.high == pytest.approx(1.0)


def test_paired_keys_and_bad_input():
    metric = {("ip-basic", "d0"): 1.0, ("ip-basic", "d1"): 2.0, ("sparse", "d0"): 3.0, ("dense", "d9"): 4.0}
    error = {("ip-basic", "d0"): 0.1, ("ip-basic", "d1"): 0.3, ("sparse", "d0"): 0.2}
    keys, x, y = paired(metric, error)
    assert keys == [("ip-basic", "d0"), ("ip-basic", "d1"), ("sparse", "d0")]
    assert x.tolist() == [1.0, 2.0, 3.0] and y.tolist() == [0.1, 0.3, 0.2]
    with pytest.raises(DcslamError, match="share no"):
        paired({"a": 1.0}, {"b": 1.0})
    with pytest.raises(DcslamError, match="same length"):
        spearman_rho([1.0, 2.0, 3.0], [1.0, 2.0])
    with pytest.raises(DcslamError, match="at least 3"):
        spearman_rho([1.0, 2.0], [1.0, 2.0])
    with pytest.raises(DcslamError, match="NaN"):
        rank_correlation([1.0, 2.0, math.nan], [1.0, 2.0, 3.0])
    with pytest.raises(DcslamError, match="level"):
        rank_correlation([1.0, 2.0, 3.0], [1.0, 2.0, 3.0], level=95)
