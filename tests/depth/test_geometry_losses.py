"""The geometry losses of dcslam.depth.losses: known answers, float64 gradcheck, and a few optimisation steps under
each loss reduce the surface metric it targets (dcslam.eval.surface)."""
import math

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from dcslam.depth.losses import edge_mixing_loss, normal_loss, point_to_plane_loss
from dcslam.errors import DcslamError
from dcslam.eval.surface import surface_errors

K = torch.tensor([[30.0, 0, 8], [0, 30.0, 6], [0, 0, 1]], dtype=torch.float64)
H, W = 12, 16
N1 = Rotation.from_euler("xy", [25, -15], degrees=True).apply([0.0, 0.0, -1.0])
P0 = np.array([0.2, -0.1, 8.0])


def plane(normal=N1, point=P0, dtype=torch.float64, K=K, shape=(H, W)):
    """Depth (1, 1, H, W) of the plane through ``point`` with ``normal`` (facing the camera)."""
    v, u = np.mgrid[:shape[0], :shape[1]].astype(np.float64)
    k = K.numpy()
    rays = np.stack([(u - k[0, 2]) / k[0, 0], (v - k[1, 2]) / k[1, 1], np.ones_like(u)], -1)
    return torch.as_tensor(np.dot(normal, point) / (rays @ normal), dtype=dtype)[None, None]


def tilted(degrees):
    axis = np.cross(N1, [1.0, 0.0, 0.0])
    return Rotation.from_rotvec(np.radians(degrees) * axis / np.linalg.norm(axis)).apply(N1)


def step(dtype=torch.float64, rows=6, columns=14, at=7):
    """Fronto-parallel planes at 5 m (columns < at) and 10 m, and their K."""
    depth = torch.full((1, 1, rows, columns), 10.0, dtype=dtype)
    depth[..., :at] = 5.0
    return depth, torch.tensor([[30.0, 0, columns / 2], [0, 30.0, rows / 2], [0, 0, 1]], dtype=torch.float64)


def metric(pred, reference, K):
    return surface_errors(pred.detach()[0, 0], reference[0, 0], K)


def optimise(loss, pred, steps, lr):
    pred = pred.clone().requires_grad_()
    optimiser = torch.optim.Adam([pred], lr=lr)
    for _ in range(steps):
        optimiser.zero_grad()
        loss(pred).backward()
        optimiser.step()
    return pred.detach()


