"""Where the points that leave a local map go: an append-only archive in an unnamed temporary file, so that a long
drive's memory stays flat and its whole map can still be written at the end.

Each appended part is stored as the raw bytes of its :class:`~dcslam.slam.pointmap.PointMap` fields, one field
after the other; only the part sizes and dtypes stay in memory. The file is deleted when the archive is cleared,
closed or collected (``tempfile.TemporaryFile``).
"""
from __future__ import annotations

import tempfile
from dataclasses import fields

import numpy as np
import torch

from dcslam.errors import DcslamError


class MapArchive:
    """Detached copies of map points, kept on disk. ``len()`` is the number of points archived.

    >>> archive = MapArchive()
    >>> archive.append(old_points)        # a PointMap (any device; stored detached, read back on the CPU)
    >>> archive.read()                    # every archived point in append order, or None
    """

    def __init__(self) -> None:
        self._file = None
        self._parts: list[tuple[int, int, torch.dtype]] = []       # (offset in bytes, points, float dtype)
        self._points = 0
        self.nbytes = 0                        # bytes in the file

    def __len__(self) -> int:
        return self._points

    def append(self, pm) -> None:
        """Store the points of ``pm`` (a :class:`PointMap`; gradients are not kept)."""
        if len(pm) == 0:
            return
        if self._file is None:
            self._file = tempfile.TemporaryFile(prefix="dcslam-map-archive-")
        self._file.seek(0, 2)
        offset = self._file.tell()
        for f in fields(pm):
            self._file.write(getattr(pm, f.name).detach().cpu().contiguous().numpy().tobytes())
        self.nbytes = self._file.tell()
        self._parts.append((offset, len(pm), pm.points.dtype))
        self._points += len(pm)

    def read(self):
        """Every archived point, detached, on the CPU, in append order -> :class:`PointMap` or None when empty."""
        from dcslam.slam.pointmap import PointMap

        if not self._parts:
            return None
        template = PointMap.empty()
        columns: dict[str, list[torch.Tensor]] = {f.name: [] for f in fields(template)}
        for offset, n, dtype in self._parts:
            self._file.seek(offset)
            for f in fields(template):
                column = getattr(template, f.name)
                kind = dtype if column.is_floating_point() else column.dtype
                shape = (n, column.shape[1]) if column.ndim == 2 else (n,)
                nbytes = int(np.prod(shape)) * torch.empty(0, dtype=kind).element_size()
                raw = self._file.read(nbytes)
                if len(raw) != nbytes:
                    raise DcslamError(f"map archive {self._file.name}: truncated (the temporary file was changed "
                                      "outside dcslam); run the SLAM again")
                array = np.frombuffer(raw, dtype=torch.empty(0, dtype=kind).numpy().dtype).reshape(shape)
                columns[f.name].append(torch.from_numpy(array.copy()))
        return PointMap(**{name: torch.cat(parts) for name, parts in columns.items()})

    def clear(self) -> None:
        """Forget every point and delete the file."""
        if self._file is not None:
            self._file.close()
        self._file, self._parts, self._points, self.nbytes = None, [], 0, 0
