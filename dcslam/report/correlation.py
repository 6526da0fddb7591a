"""Does a depth metric predict localisation? Spearman's rank correlation over (row x drive) pairs.

Each pair is one depth layer (a table row) on one drive: its depth metric there (MAE, normal angle error, flying
share, ...) and its localisation error there. Spearman's rho is the Pearson correlation of the two ranks (ties take
the mean of the ranks they span, as :func:`scipy.stats.spearmanr`); it is 1 when the error grows with the metric
however non-linearly, 0 when the metric's order says nothing about the error's. Its 95 % confidence interval is
the percentile bootstrap over pairs: ``resamples`` draws of as many pairs with replacement from a seeded generator,
rho of each; a draw in which either side is constant has no rho and is left out.
"""
from __future__ import annotations

from collections.abc import Hashable, Mapping
from dataclasses import asdict, dataclass

import numpy as np

from dcslam.errors import DcslamError


@dataclass(frozen=True)
class RankCorrelation:
    """Spearman's rho of ``pairs`` pairs and its bootstrap interval [``low``, ``high``] at ``level`` from
    ``resamples`` draws that had a rho (NaN throughout when one side is constant)."""

    rho: float
    low: float
    high: float
    pairs: int
    resamples: int
    level: float

    def as_dict(self) -> dict:
        return asdict(self)


def _ranks(x: np.ndarray) -> np.ndarray:
    """Ranks 1..N along the last axis, ties given their mean rank (``scipy.stats.rankdata``'s "average", the same
    numbers: a test compares them; in NumPy, as importing scipy.stats costs 1.5 CPU-s a process).
    Shape: (..., N) -> (..., N) float64."""
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[-1]
    order = np.argsort(x, axis=-1, kind="stable")
    ordered = np.take_along_axis(x, order, -1)
    first = np.ones(x.shape, dtype=bool)  # where a run of equal values starts, in sorted order
    first[..., 1:] = ordered[..., 1:] != ordered[..., :-1]
    last = np.ones(x.shape, dtype=bool)
    last[..., :-1] = first[..., 1:]
    position = np.broadcast_to(np.arange(n), x.shape)
    start = np.maximum.accumulate(np.where(first, position, 0), axis=-1)
    end = np.flip(np.minimum.accumulate(np.flip(np.where(last, position, n - 1), -1), axis=-1), -1)
    ranks = np.empty(x.shape, dtype=np.float64)
    np.put_along_axis(ranks, order, (start + end) / 2 + 1, -1)
    return ranks


def _pearson_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pearson correlation of each row of ``a`` with the same row of ``b``; NaN where a row is constant.
    Shape: a, b (R, N) -> (R,)."""
    a = a - a.mean(-1, keepdims=True)
    b = b - b.mean(-1, keepdims=True)
    norm = np.sqrt((a * a).sum(-1) * (b * b).sum(-1))
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = (a * b).sum(-1) / norm
    return np.where(norm > 0, np.clip(rho, -1.0, 1.0), np.nan)


def _check(metric, error) -> tuple[np.ndarray, np.ndarray]:
    x, y = np.asarray(metric, dtype=np.float64), np.asarray(error, dtype=np.float64)
    if x.ndim != 1 or x.shape != y.shape:
        raise DcslamError(f"metric {x.shape} and localisation error {y.shape} must be 1-D of the same length "
                          "(one value per row and drive)")
    if len(x) < 3:
        raise DcslamError(f"rank correlation needs at least 3 (row, drive) pairs, got {len(x)}")
    if np.isnan(x).any() or np.isnan(y).any():
        raise DcslamError("metric and localisation error must not be NaN; leave out the pairs without a value")
    return x, y


def spearman_rho(metric, error) -> float:
    """Spearman's rho of two samples (ties ranked by their mean rank); NaN when either is constant.

    Shape: metric (N,), error (N,), N >= 3.
    """
    x, y = _check(metric, error)
    return float(_pearson_rows(_ranks(x)[None], _ranks(y)[None])[0])


def rank_correlation(metric, error, resamples: int = 2000, level: float = 0.95, seed: int = 0) -> RankCorrelation:
    """Spearman's rho of a depth metric with localisation error over (row x drive) pairs, with its percentile
    bootstrap interval at ``level`` (module docstring); the same ``seed`` gives the same interval.

    Shape: metric (N,), error (N,), N >= 3: entry i of both is the same (row, drive) pair.
    """
    x, y = _check(metric, error)
    if resamples < 1:
        raise DcslamError(f"resamples must be >= 1, got {resamples}")
    if not 0 < level < 1:
        raise DcslamError(f"level must lie in (0, 1), got {level}")
    rho = spearman_rho(x, y)
    draws = np.random.default_rng(seed).integers(0, len(x), size=(resamples, len(x)))
    boot = _pearson_rows(_ranks(x[draws]), _ranks(y[draws]))
    boot = boot[~np.isnan(boot)]
    if np.isnan(rho) or not len(boot):
        return RankCorrelation(rho, np.nan, np.nan, len(x), int(len(boot)), level)
    low, high = np.quantile(boot, [(1 - level) / 2, (1 + level) / 2])
    return RankCorrelation(rho, float(low), float(high), len(x), int(len(boot)), level)


def paired(metric: Mapping[Hashable, float], error: Mapping[Hashable, float]
           ) -> tuple[list[Hashable], np.ndarray, np.ndarray]:
    """The pairs both mappings have a value for, keyed alike (e.g. ``(row, drive)``), in sorted key order:
    (keys, metric (N,), error (N,)). Fails when they share none."""
    keys = sorted(set(metric) & set(error), key=repr)
    if not keys:
        raise DcslamError("the depth metric and the localisation error share no (row, drive) pair")
    return keys, np.array([metric[k] for k in keys], np.float64), np.array([error[k] for k in keys], np.float64)
