"""Training seeds as a dimension of a table: how the runs of one recipe trained with several seeds are named, found
and compared.

``dcslam reproduce --seeds N`` trains every trained run N times: the ``k``-th run of ``<run>`` is
:func:`seed_run_name` (``<run>`` for k = 0, so one seed keeps the names of a single run; ``<run>-s<k>`` after), and
its layers (predictions, filtered layers, SLAM outputs) carry that name. A table then gives each recipe one row over
all its seeds (:class:`dcslam.report.table_5_2.SeedResults`), compared with another row by :func:`paired`.
"""
from __future__ import annotations

import re

_SEED_SUFFIX = re.compile(r"^(?P<base>.+)-s(?P<k>[1-9][0-9]*)$")
# what may differ between the runs of one recipe beyond their seed: their names, what they start from (each seed
# from the same seed's source run) and how they were launched
VOLATILE_SETTINGS = ("seed", "name", "init", "resume", "nproc", "device")


def seed_run_name(name: str, k: int) -> str:
    """The ``k``-th training seed's run of ``name``: ``name`` itself for k = 0, ``<name>-s<k>`` after."""
    if k < 0:
        raise ValueError(f"seed index must be >= 0, got {k}")
    return name if k == 0 else f"{name}-s{k}"


def seed_base(name: str) -> tuple[str, int]:
    """The inverse of :func:`seed_run_name`: ``(name, k)`` of a run name (``("chamfer-1", 2)`` for
    ``chamfer-1-s2``; ``(name, 0)`` for a name without a seed suffix)."""
    match = _SEED_SUFFIX.match(name)
    return (match["base"], int(match["k"])) if match else (name, 0)


def seed_groups(runs: list, name=lambda run: run.name, settings=lambda run: run.settings) -> list[list]:
    """``runs`` grouped into the seeds of one run: those named :func:`seed_run_name` (base, k) of one base whose
    settings differ only in :data:`VOLATILE_SETTINGS`; in the order of each group's first run, each group by k. A run
    whose settings differ from its base's stays a group of its own."""
    def key(run):
        return {k: v for k, v in (settings(run) or {}).items() if k not in VOLATILE_SETTINGS}

    groups: dict[str, list] = {}
    alone: list[list] = []
    order: list = []
    for run in runs:
        base, _ = seed_base(name(run))
        group = groups.get(base)
        if group is None:
            groups[base] = [run]
            order.append(groups[base])
        elif key(group[0]) == key(run):
            group.append(run)
        else:
            alone.append([run])
            order.append(alone[-1])
    return [sorted(group, key=lambda r: seed_base(name(r))[1]) for group in order]


def paired(result, reference) -> tuple[bool | None, float]:
    """Whether ``result``'s localisation differs from ``reference``'s beyond the spread, and the sign-bearing sum of
    the paired differences (result − reference; < 0: ``result`` localises better).

    Both give ``localisation_by_seed()`` (``{seed: {drive: value}}``). Two rows of one seed each: the paired
    t-interval over their common drives (:func:`dcslam.report.spread.differs`). Otherwise the two-level interval over
    seeds × drives (:func:`dcslam.report.spread.differs_two_level`) of the differences on the drives both have,
    paired by seed when both rows have several seeds, by drive alone when one of them has a single run per drive.
    The verdict is ``None`` with fewer than 2 common drives."""
    from dcslam.report.spread import differs, differs_two_level

    a, b = result.localisation_by_seed(), reference.localisation_by_seed()
    if len(a) == 1 and len(b) == 1:
        (x,), (y,) = a.values(), b.values()
        common = [d for d in x if d in y]
        mine, theirs = [x[d] for d in common], [y[d] for d in common]
        return differs(mine, theirs), sum(mine) - sum(theirs)
    flip = len(a) == 1  # one row with a single run per drive: the other's seeds are resampled
    if flip:
        a, b = b, a
    first = next(iter(a.values()))
    drives = [d for d in first if all(d in v for v in a.values()) and all(d in v for v in b.values())]
    seeds = list(a) if len(b) == 1 else [s for s in a if s in b]
    mine = [[a[s][d] for d in drives] for s in seeds]
    theirs = [[b[s][d] for d in drives] for s in (seeds if len(b) > 1 else b)]
    total = sum(map(sum, mine)) / max(len(seeds), 1) - sum(map(sum, theirs)) / max(len(theirs), 1)
    if flip:
        total = -total
    if len(drives) < 2 or not seeds:
        return None, total
    return differs_two_level(mine, theirs), total
