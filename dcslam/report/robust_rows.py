"""The robust columns of the beams tables: each row against the sparse input of its beam count by the signed-rank
test and the bootstrap interval of the median paired difference, and the share of the sparse → exact gap it closes
measured between medians (:mod:`dcslam.report.robust`).

A row's per-drive figure is its localisation on that drive (a row over several training seeds: the mean over its
seeds on that drive, so that drives, not runs, are the pairs). The drives on which every row of a beam count fails,
exact depth included (:func:`dcslam.report.robust.failed_by_all`), are left out of these columns and named in the
table's notes: no input localises there, so they cannot tell one input from another; the mean ± t columns keep them.
The beam-independent rows (beams "any") are compared with the largest beam count's sparse input and share its
left-out drives.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dcslam.report.robust import (SIGNED_RANK_MIN_N, MedianDifference, SignedRank, failed_by_all,
                                  gap_closed_by_medians, median_difference, signed_rank)

Key = tuple  # (beams | None, label) of a row of the beams table


def drive_localisation(result) -> dict[str, float]:
    """``{drive: localisation}`` of a row: its own per drive, or over several seeds the mean of its seeds' runs on
    each drive every seed has."""
    by_seed = result.localisation_by_seed()
    runs = list(by_seed.values())
    drives = [d for d in runs[0] if all(d in r for r in runs)]
    return {d: sum(r[d] for r in runs) / len(runs) for d in drives}


def failed_drives(result) -> set[str]:
    """The drives on which a row failed (:meth:`dcslam.report.results.LayerResult.failed`); over several seeds, the
    drives on which every seed's run failed."""
    members = getattr(result, "members", [result])
    drives = set(drive_localisation(result))
    return {d for d in drives if all(m.failed(d) for m in members)}


@dataclass(frozen=True)
class RobustComparison:
    """One row against its sparse reference over ``drives`` (those both have, less the drives every row fails on):
    the signed-rank test, the median paired difference (row − sparse) with its bootstrap interval, the verdict that
    interval gives and the gap closed between medians (``None``: no exact row, or exact no better than sparse)."""

    drives: int
    rank: SignedRank
    median: MedianDifference
    gap_closed: float | None

    @property
    def verdict(self) -> str:
        """``better`` / ``worse`` when the interval of the median difference lies below / above zero, ``within``
        when it holds zero, ``one drive`` without an interval."""
        if self.median.excludes_zero is None:
            return "one drive"
        if not self.median.excludes_zero:
            return "within"
        return "better" if self.median.median < 0 else "worse"

    def p_text(self) -> str:
        """The signed-rank p-value, or ``n<6`` when fewer than 6 drives differ (no p below 0.05 is possible)."""
        if self.rank.n < SIGNED_RANK_MIN_N or self.rank.p_value is None:
            return f"n<{SIGNED_RANK_MIN_N}"
        return f"{self.rank.p_value:.3f}"

    def fields(self) -> dict:
        """The row's robust fields: CSV values and the Markdown texts (``*_text``, ``robust_vs_sparse``)."""
        m = self.median
        return {"robust_drives": self.drives, "signed_rank_n": self.rank.n, "signed_rank_p": self.rank.p_value,
                "signed_rank_p_text": self.p_text(), "median_diff": m.median, "median_diff_ci_low": m.ci_low,
                "median_diff_ci_high": m.ci_high, "median_diff_text": m.text("{:+.4f}"),
                "robust_vs_sparse": self.verdict, "gap_closed_median": self.gap_closed,
                "gap_closed_median_text": None if self.gap_closed is None else f"{100 * self.gap_closed:.0f} %"}


def compare(row: dict[str, float], sparse: dict[str, float], exact: dict[str, float] | None,
            left_out: set[str] = frozenset()) -> RobustComparison | None:
    """``row`` (``{drive: localisation}``) against ``sparse`` on the drives both have (and ``exact`` has, for the
    gap), less ``left_out``; None when no drive remains."""
    drives = [d for d in sparse if d in row and d not in left_out]
    if not drives:
        return None
    values, reference = [row[d] for d in drives], [sparse[d] for d in drives]
    gap = None
    if exact is not None and all(d in exact for d in drives):
        ceiling = [exact[d] for d in drives]
        if np.median(reference) > np.median(ceiling):  # exact no better than sparse: no gap to close
            gap = gap_closed_by_medians(values, reference, ceiling)
    return RobustComparison(len(drives), signed_rank(values, reference), median_difference(values, reference), gap)


def robust_columns(results: dict, beams: list[int]) -> tuple[dict[Key, dict], dict[int, list[str]]]:
    """The robust fields of every row of the beams table (``results``: ``{(beams | None, label): result}``) and the
    drives every row fails on, by beam count. A row is compared with ``(b, "sparse")`` of its beam count (the
    beam-independent rows with the largest beam count's) and its gap measured to ``(None, "exact")``; the sparse row
    itself is the ``reference``, exact has no gap of its own, and a row whose every drive is left out says ``no
    drive``."""
    top = max(beams)
    scored = {k: r for k, r in results.items() if r.pairs}
    figures = {k: drive_localisation(r) for k, r in scored.items()}
    exact = figures.get((None, "exact"))
    left_out: dict[int, list[str]] = {}
    for b in beams:
        rows = {k: f for k, f in figures.items() if k[0] in (b, None)}
        if rows:
            threshold = next(iter(scored.values())).failure_threshold
            left_out[b] = failed_by_all({repr(k): f for k, f in rows.items()}, threshold,
                                        {repr(k): failed_drives(scored[k]) for k in rows})
    fields: dict[Key, dict] = {}
    for key, row in figures.items():
        b = key[0] if key[0] is not None else top
        sparse = figures.get((b, "sparse"))
        if sparse is None:
            continue
        skip = set(left_out.get(b, ()))
        if key == (b, "sparse"):
            fields[key] = {"robust_vs_sparse": "reference", "robust_drives": len(set(row) - skip)}
            continue
        comparison = compare(row, sparse, None if key == (None, "exact") else exact, skip)
        # every drive left out (every row failed on each): nothing to compare, and the row says so
        fields[key] = comparison.fields() if comparison is not None else {"robust_vs_sparse": "no drive",
                                                                           "robust_drives": 0}
    return fields, left_out


ROBUST_NOTE = (
    "robust columns: signed-rank p: two-sided Wilcoxon signed-rank test of the per-drive localisation differences "
    "from the sparse input of the same beam count (n<6: fewer than 6 drives differ, so no p below 0.05 is possible); "
    "median Δ: median of those differences (row − sparse; < 0 better) with its 95 % percentile-bootstrap interval "
    "over drives; robust vs sparse: better / worse when that interval excludes zero, else within (no drive: every "
    "drive left out); gap closed "
    "(medians): (median sparse − median row) / (median sparse − median exact) over the same drives; a row over "
    "several training seeds takes the mean of its seeds on each drive")


def left_out_text(left_out: dict[int, list[str]]) -> str:
    """The note naming the drives every row failed on, by beam count (left out of the robust columns)."""
    named = [f"{b} beams: {', '.join(drives)}" for b, drives in sorted(left_out.items(), reverse=True) if drives]
    if not named:
        return ("drives on which every row fails (exact included): none, so the robust columns use every drive")
    return ("drives on which every row fails (exact included), left out of the robust columns and kept in the means: "
            + "; ".join(named))
