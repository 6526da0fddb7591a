"""Paired comparisons that one failing drive does not swamp: beside the mean and its t-interval
(:mod:`dcslam.report.spread`), the Wilcoxon signed-rank test of the per-drive differences against a reference row,
a bootstrap interval of their median, the gap closed measured between medians, and the drives on which every input
fails (reported apart: no row can be told from another there).

A drive whose SLAM fails has a localisation error tens of times the others'; it moves a mean over five drives more
than any real difference between rows, but moves a median or a rank by one place at most.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from dcslam.errors import DcslamError
from dcslam.report.spread import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED, CONFIDENCE

#: Fewest non-zero paired differences with which a two-sided signed-rank test can reach p < 0.05: its smallest
#: p-value is 2 / 2^n (0.0625 with 5, 0.03125 with 6).
SIGNED_RANK_MIN_N = 6


def _paired(values, reference) -> np.ndarray:
    """(K,) differences ``values - reference`` of two (K,) finite rows measured on the same drives."""
    a, b = np.asarray(list(values), np.float64), np.asarray(list(reference), np.float64)
    if a.ndim != 1 or a.shape != b.shape:
        raise DcslamError(f"paired values of shapes {a.shape} and {b.shape}: expected two (K,) rows on the same drives")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        raise DcslamError("paired values that are not all finite")
    return a - b


@dataclass(frozen=True)
class SignedRank:
    """The two-sided Wilcoxon signed-rank test of paired differences against zero. ``n``: the non-zero differences
    (zeros carry no sign and are dropped); ``statistic``: the smaller of the positive and negative rank sums;
    ``p_value``: exact without ties, else the normal approximation (scipy's choice); ``None`` when every difference
    is zero. ``can_reject``: whether ``n`` allows p < 0.05 at all (``n >= 6``); with fewer drives a large p says
    nothing about the rows."""

    n: int
    statistic: float | None
    p_value: float | None

    @property
    def can_reject(self) -> bool:
        return self.n >= SIGNED_RANK_MIN_N


def signed_rank(values, reference) -> SignedRank:
    """The signed-rank test of ``values - reference``, both (K,) per-drive figures of two rows on the same drives."""
    from scipy.stats import wilcoxon

    d = _paired(values, reference)
    d = d[d != 0]
    if len(d) == 0:
        return SignedRank(0, None, None)
    result = wilcoxon(d, zero_method="wilcox", alternative="two-sided")
    return SignedRank(len(d), float(result.statistic), float(result.pvalue))


@dataclass(frozen=True)
class MedianDifference:
    """The median of paired differences ``values - reference`` over ``n`` drives and the percentile-bootstrap
    ``confidence`` interval of it (drives resampled with replacement); both bounds ``None`` for a single drive."""

    n: int
    median: float
    ci_low: float | None
    ci_high: float | None

    @property
    def excludes_zero(self) -> bool | None:
        """Whether the interval lies wholly on one side of zero (``None`` without an interval)."""
        return None if self.ci_low is None else not (self.ci_low <= 0 <= self.ci_high)

    def text(self, fmt: str = "{:+.3f}") -> str:
        """``median [low, high]``, or the bare median for a single drive."""
        if self.ci_low is None:
            return fmt.format(self.median)
        return f"{fmt.format(self.median)} [{fmt.format(self.ci_low)}, {fmt.format(self.ci_high)}]"


def median_difference(values, reference, confidence: float = CONFIDENCE, resamples: int = BOOTSTRAP_RESAMPLES,
                      seed: int = BOOTSTRAP_SEED) -> MedianDifference:
    """The :class:`MedianDifference` of two (K,) rows on the same drives; the generator's seed is fixed, so a table
    made twice prints the same interval."""
    d = _paired(values, reference)
    if len(d) == 0:
        raise DcslamError("median difference of no drives")
    if len(d) == 1:
        return MedianDifference(1, float(d[0]), None, None)
    rng = np.random.default_rng(seed)
    medians = np.median(d[rng.integers(0, len(d), size=(resamples, len(d)))], axis=1)
    tail = 100 * (1 - confidence) / 2
    low, high = np.percentile(medians, [tail, 100 - tail])
    return MedianDifference(len(d), float(np.median(d)), float(low), float(high))


def gap_closed_by_medians(values, sparse, exact) -> float | None:
    """The share of the gap between the sparse input and the exact depth that a row closes, measured between
    medians over the same drives: ``(median(sparse) - median(values)) / (median(sparse) - median(exact))`` for a
    figure where lower is better (1: as good as exact depth, 0: no better than sparse, negative: worse than sparse).
    ``None`` when the two medians agree (no gap to close). All three are (K,) rows on the same drives."""
    x, s, e = (np.asarray(list(r), np.float64) for r in (values, sparse, exact))
    if not (x.ndim == 1 and x.shape == s.shape == e.shape and len(x)):
        raise DcslamError(f"rows of shapes {x.shape}, {s.shape}, {e.shape}: expected three (K,) rows, K > 0, on the "
                          "same drives")
    if not all(np.all(np.isfinite(r)) for r in (x, s, e)):
        raise DcslamError("gap closed of values that are not all finite")
    gap = float(np.median(s) - np.median(e))
    return None if gap == 0 else float(np.median(s) - np.median(x)) / gap


def failed_by_all(rows: Mapping[str, Mapping[str, float]], threshold: float | None = None,
                  flagged: Mapping[str, set] | None = None) -> list[str]:
    """The drives on which every row fails, exact depth included: no input localises there, so the drive says
    nothing about which input is better and is reported apart. A row fails on a drive when its figure (the thesis
    localisation error) exceeds ``threshold`` (default the tables' :data:`dcslam.report.results.FAILURE_THRESHOLD`)
    or when ``flagged[row]`` names the drive (its SLAM run was flagged suspect).

    Args:
        rows: ``{row: {drive: figure}}``; only the drives every row has are judged.
    Returns:
        the drives, sorted.
    """
    if threshold is None:
        from dcslam.report.results import FAILURE_THRESHOLD as threshold
    if not rows:
        raise DcslamError("failed drives of no rows")
    flagged = flagged or {}
    unknown = sorted(set(flagged) - set(rows))
    if unknown:
        raise DcslamError(f"flagged drives of rows {unknown} that are not among the rows {sorted(rows)}")
    drives = set.intersection(*(set(figures) for figures in rows.values()))
    return sorted(drive for drive in drives
                  if all(figures[drive] > threshold or drive in flagged.get(row, ()) for row, figures in rows.items()))
