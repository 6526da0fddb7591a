"""A negative fy (ICL-NUIM: the camera's y axis points up): back-projection, projection and normals."""
import pytest
import torch

from dcslam.geometry.camera import backproject, pixel_grid, project
from dcslam.geometry.normals import vertex_normals

H, W = 24, 32


def K_of(fy: float) -> torch.Tensor:
    return torch.tensor([[30.0, 0, 15.5], [0, fy, 11.5], [0, 0, 1]], dtype=torch.float64)


def plane_depth(K: torch.Tensor, n: torch.Tensor, d: float) -> torch.Tensor:
    """Exact depth (1, 1, H, W) of the plane n . X = d seen through K."""
    uv = pixel_grid(H, W, torch.float64)
    rays = torch.stack([(uv[0] - K[0, 2]) / K[0, 0], (uv[1] - K[1, 2]) / K[1, 1], torch.ones_like(uv[0])])
    return (d / torch.einsum("i,ihw->hw", n, rays))[None, None]


def test_backprojection_mirrors_y_and_projects_back():
    depth = torch.rand(1, 1, H, W, dtype=torch.float64) * 4 + 0.5
    up, down = backproject(depth, K_of(-28.0)), backproject(depth, K_of(28.0))
    torch.testing.assert_close(up, down * torch.tensor([1.0, -1.0, 1.0], dtype=torch.float64).view(1, 3, 1, 1))
    assert bool((up[0, 1, :5] > 0).all())  # rows above the centre: y up
    uv, z = project(up[0].reshape(3, -1).T, K_of(-28.0))
    torch.testing.assert_close(uv, pixel_grid(H, W, torch.float64).reshape(2, -1).T)
    torch.testing.assert_close(z, depth.reshape(-1))


@pytest.mark.parametrize("fy", [28.0, -28.0])
def test_normals_of_a_plane_face_the_camera(fy):
    n_plane = torch.tensor([0.3, -0.4, -0.8], dtype=torch.float64)
    n_plane = n_plane / n_plane.norm()
    K = K_of(fy)
    depth = plane_depth(K, n_plane, -2.0)  # the plane n . X = -2, in front of the camera
    assert bool((depth > 0).all())
    vertex = backproject(depth, K)
    normals, ok = vertex_normals(vertex)
    assert bool(ok.all())
    facing = (normals * vertex).sum(1)
    assert bool((facing < 0).all())
    expect = n_plane if float((n_plane * vertex[0, :, 0, 0]).sum()) < 0 else -n_plane
    torch.testing.assert_close(normals[0].reshape(3, -1).T, expect.expand(H * W, 3), atol=1e-9, rtol=0)
