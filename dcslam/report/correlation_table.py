"""Which depth metric predicts localisation? The rank correlation of each with the localisation error, as a table.

The pairs are every row of a table (a depth layer) on every test drive (and training seed, for a row over seeds): the
row's depth metric on that drive and its localisation error (the thesis's metric) there. For each metric of
:data:`METRICS`: Spearman's rho over the pairs with its 95 % percentile bootstrap interval over the pairs
(:func:`dcslam.report.correlation.rank_correlation`, :data:`RESAMPLES` resamples, generator seed :data:`SEED`), the
number of pairs, and the same over the pairs whose SLAM run did not fail. Rows without localisation (no SLAM run
scored) and pairs without the metric are left out and counted. Failed runs are kept: rho uses only the order, so a
failure counts as the largest errors without its size outweighing the rest.
"""
from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

from dcslam.report.correlation import RankCorrelation, rank_correlation
from dcslam.report.tables import Column, Table

#: The depth metrics correlated with localisation: (key of the per-drive figures, name).
METRICS = (("mae_mm", "MAE (mm)"), ("rmse_mm", "RMSE (mm)"), ("normal_median_deg", "normal error, median (°)"),
           ("p2p_mean_m", "point-to-plane, mean (m)"), ("flying_share", "flying share"))
RESAMPLES = 2000
SEED = 0
MIN_PAIRS = 3  # Spearman's rho of fewer pairs is not defined (:func:`dcslam.report.correlation.rank_correlation`)

COLUMNS = [Column("metric", "depth metric"), Column("pairs", "pairs"), Column("rho_text", "rho [95 % CI]"),
           Column("left_out", "left out"), Column("failed", "failed (kept)"),
           Column("rho_without_failed_text", "rho without failed [95 % CI]")]
CSV_COLUMNS = [Column(k, k) for k in (
    "metric", "key", "pairs", "rho", "ci_low", "ci_high", "resamples", "left_out", "failed", "pairs_without_failed",
    "rho_without_failed", "ci_low_without_failed", "ci_high_without_failed")]


def _text(c: RankCorrelation | None) -> str | None:
    if c is None:
        return None
    if math.isnan(c.rho):
        return "undefined (a side is constant)"
    if math.isnan(c.low):
        return f"{c.rho:+.2f}"
    return f"{c.rho:+.2f} [{c.low:+.2f}, {c.high:+.2f}]"


def _correlate(x: list[float], y: list[float]) -> RankCorrelation | None:
    return rank_correlation(x, y, RESAMPLES, seed=SEED) if len(x) >= MIN_PAIRS else None


def correlation_table(rows: Iterable[tuple[str, object]], title: str, failure_threshold: float,
                      depth_note: str = "") -> Table:
    """The rank correlation of each depth metric with localisation over the (row × drive) pairs of ``rows``:
    ``(name, result)`` with ``result`` a :class:`dcslam.report.table_5_2.LayerResult` or ``SeedResults`` (their
    per-drive figures, ``per_drive_rows``). ``depth_note``: a line on how the metrics were computed."""
    pairs, without_localisation = [], []  # pairs: the per-drive figures of each (row, seed, drive) with localisation
    for name, result in rows:
        have = [values for _, _, values in result.per_drive_rows() if values.get("localisation") is not None]
        if not have:
            without_localisation.append(name)
        pairs += have
    table = Table(title, COLUMNS, csv_columns=CSV_COLUMNS)
    for key, label in METRICS:
        kept = [v for v in pairs if v.get(key) is not None and not (isinstance(v[key], float) and math.isnan(v[key]))]
        ok = [v for v in kept if not v.get("failed")]
        every = _correlate([v[key] for v in kept], [v["localisation"] for v in kept])
        steady = _correlate([v[key] for v in ok], [v["localisation"] for v in ok])
        table.rows.append({
            "metric": label, "key": key, "pairs": len(kept), "left_out": len(pairs) - len(kept),
            "failed": len(kept) - len(ok), "pairs_without_failed": len(ok),
            "rho": None if every is None else every.rho, "ci_low": None if every is None else every.low,
            "ci_high": None if every is None else every.high, "resamples": None if every is None else every.resamples,
            "rho_text": _text(every) or f"— (fewer than {MIN_PAIRS} pairs)",
            "rho_without_failed": None if steady is None else steady.rho,
            "ci_low_without_failed": None if steady is None else steady.low,
            "ci_high_without_failed": None if steady is None else steady.high,
            "rho_without_failed_text": _text(steady) or f"— (fewer than {MIN_PAIRS} pairs)"})
    infinite = sum(1 for v in pairs for k, _ in METRICS[:2] if v.get(k) is not None and np.isinf(v[k]))
    table.notes += [
        "each pair: one row on one test drive (and training seed), its depth metric there and its localisation error "
        "there (the thesis's metric, m + rad); rho: Spearman's rank correlation over the pairs (> 0: a larger "
        "metric goes with worse localisation); 95 % CI: percentile bootstrap over the pairs "
        f"({RESAMPLES} resamples of as many pairs with replacement, generator seed {SEED}). The pairs share drives "
        "and rows, which the bootstrap does not model: read the interval as a lower bound of the uncertainty",
        f"failed (kept): pairs whose SLAM run failed (flagged suspect, or localisation above "
        f"{failure_threshold:g} m + rad); kept because rho uses only the order, so a failure counts as the largest "
        "errors without its size outweighing the rest; 'without failed' drops them",
        f"left out: pairs without the metric (e.g. a surface metric no sampled frame defines); {len(pairs)} pairs "
        f"with localisation, and {len(without_localisation)} row(s) without localisation (no SLAM run scored) left "
        "out entirely" + (f": {', '.join(without_localisation)}" if without_localisation else ""),
        (f"{infinite} MAE / RMSE value(s) are infinite (a layer left empty on a drive): ranked as the largest"
         if infinite else ""),
        depth_note,
        "how the pairs and the interval are computed: docs/metrics.md, 'Which depth metric predicts localisation'"]
    table.notes = [n for n in table.notes if n]
    return table
