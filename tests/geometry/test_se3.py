import math

import pytest
import torch

from dcslam.errors import DcslamError
from dcslam.geometry.se3 import (compose, from_rotation_translation, inverse, pose_error, rotate, rows_times, se3_exp,
                                 se3_log, skew, so3_exp, so3_log, transform_points)

TOL = {torch.float32: dict(atol=1e-5, rtol=1e-5), torch.float64: dict(atol=1e-10, rtol=1e-10)}


def _random_twists(n, dtype, scale=1.0, seed=0):
    g = torch.Generator().manual_seed(seed)
    return torch.randn(n, 6, generator=g, dtype=dtype) * scale


class TestSkew:
    def test_cross_product(self):
        v, u = torch.randn(5, 3), torch.randn(5, 3)
        torch.testing.assert_close((skew(v) @ u[..., None])[..., 0], torch.cross(v, u, dim=-1))

    def test_shape_error(self):
        with pytest.raises(DcslamError, match=r"\(\.\.\., 3\)"):
            skew(torch.zeros(2, 4))


class TestSO3:
    def test_exp_is_rotation_and_log_inverts(self, device, dtype):
        w = _random_twists(20, dtype)[:, 3:].to(device)
        w = w / w.norm(dim=1, keepdim=True) * torch.linspace(0, 3.0, 20, dtype=dtype, device=device)[:, None]
        R = so3_exp(w)
        assert R.device.type == device.type and R.dtype == dtype
        eye = torch.eye(3, dtype=dtype, device=device).expand(20, 3, 3)
        torch.testing.assert_close(R @ R.transpose(-1, -2), eye, **TOL[dtype])
        torch.testing.assert_close(torch.linalg.det(R), torch.ones(20, dtype=dtype, device=device), **TOL[dtype])
        tol = dict(atol=1e-4, rtol=1e-4) if dtype == torch.float32 else TOL[dtype]
        torch.testing.assert_close(so3_log(R), w, **tol)

    def test_known_rotation(self):
        R = so3_exp(torch.tensor([0.0, 0.0, math.pi / 2], dtype=torch.float64))
        torch.testing.assert_close(R @ torch.tensor([1.0, 0, 0], dtype=torch.float64),
                                   torch.tensor([0.0, 1, 0], dtype=torch.float64))

    @pytest.mark.parametrize("angle", [0.0, 1e-9, 1e-5])
    def test_small_angles_are_finite_and_exact(self, angle):
        w = torch.tensor([angle, -angle, angle / 2], dtype=torch.float64)
        R = so3_exp(w)
        assert torch.isfinite(R).all()
        torch.testing.assert_close(so3_log(R), w, atol=1e-15, rtol=1e-6)

    def test_near_pi(self):
        axis = torch.tensor([1.0, 2.0, -0.5], dtype=torch.float64)
        axis = axis / axis.norm()
        for angle in (math.pi - 1e-3, math.pi - 1e-7, math.pi):
            w = so3_log(so3_exp(axis * angle))
            assert torch.isfinite(w).all()
            torch.testing.assert_close(so3_exp(w), so3_exp(axis * angle), atol=1e-6, rtol=0)

    def test_gradcheck(self):
        w = (torch.randn(4, 3, dtype=torch.float64) * 0.7).requires_grad_()
        assert torch.autograd.gradcheck(so3_exp, (w,))
        R = so3_exp(w.detach()).requires_grad_()
        assert torch.autograd.gradcheck(so3_log, (R,))

    def test_gradcheck_at_zero(self):
        w = torch.zeros(1, 3, dtype=torch.float64, requires_grad=True)
        assert torch.autograd.gradcheck(so3_exp, (w,))


