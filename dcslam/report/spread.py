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
    from scipy.stats import t

    if dof < 1:
        raise DcslamError(f"a t-interval needs at least 1 degree of freedom, got {dof}")
    return float(t.ppf(0.5 + confidence / 2, dof))


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
