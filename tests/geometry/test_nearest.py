"""Exact nearest neighbours both ways, and the squared distances to them in NumPy and torch alike."""
import numpy as np
import torch

from dcslam.geometry.nearest import nearest_indices, squared_distances


def test_exact_against_brute_force_with_outliers():
    rng = np.random.default_rng(5)
    a = np.concatenate([rng.random((2000, 3)), 30 + rng.random((10, 3))])  # outliers beyond the sampled bound
    b = np.concatenate([rng.random((1500, 3)), -20 - rng.random((7, 3))])
    ia, ib = nearest_indices(a, b)
    d = np.linalg.norm(a[:, None] - b[None], axis=2)
    assert ia.dtype == ib.dtype == np.int64 and ia.shape == (2010,) and ib.shape == (1507,)
    np.testing.assert_array_equal(d[np.arange(len(a)), ia], d.min(axis=1))
    np.testing.assert_array_equal(d[ib, np.arange(len(b))], d.min(axis=0))


def test_single_points_and_duplicates():
    a = np.zeros((1, 3))
    b = np.array([[1.0, 0, 0], [0, 2.0, 0], [1.0, 0, 0]])
    ia, ib = nearest_indices(a, b)
    assert b[ia[0]].tolist() == [1.0, 0, 0] and ib.tolist() == [0, 0, 0]


def test_squared_distances_numpy_and_torch_agree(device, dtype):
    a = np.array([[0.0, 0, 0], [1, 1, 1]])
    b = np.array([[0.0, 3, 4], [1, 1, 2]])
    index = np.array([0, 1])
    assert squared_distances(a, b, index).tolist() == [25.0, 1.0]
    ta, tb = (torch.as_tensor(x, dtype=dtype, device=device) for x in (a, b))
    out = squared_distances(ta, tb, torch.as_tensor(index, device=device))
    assert out.dtype == dtype and out.device.type == device.type and out.tolist() == [25.0, 1.0]


def test_squared_distances_gradcheck_float64():
    g = torch.Generator().manual_seed(0)
    a = torch.rand(6, 3, generator=g, dtype=torch.float64, requires_grad=True)
    b = torch.rand(4, 3, generator=g, dtype=torch.float64, requires_grad=True)
    index = torch.tensor([0, 3, 3, 1, 2, 0])
    assert torch.autograd.gradcheck(lambda x, y: squared_distances(x, y, index), (a, b))
