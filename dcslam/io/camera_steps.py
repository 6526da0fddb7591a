"""The camera's steps over a drive (:mod:`dcslam.slam.camera`), kept by ``dcslam slam --camera`` in
``<drives>/.camera/<drive>-<key>.npz`` so that every input judged by the same camera reads them instead of measuring
them again: a NumPy ``.npz`` (no pickles) of ``T`` (S, 4, 4) float64, ``covariance`` (S, 6, 6) float64 (NaN where a
step was not measured), ``returns`` (S,) int64 and ``measured`` (S,) bool (docs/formats.md).

A cache: the reader answers None for anything it cannot read as S steps (then they are measured again), and the
writer keeps nothing where it cannot write.
"""
from __future__ import annotations

import io
import zipfile
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError

FIELDS = {"T": (4, 4), "covariance": (6, 6), "returns": (), "measured": ()}


def write_camera_steps(path: Path, T: np.ndarray, covariance: np.ndarray, returns: np.ndarray,
                       measured: np.ndarray) -> bool:
    """Write S steps to ``path`` atomically; False (nothing written) where its folder cannot be made or written.
    Shapes: T (S, 4, 4), covariance (S, 6, 6), returns (S,), measured (S,); a mismatch is a :class:`ValueError`."""
    from dcslam.io.atomic import write_bytes_atomic

    arrays = {"T": np.asarray(T, np.float64), "covariance": np.asarray(covariance, np.float64),
              "returns": np.asarray(returns, np.int64), "measured": np.asarray(measured, bool)}
    n = len(arrays["T"])
    for name, shape in FIELDS.items():
        if arrays[name].shape != (n, *shape):
            raise ValueError(f"camera steps: {name} has shape {arrays[name].shape}, expected {(n, *shape)}")
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_bytes_atomic(path, buffer.getvalue())
    except (OSError, DcslamError):
        return False
    return True


def read_camera_steps(path: Path, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The ``n`` steps kept in ``path``: (T, covariance, returns, measured) as written, or None when there is no such
    file or it does not read as ``n`` steps (not an npz, a field missing or of another shape or kind)."""
    try:
        with np.load(path, allow_pickle=False) as f:
            arrays = {name: f[name] for name in FIELDS}
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile):
        return None
    kinds = {"T": "f", "covariance": "f", "returns": "iu", "measured": "b"}
    if any(arrays[name].shape != (n, *shape) or arrays[name].dtype.kind not in kinds[name]
           for name, shape in FIELDS.items()):
        return None
    return arrays["T"], arrays["covariance"], arrays["returns"], arrays["measured"]
