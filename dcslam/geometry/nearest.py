"""Exact nearest neighbours between two point clouds, both ways, and the squared distances to them: the one
implementation behind the training loss (:mod:`dcslam.depth.chamfer`, torch, differentiable) and the map score
(:mod:`dcslam.eval.maps`, NumPy).

Neighbours are found by an exact k-d tree search (SciPy ``cKDTree``, all cores). Each tree is built once per cloud
(unbalanced, non-compact nodes: a faster build, the same exact answers), the two builds run in parallel threads, and
each cloud queries the other's tree in its *own* tree's leaf order, which is spatially coherent and several times
faster than querying in arbitrary order. The search is bounded by a distance estimated from a sample, which prunes
most of the tree; points beyond it are searched again without a bound, so the answer stays exact. See
``benchmarks/bench_depth.py`` for the speed against a plain cKDTree query.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np


def _build_tree(points: np.ndarray):
    from scipy.spatial import cKDTree

    return cKDTree(points, balanced_tree=False, compact_nodes=False)


def _search_radius(tree, points: np.ndarray, sample: int = 2048, quantile: float = 0.95) -> float:
    """A distance bound that most nearest neighbours lie within: 1.5 × the 95th percentile of the exact distances of
    an evenly spread sample. A bounded search prunes far more of the tree; the few points beyond it are searched
    again without a bound, so the result is exact whatever the bound."""
    step = max(1, len(points) // sample)
    distance = tree.query(points[::step], k=1)[0]
    bound = 1.5 * float(np.quantile(distance, quantile))
    return bound if bound > 0 else np.inf


def _query(tree, own_tree, points: np.ndarray) -> np.ndarray:
    order = own_tree.indices  # the query cloud's own leaf order: spatially coherent queries
    ordered = points[order]
    bound = _search_radius(tree, ordered)
    distance, found = tree.query(ordered, k=1, workers=-1, distance_upper_bound=bound)
    missed = np.flatnonzero(np.isinf(distance))
    if missed.size:  # farther than the bound: search those again without one, so the answer stays exact
        found[missed] = tree.query(ordered[missed], k=1, workers=-1)[1]
    index = np.empty(len(points), np.int64)
    index[order] = found
    return index


def nearest_indices(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact nearest neighbours both ways.

    Shape:
        a: (P, 3), b: (Q, 3) float64, neither empty → index into b of each point of a (P,) int64, index into a of
        each point of b (Q,) int64
    """
    with ThreadPoolExecutor(max_workers=2) as pool:
        tree_a, tree_b = pool.map(_build_tree, (a, b))
    return _query(tree_b, tree_a, a), _query(tree_a, tree_b, b)


def squared_distances(a, b, index):
    """Squared distance from each point of ``a`` to the point of ``b`` that ``index`` picks, for NumPy arrays and
    torch tensors alike (in torch the gradient flows to both clouds).

    Shape: a (P, 3), b (Q, 3), index (P,) into b → (P,)
    """
    matched = b.index_select(0, index.to(b.device)) if hasattr(b, "index_select") else b[index]
    return ((a - matched) ** 2).sum(-1)
