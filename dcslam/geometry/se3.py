"""SE(3) and SO(3) helpers on 4 x 4 matrices and 6-vectors, small-angle safe and differentiable.

Conventions: ``T_a_b`` maps coordinates in frame b to frame a (``p_a = T_a_b @ p_b``). A twist ``xi`` is
``(v, w)``: translation part first, rotation part (axis-angle) last, and ``exp(xi)`` is the 4 x 4 matrix
``[[R, V v], [0, 1]]``. The pose solvers (:mod:`dcslam.slam.solvers`) apply updates on the right,
``T_world_cam <- T_world_cam @ exp(xi)``, so ``xi`` is a motion expressed in the camera's own frame.
"""
from __future__ import annotations

import torch

from dcslam.errors import DcslamError

# Below this squared angle the Taylor expansions are used (exact to float64 rounding there).
_SMALL = 1e-8


def _check(x: torch.Tensor, tail: tuple[int, ...], name: str) -> None:
    if not isinstance(x, torch.Tensor):
        raise DcslamError(f"{name} must be a torch.Tensor, got {type(x).__name__}")
    if tuple(x.shape[-len(tail):]) != tail or x.ndim < len(tail):
        raise DcslamError(f"{name} has shape {tuple(x.shape)}, expected (..., {', '.join(map(str, tail))})")


def skew(v: torch.Tensor) -> torch.Tensor:
    """Cross-product matrix: ``skew(v) @ u == cross(v, u)``.

    Shape: v (..., 3) -> (..., 3, 3).
    """
    _check(v, (3,), "v")
    x, y, z = v.unbind(-1)
    o = torch.zeros_like(x)
    return torch.stack([o, -z, y, z, o, -x, -y, x, o], -1).unflatten(-1, (3, 3))   # one stack, not four


def _coefficients(theta2: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """A = sin t / t, B = (1 - cos t) / t^2, C = (t - sin t) / t^3, with Taylor series near t = 0."""
    if theta2.ndim == 0 and theta2.device.type == "cpu" and not theta2.requires_grad:
        # one angle (a solver's step, dozens a frame): only the branch it takes, by the same operations as below,
        # so the same values in a third of the calls (tensors of one element cost their calls, not their sums);
        # with a graph, the one below (its gradients summed in its own order)
        if bool(theta2 < _SMALL):
            return (1 - theta2 / 6 + theta2 ** 2 / 120, 0.5 - theta2 / 24 + theta2 ** 2 / 720,
                    1.0 / 6 - theta2 / 120 + theta2 ** 2 / 5040)
        t = torch.sqrt(theta2)
        sin = torch.sin(t)
        return sin / t, (1 - torch.cos(t)) / theta2, (t - sin) / (theta2 * t)
    small = theta2 < _SMALL
    t2 = torch.where(small, torch.ones_like(theta2), theta2)
    t = torch.sqrt(t2)
    A = torch.where(small, 1 - theta2 / 6 + theta2 ** 2 / 120, torch.sin(t) / t)
    B = torch.where(small, 0.5 - theta2 / 24 + theta2 ** 2 / 720, (1 - torch.cos(t)) / t2)
    C = torch.where(small, 1.0 / 6 - theta2 / 120 + theta2 ** 2 / 5040, (t - torch.sin(t)) / (t2 * t))
    return A, B, C


def so3_exp(w: torch.Tensor) -> torch.Tensor:
    """Rodrigues' formula: axis-angle vectors to rotation matrices.

    Shape: w (..., 3) -> (..., 3, 3).
    """
    _check(w, (3,), "w")
    A, B, _ = _coefficients((w * w).sum(-1))
    W = skew(w)
    eye = torch.eye(3, dtype=w.dtype, device=w.device).expand(W.shape)
    return eye + A[..., None, None] * W + B[..., None, None] * (W @ W)


def so3_log(R: torch.Tensor) -> torch.Tensor:
    """Rotation matrices to axis-angle vectors (angle in [0, pi]); safe near 0 and near pi.

    Shape: R (..., 3, 3) -> (..., 3).
    """
    _check(R, (3, 3), "R")
    trace = R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2]
    cos = ((trace - 1) / 2).clamp(-1.0, 1.0)
    vee = torch.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    near_zero = cos > 1 - 1e-6
    near_pi = cos < -1 + 1e-4
    safe_cos = torch.where(near_zero | near_pi, torch.zeros_like(cos), cos)
    theta = torch.acos(safe_cos)
    generic = vee * (theta / (2 * torch.sin(theta)))[..., None]
    # 1 - cos ~ t^2 / 2, so t / (2 sin t) ~ (1 + t^2 / 6) / 2 with t^2 ~ 2 (1 - cos).
    small = vee * (0.5 + (1 - cos) / 6)[..., None]
    # Near pi: the symmetric part is cos I + (1 - cos) a a^T; take the axis from its largest diagonal entry.
    eye = torch.eye(3, dtype=R.dtype, device=R.device)
    B = ((R + R.transpose(-1, -2)) / 2 - cos[..., None, None] * eye) / (1 - cos).clamp_min(1e-12)[..., None, None]
    diag = torch.diagonal(B, dim1=-2, dim2=-1)
    k = diag.argmax(-1, keepdim=True)
    col = torch.gather(B, -1, k[..., None, :].expand(*B.shape[:-1], 1)).squeeze(-1)
    axis = col / col.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    axis = torch.where((axis * vee).sum(-1, keepdim=True) < 0, -axis, axis)
    theta_pi = torch.acos(cos.clamp(-1.0, 1 - 1e-12))
    at_pi = axis * theta_pi[..., None]
    return torch.where(near_zero[..., None], small, torch.where(near_pi[..., None], at_pi, generic))


