import pytest
import torch

from dcslam.errors import DcslamError
from dcslam.geometry.camera import backproject, depth_to_points, pixel_grid, project
from dcslam.geometry.se3 import se3_exp

K = torch.tensor([[50.0, 0, 15.5], [0, 55.0, 11.5], [0, 0, 1]], dtype=torch.float64)


class TestBackproject:
    @pytest.mark.parametrize("batch", [1, 3])
    def test_projects_back_to_its_pixels(self, device, dtype, batch):
        depth = torch.rand(batch, 1, 24, 32, dtype=dtype, device=device) * 10 + 1
        vertex = backproject(depth, K.to(device, dtype))
        assert vertex.shape == (batch, 3, 24, 32) and vertex.device.type == device.type
        uv, z = project(vertex.permute(0, 2, 3, 1).reshape(batch, -1, 3), K.to(device, dtype))
        grid = pixel_grid(24, 32, dtype).to(device).reshape(2, -1).T.expand(batch, -1, -1)
        tol = 1e-3 if dtype == torch.float32 else 1e-9
        torch.testing.assert_close(uv, grid, atol=tol, rtol=0)
        torch.testing.assert_close(z, depth.reshape(batch, -1))

    def test_known_answer_and_zero_depth(self):
        depth = torch.zeros(1, 1, 24, 32, dtype=torch.float64)
        depth[0, 0, 11, 25] = 2.0
        vertex = backproject(depth, K)
        torch.testing.assert_close(vertex[0, :, 11, 25], torch.tensor([2.0 * 9.5 / 50, -2.0 * 0.5 / 55, 2.0],
                                                                        dtype=torch.float64))
        assert vertex.abs().sum() == vertex[0, :, 11, 25].abs().sum()

    def test_per_batch_intrinsics(self):
        depth = torch.ones(2, 1, 4, 5, dtype=torch.float64)
        Ks = torch.stack([K, K * torch.tensor([[2.0, 1, 1], [1, 2, 1], [1, 1, 1]], dtype=torch.float64)])
        vertex = backproject(depth, Ks)
        torch.testing.assert_close(vertex[1, :2], vertex[0, :2] / 2)

    def test_gradcheck(self):
        depth = (torch.rand(1, 1, 3, 4, dtype=torch.float64) + 1).requires_grad_()
        assert torch.autograd.gradcheck(backproject, (depth, K))
        points = (torch.rand(6, 3, dtype=torch.float64) + torch.tensor([0, 0, 1.0], dtype=torch.float64))
        assert torch.autograd.gradcheck(lambda p: project(p, K)[0], (points.requires_grad_(),))

    def test_shape_errors(self):
        with pytest.raises(DcslamError, match=r"\(B, 1, H, W\)"):
            backproject(torch.ones(2, 4, 5), K)
        with pytest.raises(DcslamError, match=r"\(3, 3\)"):
            backproject(torch.ones(1, 1, 4, 5), torch.eye(4))
        with pytest.raises(DcslamError, match="floating"):
            backproject(torch.ones(1, 1, 4, 5, dtype=torch.int64), K)
        with pytest.raises(DcslamError, match=r"\(N, 3\)"):
            project(torch.ones(4, 2), K)


def test_depth_to_points_in_world():
    depth = torch.zeros(24, 32, dtype=torch.float64)
    depth[5, 7] = 3.0
    depth[20, 30] = 4.0
    T = se3_exp(torch.tensor([1.0, 2.0, 3.0, 0.1, 0.2, 0.3], dtype=torch.float64))
    points_cam, index = depth_to_points(depth, K)
    points_world, index2 = depth_to_points(depth, K, T)
    assert points_cam.shape == (2, 3) and index.tolist() == [5 * 32 + 7, 20 * 32 + 30]
    torch.testing.assert_close(points_world, points_cam @ T[:3, :3].T + T[:3, 3])
