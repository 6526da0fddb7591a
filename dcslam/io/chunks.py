"""One frame of an HDF5 dataset stored one frame per chunk, read as ``dataset[i]`` reads it, in less CPU.

dcslam's drive and layer files keep each frame in a chunk of its own, deflated (level 1) and byte-shuffled. HDF5
inflates with the zlib it was built with; :class:`FrameReader` takes the chunk's bytes as stored and inflates them
with ISA-L (``isal``, where it is installed), then undoes the shuffle in NumPy: the same array, bit for bit, in
less than half the CPU (1242 x 375: a colour image 8.1 -> 3.7 ms, a sparse depth frame 3.8 -> 1.7 ms; reading was a
sixth of a sparse SLAM frame's CPU). Any other layout (other filters, chunks, byte order, a chunk whose
filters were skipped) and any chunk that does not inflate goes through h5py: its values, and its errors, are
h5py's. A chunk that inflates to other than one frame's bytes is refused in one line (HDF5 itself fills the missing
bytes with whatever its buffer held).
"""
from __future__ import annotations

import zlib

import numpy as np

from dcslam.errors import DcslamError

try:  # ISA-L's inflate: a zlib stream's bytes, the same as zlib.decompress gives, at 2.5 times the speed
    from isal.isal_zlib import decompress as _inflate
    from isal.isal_zlib import error as _isal_error
except ImportError:  # pragma: no cover - isal is a dependency; without it the format still reads, at zlib's speed
    _inflate, _isal_error = zlib.decompress, zlib.error

_DEFLATE, _SHUFFLE = 1, 2   # HDF5's filter identifiers (H5Z_FILTER_DEFLATE, H5Z_FILTER_SHUFFLE)


class FrameReader:
    """``reader(i)`` is ``dataset[i]`` (a new, writable array) for an (N, ...) h5py dataset. The layout is checked
    once, here; datasets that do not qualify are read by h5py every time."""

    def __init__(self, dataset):
        self.dataset = dataset
        self.shape = dataset.shape[1:]
        self.dtype = dataset.dtype
        self.shuffled = False
        self.fast = self._qualifies()

    def _qualifies(self) -> bool:
        d = self.dataset
        if d.ndim < 2 or d.chunks != (1, *self.shape) or d.dtype.kind not in "fiub" or not d.dtype.isnative:
            return False
        plist = d.id.get_create_plist()
        filters = [plist.get_filter(k)[0] for k in range(plist.get_nfilters())]
        self.shuffled = filters == [_SHUFFLE, _DEFLATE] and d.dtype.itemsize > 1
        return filters in ([_DEFLATE], [_SHUFFLE, _DEFLATE])

    def __call__(self, i: int) -> np.ndarray:
        if not self.fast or not 0 <= i < self.dataset.shape[0]:
            return self.dataset[i]
        try:
            mask, stored = self.dataset.id.read_direct_chunk((i,) + (0,) * len(self.shape))
            data = _inflate(stored) if mask == 0 else None
        except (OSError, ValueError, zlib.error, _isal_error):    # let h5py read it, and say what is wrong with it
            data = None
        if data is None:
            return self.dataset[i]
        size = self.dtype.itemsize * int(np.prod(self.shape))
        if len(data) != size:   # HDF5 would hand back the frame's missing bytes as whatever its buffer held
            raise DcslamError(f"{self.dataset.file.filename}: {self.dataset.name} frame {i} inflates to {len(data)} "
                              f"bytes, expected {size}: the file is damaged; make it again")
        raw = np.frombuffer(data, np.uint8)
        if self.shuffled:  # HDF5's shuffle stores byte k of every element, then byte k + 1: put them back side by side
            k = self.dtype.itemsize
            planes, out = raw.reshape(k, -1), np.empty((size // k, k), np.uint8)
            for b in range(k):
                out[:, b] = planes[b]
            return out.view(self.dtype).reshape(self.shape)
        return raw.view(self.dtype).reshape(self.shape).copy()