class TestNormalLoss:
    def test_known_angle(self, dtype):
        for degrees in (0.0, 10.0, 30.0):
            loss = normal_loss(plane(tilted(degrees), dtype=dtype), plane(dtype=dtype), K)
            assert loss.dtype == dtype
            assert loss.item() == pytest.approx(1 - math.cos(math.radians(degrees)), abs=1e-5)

    def test_mask_and_holes(self):
        pred, ref = plane(tilted(20.0)), plane()
        ref[..., :, :4] = 0                               # no reference there: not scored
        mask = torch.ones_like(pred, dtype=torch.bool)
        mask[..., 6:, :] = False
        expected = 1 - math.cos(math.radians(20.0))
        assert normal_loss(pred, ref, K, mask).item() == pytest.approx(expected, abs=1e-6)
        assert normal_loss(pred, torch.zeros_like(ref), K).item() == 0

    def test_gradcheck_float64(self):
        noise = 0.02 * torch.randn(1, 1, H, W, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
        pred = (plane(tilted(5.0)) + noise).requires_grad_()
        assert torch.autograd.gradcheck(lambda p: normal_loss(p, plane(), K), (pred,))

    def test_steps_reduce_the_normal_error(self):
        ref = plane()
        noise = 0.04 * torch.randn(1, 1, H, W, dtype=torch.float64, generator=torch.Generator().manual_seed(2))
        start = plane(tilted(8.0)) + noise
        end = optimise(lambda p: normal_loss(p, ref, K), start, steps=30, lr=0.01)
        before, after = metric(start, ref, K).normal_mean_deg, metric(end, ref, K).normal_mean_deg
        assert after < 0.5 * before


class TestPointToPlaneLoss:
    def test_known_offset(self, dtype):
        delta = 0.3
        pred, ref = plane(point=P0 - delta * N1, dtype=dtype), plane(dtype=dtype)
        assert point_to_plane_loss(pred, ref, K).item() == pytest.approx(delta ** 2, rel=1e-4)
        assert point_to_plane_loss(ref, ref, K).item() == 0

    def test_gradcheck_float64(self):
        noise = 0.1 * torch.randn(1, 1, H, W, dtype=torch.float64, generator=torch.Generator().manual_seed(3))
        pred = (plane() + noise).requires_grad_()
        assert torch.autograd.gradcheck(lambda p: point_to_plane_loss(p, plane(), K), (pred,))

    def test_steps_reduce_the_point_to_plane_distance(self):
        ref = plane()
        noise = 0.2 * torch.randn(1, 1, H, W, dtype=torch.float64, generator=torch.Generator().manual_seed(4))
        start = plane(point=P0 - 0.5 * N1) + noise
        end = optimise(lambda p: point_to_plane_loss(p, ref, K), start, steps=20, lr=0.05)
        assert metric(end, ref, K).p2p_mean_m < 0.5 * metric(start, ref, K).p2p_mean_m


class TestEdgeMixingLoss:
    def test_known_mixing(self, dtype):
        ref, K_step = step(dtype)
        mixed = ref.clone()
        mixed[..., 5:9] = torch.tensor([6.0, 7.0, 8.0, 9.0], dtype=dtype)
        # columns 4..9 near the edge at 6 | 7: squared distances to the nearer side 0, 1, 4, 4, 1, 0
        assert edge_mixing_loss(mixed, ref, K_step).item() == pytest.approx(10 / 6, rel=1e-5)
        assert edge_mixing_loss(ref, ref, K_step).item() == 0
        shifted = ref.clone()
        shifted[..., 7] = 5.0                            # the edge a pixel off: on the other side's surface
        assert edge_mixing_loss(shifted, ref, K_step).item() == pytest.approx(0, abs=1e-12)

    def test_smooth_surface_has_no_edge_term(self):
        assert edge_mixing_loss(plane(tilted(10.0)), plane(), K).item() == 0

    def test_gradcheck_float64(self):
        ref, K_step = step()
        ref = ref + 0.05 * torch.randn(ref.shape, dtype=torch.float64, generator=torch.Generator().manual_seed(5))
        pred = ref.clone()
        pred[..., 5:9] += torch.tensor([1.2, 2.1, -2.3, -1.1], dtype=torch.float64)
        assert torch.autograd.gradcheck(lambda p: edge_mixing_loss(p, ref, K_step), (pred.requires_grad_(),))

    def test_steps_reduce_the_flying_share(self):
        ref, K_step = step()
        start = ref.clone()
        start[..., 5:9] = torch.tensor([6.0, 7.0, 8.0, 9.0], dtype=torch.float64)
        end = optimise(lambda p: edge_mixing_loss(p, ref, K_step), start, steps=60, lr=0.05)
        before, after = metric(start, ref, K_step).flying_share, metric(end, ref, K_step).flying_share
        assert before == pytest.approx(4 / 6) and after < 0.5 * before


def test_batches_and_shapes():
    pred = torch.cat([plane(tilted(10.0)), plane(tilted(20.0))])
    ref = torch.cat([plane(), plane()])
    mean = (2 - math.cos(math.radians(10.0)) - math.cos(math.radians(20.0))) / 2
    assert normal_loss(pred, ref, K).item() == pytest.approx(mean, abs=1e-6)
    with pytest.raises(DcslamError, match="expected \\(B, 1, H, W\\)"):
        point_to_plane_loss(pred[:, 0], ref[:, 0], K)
    with pytest.raises(DcslamError, match="shapes differ"):
        edge_mixing_loss(pred, ref[:1], K)
    with pytest.raises(DcslamError, match="mask"):
        normal_loss(pred, ref, K, mask=torch.ones_like(pred))
