"""Rotations in NumPy (float64): roll-pitch-yaw angles, unit quaternions, interpolation, look-at frames.

The torch, differentiable side is :mod:`dcslam.geometry.se3`; these helpers serve the file formats (OXTS angles,
TUM quaternions), the synthetic generators and the scores. Conventions:

- roll, pitch, yaw as in KITTI's OXTS and pykitti: ``R = Rz(yaw) · Ry(pitch) · Rx(roll)``;
- quaternions are Hamilton, scalar last, ``(qx, qy, qz, qw)``, as in TUM trajectory files.
"""
from __future__ import annotations

import numpy as np


def rotation_from_rpy(roll: np.ndarray, pitch: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Angles (N,) in radians → (N, 3, 3) rotations ``Rz(yaw) · Ry(pitch) · Rx(roll)``."""
    roll, pitch, yaw = (np.asarray(a, dtype=np.float64) for a in (roll, pitch, yaw))
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    return np.stack([
        np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], -1),
        np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], -1),
        np.stack([-sp, cp * sr, cp * cr], -1),
    ], -2)


def rpy_from_rotation(R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N, 3, 3) rotations ``Rz(yaw) Ry(pitch) Rx(roll)`` → roll, pitch, yaw (N,) each; the inverse of
    :func:`rotation_from_rpy` for pitch inside (−π/2, π/2)."""
    pitch = -np.arcsin(np.clip(R[:, 2, 0], -1, 1))
    roll = np.arctan2(R[:, 2, 1], R[:, 2, 2])
    yaw = np.arctan2(R[:, 1, 0], R[:, 0, 0])
    return roll, pitch, yaw


def rotation_to_quaternion(R: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices → (..., 4) unit quaternions (qx, qy, qz, qw) with qw >= 0."""
    R = np.asarray(R, dtype=np.float64)
    m = R.reshape(-1, 3, 3)
    q = np.empty((m.shape[0], 4))
    tr = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    # Shepperd's method: pick the largest of (w, x, y, z) to divide by, for accuracy everywhere.
    cands = np.stack([tr, m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]], axis=1)
    pick = np.argmax(cands, axis=1)
    for i in range(m.shape[0]):
        a = m[i]
        if pick[i] == 0:
            s = 2.0 * np.sqrt(max(1.0 + tr[i], 1e-300))
            q[i] = [(a[2, 1] - a[1, 2]) / s, (a[0, 2] - a[2, 0]) / s, (a[1, 0] - a[0, 1]) / s, 0.25 * s]
        elif pick[i] == 1:
            s = 2.0 * np.sqrt(max(1.0 + a[0, 0] - a[1, 1] - a[2, 2], 1e-300))
            q[i] = [0.25 * s, (a[0, 1] + a[1, 0]) / s, (a[0, 2] + a[2, 0]) / s, (a[2, 1] - a[1, 2]) / s]
        elif pick[i] == 2:
            s = 2.0 * np.sqrt(max(1.0 + a[1, 1] - a[0, 0] - a[2, 2], 1e-300))
            q[i] = [(a[0, 1] + a[1, 0]) / s, 0.25 * s, (a[1, 2] + a[2, 1]) / s, (a[0, 2] - a[2, 0]) / s]
        else:
            s = 2.0 * np.sqrt(max(1.0 + a[2, 2] - a[0, 0] - a[1, 1], 1e-300))
            q[i] = [(a[0, 2] + a[2, 0]) / s, (a[1, 2] + a[2, 1]) / s, 0.25 * s, (a[1, 0] - a[0, 1]) / s]
    q[q[:, 3] < 0] *= -1
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q.reshape(R.shape[:-2] + (4,))


def quaternion_to_rotation(q: np.ndarray) -> np.ndarray:
    """(..., 4) quaternions (qx, qy, qz, qw), normalised here → (..., 3, 3) rotation matrices."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def slerp(q0: np.ndarray, q1: np.ndarray, w: float) -> np.ndarray:
    """Spherical interpolation between unit quaternions (4,) at fraction ``w`` in [0, 1], along the shorter arc."""
    if float(q0 @ q1) < 0:
        q1 = -q1
    dot = min(float(q0 @ q1), 1.0)
    angle = np.arccos(dot)
    if angle < 1e-9:
        return q0
    return (np.sin((1 - w) * angle) * q0 + np.sin(w * angle) * q1) / np.sin(angle)


def look_rotation(forward: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """R_world_cam (N, 3, 3) of a camera with x right, **y up**, z forward (ICL-NUIM's) looking along ``forward``
    (N, 3) with the world's z axis up, rolled by ``roll`` (N,) radians about the optical axis. Columns x = y × z, so
    the rotation is proper (det +1)."""
    z = forward / np.linalg.norm(forward, axis=1, keepdims=True)
    up = np.array([0.0, 0.0, 1.0])
    y0 = up - (z @ up)[:, None] * z
    y0 /= np.linalg.norm(y0, axis=1, keepdims=True)
    c, s = np.cos(roll)[:, None], np.sin(roll)[:, None]
    y = c * y0 + s * np.cross(z, y0)
    x = np.cross(y, z)
    return np.stack([x, y, z], axis=2)


def nearest_rotation(R: np.ndarray) -> np.ndarray:
    """The rotation matrices nearest (Frobenius) to ``R``: ``U diag(1, 1, det(U Vᵀ)) Vᵀ`` from its SVD. Poses
    composed in float32 drift off SO(3) by ~1e-4 over tens of frames; this puts them back before they are written.
    Shapes: (..., 3, 3) -> (..., 3, 3) float64."""
    R = np.asarray(R, dtype=np.float64)
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"rotations have shape {R.shape}, expected (..., 3, 3)")
    U, _, Vt = np.linalg.svd(R)
    d = np.sign(np.linalg.det(U @ Vt))
    U = U.copy()
    U[..., :, 2] *= d[..., None]
    return U @ Vt
