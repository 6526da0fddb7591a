"""The spread of a figure across test drives (or training seeds): mean, standard deviation, a 95 % t-interval of
the mean, median and the number of failures.

A table row of dcslam is a mean over drives; with a handful of drives one failed SLAM run moves that mean more than
any real difference between rows, so every row also carries its spread, its median and how many drives failed, and
two rows are said to differ only when the interval of their difference excludes zero.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dcslam.errors import DcslamError

CONFIDENCE = 0.95


def t_quantile(confidence: float, dof: int) -> float:
    """Two-sided Student-t quantile: the half-width factor of a ``confidence`` interval with ``dof`` degrees of
    freedom (e.g. 12.706 for 0.95 and 1, 2.776 for 0.95 and 4)."""
    from scipy.special import stdtrit  # what scipy.stats.t.ppf computes, without importing scipy.stats (1.5 CPU-s)

    if dof < 1:
        raise DcslamError(f"a t-interval needs at least 1 degree of freedom, got {dof}")
    return float(stdtrit(dof, 0.5 + confidence / 2))


@dataclass(frozen=True)
class Spread:
    """Summary of ``n`` values (one per drive). ``std`` is the sample standard deviation (ddof 1); ``ci_low`` /
    ``ci_high`` the ``confidence`` t-interval of the mean; both ``None`` for a single value. ``failures`` counts the
    drives flagged as failed (they are included in every figure: a failure is a result)."""

    n: int
    mean: float
    std: float | None
    ci_low: float | None
    ci_high: float | None
    median: float
    failures: int = 0

    @property
    def half_width(self) -> float | None:
        return None if self.ci_high is None else (self.ci_high - self.ci_low) / 2

    def text(self, fmt: str = "{:.3f}") -> str:
        """``mean ± half-width`` (the 95 % interval's), or the bare mean for a single drive."""
        if self.half_width is None or not math.isfinite(self.half_width):
            return fmt.format(self.mean)
        return f"{fmt.format(self.mean)} ± {fmt.format(self.half_width)}"


def spread(values, failures: int = 0, confidence: float = CONFIDENCE) -> Spread:
    """The :class:`Spread` of ``values`` (K,), finite numbers; fails on an empty or non-finite input."""
    x = np.asarray(list(values), dtype=np.float64)
    if x.ndim != 1 or len(x) == 0:
        raise DcslamError(f"spread of {x.shape} values: expected (K,) with K > 0")
    if not np.all(np.isfinite(x)):
        raise DcslamError("spread of values that are not all finite")
    mean, median = float(x.mean()), float(np.median(x))
    if len(x) == 1:
        return Spread(1, mean, None, None, None, median, failures)
    std = float(x.std(ddof=1))
    half = t_quantile(confidence, len(x) - 1) * std / math.sqrt(len(x))
    return Spread(len(x), mean, std, mean - half, mean + half, median, failures)


def differs(values, reference, confidence: float = CONFIDENCE) -> bool | None:
    """Whether two rows measured on the same drives differ beyond their spread: the paired t-interval of the
    per-drive differences (K,) excludes zero. ``None`` with fewer than 2 drives (nothing to tell)."""
    a, b = np.asarray(list(values), dtype=np.float64), np.asarray(list(reference), dtype=np.float64)
    if a.shape != b.shape:
        raise DcslamError(f"paired values of different shapes {a.shape} and {b.shape}")
    if len(a) < 2:
        return None
    diff = spread(a - b, confidence=confidence)
    if diff.std == 0:
        return diff.mean != 0
    return not (diff.ci_low <= 0 <= diff.ci_high)


#: Resamples of :func:`two_level_interval`, and the seed of its random generator (fixed: a table made twice from the
#: same runs prints the same intervals).
BOOTSTRAP_RESAMPLES = 10000
BOOTSTRAP_SEED = 0
TWO_LEVEL_METHOD = (f"two-level percentile bootstrap ({BOOTSTRAP_RESAMPLES} resamples, generator seed "
                    f"{BOOTSTRAP_SEED}): training seeds resampled with replacement, then the test drives with "
                    "replacement, the same drives for every resampled seed (each drive is run by every seed)")


def _matrix(values) -> np.ndarray:
    x = np.asarray(values, dtype=np.float64)
    if x.ndim != 2 or x.size == 0:
        raise DcslamError(f"values of shape {x.shape}: expected (S seeds, D drives) with S, D > 0")
    if not np.all(np.isfinite(x)):
        raise DcslamError("values that are not all finite")
    return x


def two_level_interval(values, confidence: float = CONFIDENCE, resamples: int = BOOTSTRAP_RESAMPLES,
                       seed: int = BOOTSTRAP_SEED) -> tuple[float, float]:
    """The ``confidence`` interval of the mean of ``values`` (S seeds, D drives) that counts both sources of spread:
    each of ``resamples`` bootstrap samples draws S seeds with replacement, then D drives with replacement (one draw
    of drives for all the drawn seeds: the drives are shared, so their effect must not average out across seeds),
    and takes the mean of that (S, D) sample; the interval is the percentiles of those means. A single seed reduces
    it to the bootstrap over drives, a single drive to the bootstrap over seeds."""
    x = _matrix(values)
    s, d = x.shape
    rng = np.random.default_rng(seed)
    means = np.empty(resamples)
    chunk = max(1, 2_000_000 // (s * d))
    for start in range(0, resamples, chunk):
        n = min(chunk, resamples - start)
        rows = rng.integers(0, s, size=(n, s))
        cols = rng.integers(0, d, size=(n, d))
        means[start:start + n] = x[rows[:, :, None], cols[:, None, :]].mean(axis=(1, 2))
    tail = 100 * (1 - confidence) / 2
    low, high = np.percentile(means, [tail, 100 - tail])
    return float(low), float(high)


@dataclass(frozen=True)
class SeedSpread:
    """Summary of values over ``seeds`` training seeds × ``drives`` test drives: their ``mean``, the two-level
    bootstrap interval of it (:func:`two_level_interval`), ``seed_std`` (the sample std of the per-seed means over
    the drives: the seed-to-seed spread alone; None for one seed), the ``median`` of all values and the
    ``failures`` among the runs."""

    seeds: int
    drives: int
    mean: float
    ci_low: float
    ci_high: float
    seed_std: float | None
    median: float
    failures: int = 0

    def text(self, fmt: str = "{:.3f}") -> str:
        """``mean [low, high]`` (the interval is not symmetric about the mean)."""
        return f"{fmt.format(self.mean)} [{fmt.format(self.ci_low)}, {fmt.format(self.ci_high)}]"


def seed_spread(values, failures: int = 0, confidence: float = CONFIDENCE) -> SeedSpread:
    """The :class:`SeedSpread` of ``values`` (S, D), finite numbers."""
    x = _matrix(values)
    low, high = two_level_interval(x, confidence)
    per_seed = x.mean(axis=1)
    return SeedSpread(x.shape[0], x.shape[1], float(x.mean()), low, high,
                      float(per_seed.std(ddof=1)) if len(per_seed) > 1 else None, float(np.median(x)), failures)


def differs_two_level(values, reference, confidence: float = CONFIDENCE) -> bool | None:
    """Whether a row measured by several seeds on the same drives differs from ``reference`` beyond the spread:
    the two-level interval of the per-run differences excludes zero. ``values`` (S, D); ``reference`` (S, D) (paired
    by seed and drive) or (1, D) (a row without seeds, paired by drive). ``None`` with fewer than 2 drives."""
    a, b = _matrix(values), _matrix(reference)
    if b.shape[1] != a.shape[1] or b.shape[0] not in (1, a.shape[0]):
        raise DcslamError(f"paired values of shapes {a.shape} and {b.shape}: expected (S, D) and (S, D) or (1, D)")
    if a.shape[1] < 2:
        return None
    low, high = two_level_interval(a - b, confidence)
    return not (low <= 0 <= high)