def se3_exp(xi: torch.Tensor) -> torch.Tensor:
    """Twists ``(v, w)`` to 4 x 4 rigid transforms.

    Shape: xi (..., 6) -> (..., 4, 4).
    """
    _check(xi, (6,), "xi")
    v, w = xi[..., :3], xi[..., 3:]
    A, B, C = _coefficients((w * w).sum(-1))
    W = skew(w)
    WW = W @ W
    eye = torch.eye(3, dtype=xi.dtype, device=xi.device).expand(W.shape)
    R = eye + A[..., None, None] * W + B[..., None, None] * WW
    V = eye + B[..., None, None] * W + C[..., None, None] * WW
    t = (V @ v[..., None])[..., 0]
    return from_rotation_translation(R, t)


def se3_log(T: torch.Tensor) -> torch.Tensor:
    """4 x 4 rigid transforms to twists ``(v, w)``; the inverse of :func:`se3_exp` for angles below pi.

    Shape: T (..., 4, 4) -> (..., 6).
    """
    _check(T, (4, 4), "T")
    w = so3_log(T[..., :3, :3])
    theta2 = (w * w).sum(-1)
    small = theta2 < _SMALL
    t2 = torch.where(small, torch.ones_like(theta2), theta2)
    t = torch.sqrt(t2)
    # V^-1 = I - W / 2 + D W^2 with D = (1 - A / (2 B)) / t^2.
    D = torch.where(small, 1.0 / 12 + theta2 / 720, (1 - (t * torch.sin(t)) / (2 * (1 - torch.cos(t)))) / t2)
    W = skew(w)
    eye = torch.eye(3, dtype=T.dtype, device=T.device).expand(W.shape)
    V_inv = eye - W / 2 + D[..., None, None] * (W @ W)
    v = (V_inv @ T[..., :3, 3:4])[..., 0]
    return torch.cat([v, w], -1)


