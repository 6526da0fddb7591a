"""Chamfer distance between two point clouds, as the thesis defines it, differentiable.

    chamfer(A, B) = mean_{a in A} min_{b in B} ||a − b||²  +  mean_{b in B} min_{a in A} ||b − a||²

and its point-to-plane form against a reference cloud B with unit normals n (the same nearest neighbours, each
distance measured along the normal of the pair's point of B, the residual ICP minimises):

    plane_chamfer(A, B) = mean_{a in A} (n_b(a) · (a − b(a)))²  +  mean_{b in B} (n_b · (b − a(b)))²

Nearest neighbours are found without gradient by the exact search of :mod:`dcslam.geometry.nearest`; the squared
distances are then recomputed in torch from the matched pairs, so the gradient flows to both clouds (the
nearest-neighbour assignment is piecewise constant, so this is the exact gradient almost everywhere).
"""
from __future__ import annotations

import torch

from dcslam.errors import DcslamError
from dcslam.geometry.nearest import nearest_indices, squared_distances


def _check_cloud(points: torch.Tensor, name: str) -> None:
    if not isinstance(points, torch.Tensor) or points.ndim != 2 or points.shape[1] != 3:
        shape = tuple(points.shape) if hasattr(points, "shape") else type(points).__name__
        raise DcslamError(f"{name} has shape {shape}, expected (P, 3)")
    if points.shape[0] == 0:
        raise DcslamError(f"{name} is empty; the chamfer distance needs at least one point in each cloud")


def nearest_neighbours(a: torch.Tensor, b: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Exact nearest neighbours both ways, without gradient.

    Shape:
        a: (P, 3), b: (Q, 3) → index into b of each point of a (P,) int64, index into a of each point of b (Q,) int64
    """
    _check_cloud(a, "a")
    _check_cloud(b, "b")
    idx_ab, idx_ba = nearest_indices(a.detach().to("cpu", torch.float64).numpy(),
                                     b.detach().to("cpu", torch.float64).numpy())
    return torch.from_numpy(idx_ab).to(a.device), torch.from_numpy(idx_ba).to(b.device)


def chamfer_distance(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Symmetric chamfer distance (squared distances, mean over each cloud, both directions), differentiable.

    Shape:
        a: (P, 3), b: (Q, 3), same dtype and device → scalar (units of the points, squared)
    """
    idx_ab, idx_ba = nearest_neighbours(a, b)
    if a.dtype != b.dtype:
        raise DcslamError(f"clouds have different dtypes {a.dtype} and {b.dtype}")
    return squared_distances(a, b, idx_ab).mean() + squared_distances(b, a, idx_ba).mean()


def plane_chamfer_distance(a: torch.Tensor, b: torch.Tensor, b_normals: torch.Tensor) -> torch.Tensor:
    """Symmetric point-to-plane chamfer distance (the module docstring) of cloud ``a`` against reference cloud ``b``
    with unit normals ``b_normals``, differentiable: a point of ``a`` that slides along the reference surface costs
    nothing (the point form charges it for the spacing of ``b``'s samples).

    Shape:
        a: (P, 3), b: (Q, 3), b_normals: (Q, 3), same dtype and device → scalar (units of the points, squared)
    """
    idx_ab, idx_ba = nearest_neighbours(a, b)
    if a.dtype != b.dtype or b_normals.dtype != b.dtype:
        raise DcslamError(f"clouds and normals have different dtypes {a.dtype}, {b.dtype}, {b_normals.dtype}")
    if b_normals.shape != b.shape:
        raise DcslamError(f"normals have shape {tuple(b_normals.shape)}, expected {tuple(b.shape)}")
    n_ab = b_normals.index_select(0, idx_ab)
    a_to_b = ((a - b.index_select(0, idx_ab)) * n_ab).sum(-1)
    b_to_a = ((b - a.index_select(0, idx_ba)) * b_normals).sum(-1)
    return (a_to_b * a_to_b).mean() + (b_to_a * b_to_a).mean()
