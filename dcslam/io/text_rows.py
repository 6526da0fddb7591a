"""Text files of numbers, one record per line (TUM trajectories, KITTI pose files): one reader for both."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError


def read_number_rows(path: Path | str, columns: int, fmt: str, what: str = "pose file",
                     comments: bool = False, unit: str = "numbers") -> np.ndarray:
    """Every non-empty line of ``path`` as ``columns`` finite floats -> (N, columns) float64.

    ``fmt`` describes the expected format in the error messages; ``comments`` lets lines starting with ``#`` and
    commas between fields through (TUM's tools write both); ``unit`` names a line's items in messages. Fails with one
    line naming the file and line for a missing file, a wrong count, a non-number, no rows or a NaN/inf.
    """
    path = Path(path)
    if path.is_dir():
        raise DcslamError(f"{what} {path} is a folder; pass a {'TUM trajectory' if comments else 'pose'} file "
                          f"({fmt})")
    if not path.is_file():
        raise DcslamError(f"{what} {path} not found")
    rows = []
    for number, line in enumerate(path.read_text().splitlines(), 1):
        line = line.strip()
        if comments:
            if line.startswith("#"):
                continue
            line = line.replace(",", " ")
        fields = line.split()
        if not fields:
            continue
        if len(fields) != columns:
            raise DcslamError(f"{path}:{number}: {len(fields)} {unit}, expected {columns} ({fmt})")
        try:
            rows.append([float(f) for f in fields])
        except ValueError:
            raise DcslamError(f"{path}:{number}: not a number ({fmt})") from None
    if not rows:
        raise DcslamError(f"{path}: no poses ({fmt})")
    data = np.array(rows)
    finite = np.isfinite(data).all(axis=1)
    if not finite.all():
        bad = int(np.flatnonzero(~finite)[0])
        raise DcslamError(f"{path}: pose {bad} has non-finite values (NaN or infinite: a failed trajectory?); "
                          f"remake the file")
    return data
