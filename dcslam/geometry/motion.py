"""The motion between two poses: how far (metres) and how much turned (radians), for NumPy arrays and torch tensors.

One definition for the SLAM's step checks, the health gaps, the adaptive ICP gate and the trajectory scores:
``X = T_a^-1 T_b``, translation ``|t_X|``, rotation ``atan2(|sin|, cos)`` of ``R_X`` with
``|sin| = |vee(R_X - R_X^T)| / 2`` and ``cos = (trace(R_X) - 1) / 2``. That form is exact to rounding at every angle
in [0, pi]; ``acos`` of the trace alone loses half the digits near 0 (an angle below ~1e-8 rad reads as 0) and
near pi. ``T_a^-1`` is a general matrix inverse (a linear solve): rotations read from files (KITTI's poses print
about 7 digits) are orthonormal to ~1e-7 only, so ``R^T`` is not their inverse, and a pose scored against itself
through a transpose would differ from itself by ~1e-7 rad.
"""
from __future__ import annotations

import sys

import numpy as np

from dcslam.errors import DcslamError


def relative_motion(T_a, T_b):
    """Translation norm (metres, or the poses' unit) and rotation angle (radians, in [0, pi]) of ``T_a^-1 T_b``.

    Computed in float64 whatever the inputs' dtype. NumPy arrays (or anything ``np.asarray`` reads) give NumPy
    float64 arrays; torch tensors (float32 or float64, any device) give float64 tensors on that device,
    differentiable (the angle's gradient is undefined at exactly 0 and pi, where ``|sin|`` has a kink).

    Shape: T_a (..., 4, 4), T_b (..., 4, 4), batch dimensions broadcast -> metres (...), radians (...).
    """
    torch = sys.modules.get("torch")            # imported by the caller if it passes tensors; not imported here
    if torch is not None and (isinstance(T_a, torch.Tensor) or isinstance(T_b, torch.Tensor)):
        return _relative_motion_torch(torch, T_a, T_b)
    A, B = (np.asarray(T, dtype=np.float64) for T in (T_a, T_b))
    batch = _batch_shape(A.shape, B.shape)
    X = np.linalg.solve(np.broadcast_to(A, batch + (4, 4)), np.broadcast_to(B, batch + (4, 4)))
    R = X[..., :3, :3]
    vee = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    cos = (R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2] - 1.0) / 2.0
    return np.linalg.norm(X[..., :3, 3], axis=-1), np.arctan2(np.linalg.norm(vee, axis=-1) / 2.0, cos)


def _relative_motion_torch(torch, T_a, T_b):
    device = T_a.device if isinstance(T_a, torch.Tensor) else T_b.device
    A, B = (torch.as_tensor(T, device=device).to(torch.float64) for T in (T_a, T_b))
    # NumPy's broadcast of the batch shapes: torch.broadcast_shapes imports sympy on its first call (~0.5 CPU-s)
    batch = _batch_shape(tuple(A.shape), tuple(B.shape))
    X = torch.linalg.solve(A.expand(*batch, 4, 4), B.expand(*batch, 4, 4))
    R = X[..., :3, :3]
    vee = torch.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    cos = (R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2] - 1.0) / 2.0
    return X[..., :3, 3].norm(dim=-1), torch.atan2(vee.norm(dim=-1) / 2.0, cos)


def _batch_shape(a: tuple, b: tuple) -> tuple[int, ...]:
    """The broadcast batch shape of poses of shapes ``a`` and ``b`` (each (..., 4, 4)), checked."""
    for name, shape in (("T_a", a), ("T_b", b)):
        if len(shape) < 2 or tuple(shape[-2:]) != (4, 4):
            raise DcslamError(f"{name} has shape {tuple(shape)}, expected (..., 4, 4)")
    try:
        return np.broadcast_shapes(tuple(a[:-2]), tuple(b[:-2]))
    except ValueError:
        raise DcslamError(f"poses of shapes {tuple(a)} and {tuple(b)} do not broadcast") from None
