import pytest
import torch

from dcslam.depth.chamfer import chamfer_distance, nearest_neighbours, plane_chamfer_distance
from dcslam.errors import DcslamError


def brute_force(a, b):
    d = torch.cdist(a, b).square()
    return d.min(dim=1).values.mean() + d.min(dim=0).values.mean()


class TestChamfer:
    @pytest.mark.parametrize("p,q", [(1, 1), (50, 80), (300, 200)])
    def test_matches_brute_force_values_and_gradients(self, p, q):
        g = torch.Generator().manual_seed(p + q)
        a = torch.rand(p, 3, generator=g, dtype=torch.float64).requires_grad_()
        b = torch.rand(q, 3, generator=g, dtype=torch.float64).requires_grad_()
        ours = chamfer_distance(a, b)
        ref = brute_force(a, b)
        assert ours.item() == pytest.approx(ref.item(), rel=1e-12)
        ga, gb = torch.autograd.grad(ours, (a, b))
        ra, rb = torch.autograd.grad(ref, (a, b))
        assert torch.allclose(ga, ra) and torch.allclose(gb, rb)

    def test_gradcheck_float64(self):
        g = torch.Generator().manual_seed(1)
        a = torch.rand(30, 3, generator=g, dtype=torch.float64, requires_grad=True)
        b = torch.rand(25, 3, generator=g, dtype=torch.float64, requires_grad=True)
        assert torch.autograd.gradcheck(chamfer_distance, (a, b), eps=1e-7)

    def test_identical_clouds_zero_and_symmetric(self, device, dtype):
        a = torch.rand(100, 3, device=device, dtype=dtype)
        assert chamfer_distance(a, a.clone()).item() == 0
        b = torch.rand(70, 3, device=device, dtype=dtype)
        assert chamfer_distance(a, b).item() == pytest.approx(chamfer_distance(b, a).item())

    def test_known_answer_shift(self, device, dtype):
        a = torch.tensor([[0.0, 0, 0], [10.0, 0, 0]], device=device, dtype=dtype)
        b = a + torch.tensor([0.0, 0.5, 0], device=device, dtype=dtype)
        distance = chamfer_distance(a, b)
        assert distance.device.type == device.type and distance.dtype == dtype
        assert distance.item() == pytest.approx(0.5)  # 0.25 each way

    def test_nearest_neighbours_exact(self):
        a, b = torch.rand(500, 3), torch.rand(400, 3)
        ia, ib = nearest_neighbours(a, b)
        d = torch.cdist(a.double(), b.double())
        assert torch.equal(ia, d.argmin(dim=1)) and torch.equal(ib, d.argmin(dim=0))

    def test_exact_beyond_the_search_bound(self):
        # A dense cloud plus far outliers: the sampled search bound is small, so the outliers' neighbours (and the
        # neighbours of the points they are nearest to) are found only by the second, unbounded search.
        g = torch.Generator().manual_seed(3)
        a = torch.cat([torch.rand(3000, 3, generator=g), 50 + 10 * torch.rand(20, 3, generator=g)]).double()
        b = torch.cat([torch.rand(2500, 3, generator=g), -40 - 5 * torch.rand(15, 3, generator=g)]).double()
        ia, ib = nearest_neighbours(a, b)
        d = torch.cdist(a, b)
        assert torch.allclose(d.gather(1, ia[:, None])[:, 0], d.min(dim=1).values)
        assert torch.allclose(d.gather(0, ib[None])[0], d.min(dim=0).values)
        assert chamfer_distance(a, b).item() == pytest.approx(brute_force(a, b).item(), rel=1e-12)

    def test_bad_input(self):
        with pytest.raises(DcslamError):
            chamfer_distance(torch.rand(5, 2), torch.rand(5, 3))
        with pytest.raises(DcslamError):
            chamfer_distance(torch.rand(0, 3), torch.rand(5, 3))


class TestPlaneChamfer:
    def test_known_answer_and_sliding_costs_nothing(self, dtype):
        # a grid on the plane z = 0 (normals +z): moved along the plane it costs nothing, moved off it by 0.5 m it
        # costs 0.25 m² each way (the point form charges both)
        u, v = torch.meshgrid(torch.arange(5, dtype=dtype), torch.arange(4, dtype=dtype), indexing="ij")
        b = torch.stack([u.flatten(), v.flatten(), torch.zeros(20, dtype=dtype)], 1)
        n = torch.tensor([0.0, 0, 1], dtype=dtype).expand(20, 3)
        slid = b + torch.tensor([0.3, 0.2, 0], dtype=dtype)
        assert plane_chamfer_distance(slid, b, n).item() == pytest.approx(0, abs=1e-12)
        assert chamfer_distance(slid, b).item() > 0.1
        lifted = b + torch.tensor([0.0, 0, 0.5], dtype=dtype)
        assert plane_chamfer_distance(lifted, b, n).item() == pytest.approx(0.5)

    def test_gradcheck_float64(self):
        g = torch.Generator().manual_seed(2)
        a = torch.rand(30, 3, generator=g, dtype=torch.float64, requires_grad=True)
        b = torch.rand(25, 3, generator=g, dtype=torch.float64, requires_grad=True)
        n = torch.nn.functional.normalize(torch.randn(25, 3, generator=g, dtype=torch.float64), dim=1)
        assert torch.autograd.gradcheck(plane_chamfer_distance, (a, b, n.requires_grad_()), eps=1e-7)

    def test_bad_normals(self):
        with pytest.raises(DcslamError, match="normals have shape"):
            plane_chamfer_distance(torch.rand(5, 3), torch.rand(4, 3), torch.rand(3, 3))