def from_rotation_translation(R: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """Assemble 4 x 4 transforms. Shape: R (..., 3, 3), t (..., 3) -> (..., 4, 4)."""
    _check(R, (3, 3), "R")
    _check(t, (3,), "t")
    top = torch.cat([R, t[..., None]], -1)
    bottom = torch.zeros(*top.shape[:-2], 1, 4, dtype=R.dtype, device=R.device)
    bottom[..., 0, 3] = 1
    return torch.cat([top, bottom], -2)


def inverse(T: torch.Tensor) -> torch.Tensor:
    """Inverse of rigid transforms (``T_b_a`` from ``T_a_b``). Shape: (..., 4, 4) -> (..., 4, 4)."""
    _check(T, (4, 4), "T")
    Rt = T[..., :3, :3].transpose(-1, -2)
    return from_rotation_translation(Rt, -(Rt @ T[..., :3, 3:4])[..., 0])


def compose(T_a_b: torch.Tensor, T_b_c: torch.Tensor) -> torch.Tensor:
    """``T_a_c = T_a_b @ T_b_c`` with shape checks. Shape: (..., 4, 4), (..., 4, 4) -> (..., 4, 4)."""
    _check(T_a_b, (4, 4), "T_a_b")
    _check(T_b_c, (4, 4), "T_b_c")
    return T_a_b @ T_b_c


def transform_points(T_a_b: torch.Tensor, points_b: torch.Tensor) -> torch.Tensor:
    """Map points from frame b to frame a.

    Shape: T_a_b (4, 4) or (B, 4, 4); points_b (..., N, 3) with matching batch -> (..., N, 3).
    """
    _check(T_a_b, (4, 4), "T_a_b")
    _check(points_b, (3,), "points_b")
    R, t = T_a_b[..., :3, :3], T_a_b[..., :3, 3]
    return rows_times(points_b, R.transpose(-1, -2)) + t[..., None, :]


def rotate(T_a_b: torch.Tensor, vectors_b: torch.Tensor) -> torch.Tensor:
    """Rotate direction vectors (normals) from frame b to frame a. Shape as :func:`transform_points`."""
    _check(T_a_b, (4, 4), "T_a_b")
    _check(vectors_b, (3,), "vectors_b")
    return rows_times(vectors_b, T_a_b[..., :3, :3].transpose(-1, -2))


#: Rows from which :func:`rows_times` takes its fast path (an AVX-512 Xeon gave other bits up to 10 rows in float32)
FAST_ROWS = 64


def rows_times(points: torch.Tensor, M: torch.Tensor) -> torch.Tensor:
    """``points @ M`` for (N, 3) rows and a 3 x 3 matrix (any other shapes: plain ``@``).

    On the CPU, outside autograd, for at least :data:`FAST_ROWS` rows, the matrix is made contiguous first: the same
    products summed in the same order (the same bits, checked in the tests), 1.3-1.6 times faster for the 10^4-10^5
    points of a SLAM step than the strided slice of a pose. Below that the plain product is kept: on AVX-512 hosts a
    handful of rows times a strided matrix takes another kernel, whose bits differ. Where a gradient is needed the
    plain product is kept too, so that backward passes, whose sums over the points depend on the layout, stay as they
    were. Shape: points (..., N, 3), M (..., 3, 3).
    """
    if (points.ndim == 2 and M.ndim == 2 and points.device.type == "cpu" and points.shape[0] >= FAST_ROWS
            and not (torch.is_grad_enabled() and (points.requires_grad or M.requires_grad))):
        from dcslam.native import rows_times as native_rows_times

        native = native_rows_times(points, M)      # torch.mm's sums in one pass (dcslam.native), where it applies
        return torch.mm(points, M.contiguous()) if native is None else native
    return points @ M


def pose_error(T_a: torch.Tensor, T_b: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Translation (same unit as the poses) and rotation angle (radians) of ``T_a^-1 T_b``, in ``T_a``'s dtype:
    :func:`dcslam.geometry.motion.relative_motion` (float64 inside, exact near 0 and pi).

    Shape: (..., 4, 4), (..., 4, 4) -> ((...), (...)).
    """
    from dcslam.geometry.motion import relative_motion

    _check(T_a, (4, 4), "T_a")
    _check(T_b, (4, 4), "T_b")
    metres, radians = relative_motion(T_a, T_b)
    return metres.to(T_a.dtype), radians.to(T_a.dtype)
