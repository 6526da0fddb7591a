"""Where the points that leave a local map go: an append-only archive in an unnamed temporary file, so that a long
drive's memory stays flat and its whole map can still be written at the end.

Each appended part is stored as the raw bytes of its fields (a dataclass of tensors, one row per point, such as
:class:`~dcslam.slam.pointmap.PointMap`), one field after the other; only the part sizes and the fields' dtypes and
shapes stay in memory, and :meth:`MapArchive.read` rebuilds the appended class from them, so this module needs no
map module (nothing here imports :mod:`dcslam.slam.pointmap`, which imports this one). The file is deleted when
the archive is cleared, closed or collected (``tempfile.TemporaryFile``).
"""
from __future__ import annotations

import tempfile
from dataclasses import fields

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
        # (offset in bytes, points, ((field, dtype, shape per point), ...)) per part
        self._parts: list[tuple[int, int, tuple[tuple[str, torch.dtype, tuple[int, ...]], ...]]] = []
        self._kind = None                      # the class of the appended maps
        self._points = 0
        self.nbytes = 0                        # bytes in the file

    def __len__(self) -> int:
        return self._points

    def append(self, pm) -> None:
        """Store the points of ``pm`` (a :class:`PointMap`, or any dataclass of tensors with one row per point;
        gradients are not kept). Every part is of the first part's class."""
        if len(pm) == 0:
            return
        if self._kind is not None and type(pm) is not self._kind:
            raise DcslamError(f"map archive holds {self._kind.__name__} parts, not {type(pm).__name__}")
        if self._file is None:
            self._file = tempfile.TemporaryFile(prefix="dcslam-map-archive-")
        self._file.seek(0, 2)
        offset = self._file.tell()
        layout = []
        for f in fields(pm):
            column = getattr(pm, f.name).detach()
            self._file.write(memoryview(column.cpu().contiguous().numpy()).cast("B"))
            layout.append((f.name, column.dtype, tuple(column.shape[1:])))
        self.nbytes = self._file.tell()
        self._kind = type(pm)
        self._parts.append((offset, len(pm), tuple(layout)))
        self._points += len(pm)

    def read(self, then=None):
        """Every archived point, detached, on the CPU, in append order, followed by the points of ``then`` (a map of
        the appended class, any device) when given -> the appended class (:class:`PointMap`) or None when empty.
        Each field is allocated once at its final size and read into in place: reading back a long drive's map
        costs the map's memory, not twice or thrice it."""
        if not self._parts:
            return None
        layout = self._parts[0][2]
        if any(part[2] != layout for part in self._parts):
            raise DcslamError(f"map archive {self._file.name}: parts of different dtypes or shapes")
        extra = 0 if then is None else len(then)
        columns = {name: torch.empty((self._points + extra, *tail), dtype=dtype) for name, dtype, tail in layout}
        row = 0
        for offset, n, _ in self._parts:
            self._file.seek(offset)
            for name, _, _ in layout:
                target = memoryview(columns[name][row:row + n].numpy()).cast("B")
                if self._file.readinto(target) != len(target):
                    raise DcslamError(f"map archive {self._file.name}: truncated (the temporary file was changed "
                                      "outside dcslam); run the SLAM again")
            row += n
        if extra:
            for name in columns:
                columns[name][row:].copy_(getattr(then, name).detach())
        return self._kind(**columns)

    def clear(self) -> None:
        """Forget every point and delete the file."""
        if self._file is not None:
            self._file.close()
        self._file, self._parts, self._kind, self._points, self.nbytes = None, [], None, 0, 0
