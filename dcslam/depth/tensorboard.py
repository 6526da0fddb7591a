"""Training curves for TensorBoard, beside ``metrics.jsonl``: :class:`TensorBoardWriter` takes the records
:func:`dcslam.depth.train.train_loop` writes there (dicts with ``kind``, ``epoch``, ``step`` and numbers: ``loss``,
``lr``, the loss's parts, the validation scores) and writes each number as the scalar ``<kind>/<key>`` at ``step``.

TensorBoard reads its event files while they grow, so they are appended to in place (not written under a temporary
name and renamed as dcslam's other files are): each event is framed with its own checksums, so an interrupted run
leaves a readable prefix. Needs the ``tensorboard`` package (the ``tensorboard`` extra); torch's writer is imported
only when a writer is made.
"""
from __future__ import annotations

import math
from pathlib import Path

from dcslam.errors import DcslamError

INSTALL = "pip install 'dcslam[tensorboard]'"
#: Keys of a record that place it (its series and position) rather than being plotted.
PLACING = ("kind", "epoch", "step")


def scalars(record: dict) -> dict[str, float]:
    """The plotted numbers of one record: ``{"<kind>/<key>": value}`` for each finite int or float (not a bool)
    other than :data:`PLACING`; a record without ``kind`` or an integer ``step`` is a :class:`DcslamError`."""
    if not isinstance(record, dict) or "kind" not in record or not isinstance(record.get("step"), int) \
            or isinstance(record.get("step"), bool):
        raise DcslamError(f"not a metrics record (needs kind and an integer step): {str(record)[:80]}")
    return {f"{record['kind']}/{key}": float(value) for key, value in record.items()
            if key not in PLACING and isinstance(value, (int, float)) and not isinstance(value, bool)
            and math.isfinite(value)}


class TensorBoardWriter:
    """Event files under ``log_dir`` (made if missing): :meth:`write` a record, :meth:`close` (or use ``with``)
    when done; ``purge_step``: events at or after that step already in ``log_dir`` are dropped (a resumed run).
    ``epoch`` is written too, as the scalar ``<kind>/epoch``, so curves can be read per epoch."""

    def __init__(self, log_dir: Path | str, purge_step: int | None = None) -> None:
        try:
            from torch.utils.tensorboard import SummaryWriter
        except ImportError:
            raise DcslamError(f"--log tensorboard needs the tensorboard package: {INSTALL}") from None
        self.log_dir = Path(log_dir)
        # purge_step: a resumed run drops the events an earlier process wrote from that step on, as metrics.jsonl
        # drops its rows after the checkpoint, so no step is plotted twice
        self._writer = SummaryWriter(log_dir=str(self.log_dir), purge_step=purge_step)

    def write(self, record: dict) -> None:
        """One metrics record (as written to ``metrics.jsonl``)."""
        values = scalars(record)
        if isinstance(record.get("epoch"), int):
            values[f"{record['kind']}/epoch"] = float(record["epoch"])
        for tag, value in values.items():
            self._writer.add_scalar(tag, value, global_step=record["step"])

    def flush(self) -> None:
        self._writer.flush()

    def close(self) -> None:
        self._writer.close()

    def __enter__(self) -> "TensorBoardWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
