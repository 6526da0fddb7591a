"""Chamfer distance between two point clouds, as the thesis defines it, differentiable.

    chamfer(A, B) = mean_{a in A} min_{b in B} ||a − b||²  +  mean_{b in B} min_{a in A} ||b − a||²

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