class TestSE3:
    @pytest.mark.parametrize("batch", [(), (1,), (7,), (2, 3)])
    def test_exp_log_round_trip(self, device, dtype, batch):
        xi = _random_twists(max(1, math.prod(batch)), dtype, 0.8).reshape(*batch, 6).to(device)
        T = se3_exp(xi)
        assert T.shape == (*batch, 4, 4) and T.device.type == device.type and T.dtype == dtype
        tol = dict(atol=1e-4, rtol=1e-4) if dtype == torch.float32 else TOL[dtype]
        torch.testing.assert_close(se3_log(T), xi, **tol)

    def test_inverse_and_compose(self):
        T = se3_exp(_random_twists(5, torch.float64))
        eye = torch.eye(4, dtype=torch.float64).expand(5, 4, 4)
        torch.testing.assert_close(compose(T, inverse(T)), eye)
        torch.testing.assert_close(inverse(T), torch.linalg.inv(T))

    def test_transform_points(self):
        T = se3_exp(_random_twists(1, torch.float64))[0]
        p = torch.randn(10, 3, dtype=torch.float64)
        expected = (T @ torch.cat([p, torch.ones(10, 1, dtype=torch.float64)], 1).T).T[:, :3]
        torch.testing.assert_close(transform_points(T, p), expected)
        torch.testing.assert_close(rotate(T, p), p @ T[:3, :3].T)
        torch.testing.assert_close(transform_points(inverse(T), transform_points(T, p)), p)

    @pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
    @pytest.mark.parametrize("n", [0, 1, 7, 4099, 40000])
    def test_rows_times_gives_the_bits_of_the_plain_product(self, dtype, n):
        """The fast path (a contiguous matrix, outside autograd) must not change a pose by one bit: SLAM's
        tables rest on bit-identical runs."""
        torch.manual_seed(n)
        T = se3_exp(_random_twists(1, torch.float64))[0].to(dtype)
        T[:3, 3] *= 100
        p = (torch.randn(n, 3, dtype=dtype) * 30).contiguous()
        for M in (T[:3, :3], T[:3, :3].transpose(-1, -2)):         # strided slices of a pose
            assert torch.equal(rows_times(p, M), p @ M)
        assert torch.equal(transform_points(T, p), p @ T[:3, :3].transpose(-1, -2) + T[:3, 3])
        assert torch.equal(rotate(T, p), p @ T[:3, :3].transpose(-1, -2))

    def test_rows_times_keeps_the_graph(self):
        T = se3_exp(_random_twists(1, torch.float64))[0].requires_grad_()
        p = torch.randn(6, 3, dtype=torch.float64, requires_grad=True)
        assert rows_times(p, T[:3, :3]).requires_grad
        assert torch.autograd.gradcheck(rows_times, (p, T[:3, :3]))
        with torch.no_grad():
            assert torch.equal(rows_times(p, T[:3, :3]), p @ T[:3, :3])

    def test_pose_error(self):
        T = from_rotation_translation(so3_exp(torch.tensor([0.0, 0.1, 0.0], dtype=torch.float64)),
                                      torch.tensor([3.0, 4.0, 0.0], dtype=torch.float64))
        dt, dr = pose_error(torch.eye(4, dtype=torch.float64), T)
        assert float(dt) == pytest.approx(5.0) and float(dr) == pytest.approx(0.1)

    def test_gradcheck(self):
        xi = (_random_twists(3, torch.float64, 0.5)).requires_grad_()
        assert torch.autograd.gradcheck(se3_exp, (xi,))
        T = se3_exp(xi.detach()).requires_grad_()
        assert torch.autograd.gradcheck(se3_log, (T,))
        assert torch.autograd.gradcheck(inverse, (T,))
        p = torch.randn(5, 3, dtype=torch.float64, requires_grad=True)
        assert torch.autograd.gradcheck(transform_points, (T[0], p))

    def test_gradcheck_at_identity(self):
        xi = torch.zeros(6, dtype=torch.float64, requires_grad=True)
        assert torch.autograd.gradcheck(se3_exp, (xi,))

    def test_shape_errors(self):
        with pytest.raises(DcslamError, match=r"\(\.\.\., 6\)"):
            se3_exp(torch.zeros(3))
        with pytest.raises(DcslamError, match=r"\(\.\.\., 4, 4\)"):
            inverse(torch.zeros(3, 3))
        with pytest.raises(DcslamError, match="torch.Tensor"):
            se3_log([[1.0]])


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_one_angle_takes_one_branch_with_the_same_values(dtype):
    """The coefficients of one angle (a solver's step) come from the branch it takes alone: the values of the
    batched form, which computes both and selects, bit for bit, on both sides of the Taylor switch."""
    from dcslam.geometry.se3 import _SMALL, _coefficients

    theta2 = torch.tensor([0.0, 1e-12, _SMALL / 2, _SMALL, 2 * _SMALL, 1e-6, 0.3, 2.0, 9.0], dtype=dtype)
    batched = _coefficients(theta2)
    for k, value in enumerate(theta2):
        for one, many in zip(_coefficients(value), batched):
            assert one.shape == () and torch.equal(one, many[k]), (float(value), float(one), float(many[k]))
