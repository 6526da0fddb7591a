"""Progress bars on stderr (rich), so that stdout stays for results.

Set ``DCSLAM_PROGRESS=0`` to silence them (tests do).
"""
from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from typing import TypeVar

T = TypeVar("T")


def enabled() -> bool:
    return os.environ.get("DCSLAM_PROGRESS", "1") != "0"


def track(items: Iterable[T], description: str, total: int | None = None) -> Iterator[T]:
    """Iterate over ``items`` with a progress bar on stderr (a no-op when progress is disabled)."""
    from dcslam.interrupt import check

    if not enabled():
        for item in items:
            check()
            yield item
        return
    from rich.console import Console
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                               TimeRemainingColumn)

    if total is None and hasattr(items, "__len__"):
        total = len(items)  # type: ignore[arg-type]
    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
               TimeRemainingColumn(), TextColumn("{task.fields[status]}"))
    with Progress(*columns, console=Console(stderr=True), transient=False) as bar:
        task = bar.add_task(description, total=total, status="")
        for item in items:
            check()
            yield item
            bar.advance(task)


class Bar:
    """A progress bar driven by hand, for loops that report a running value (e.g. a loss).

    >>> with Bar("train", total=10) as bar:
    ...     bar.advance(status="loss 0.12")
    """

    def __init__(self, description: str, total: int | None):
        self.description, self.total = description, total
        self._progress = None
        self._task = None

    def __enter__(self) -> "Bar":
        if enabled():
            from rich.console import Console
            from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                                       TimeRemainingColumn)

            self._progress = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                                      TimeElapsedColumn(), TimeRemainingColumn(), TextColumn("{task.fields[status]}"),
                                      console=Console(stderr=True))
            self._progress.__enter__()
            self._task = self._progress.add_task(self.description, total=self.total, status="")
        return self

    def advance(self, n: int = 1, status: str | None = None) -> None:
        from dcslam.interrupt import check

        check()  # a Ctrl-C swallowed by a finalizer still stops the loop here
        if self._progress is not None:
            fields = {} if status is None else {"status": status}
            self._progress.update(self._task, advance=n, **fields)

    def __exit__(self, *exc) -> None:
        if self._progress is not None:
            self._progress.__exit__(*exc)
