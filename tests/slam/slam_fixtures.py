"""Helpers shared by the SLAM tests (loaded by file path, as tests/io/kitti_fixtures.py is)."""
import torch

from dcslam.geometry.se3 import se3_exp
from dcslam.slam.association import view_from_frame
from dcslam.slam.frame import prepare_frame
from dcslam.slam.odometry import ICPOdometry
from dcslam.slam.solvers import DifferentiableLM


def pose_gradcheck(kernel=None, max_distance: float = 0.5) -> None:
    """ICP with the differentiable LM on a corner of three slanted planes (fully constrained): gradcheck of the
    estimated pose against the source depth."""
    h, w = 10, 14
    K = torch.tensor([[12.0, 0, 6.5], [0, 12.0, 4.5], [0, 0, 1]], dtype=torch.float64)
    v, u = torch.meshgrid(torch.arange(h, dtype=torch.float64), torch.arange(w, dtype=torch.float64), indexing="ij")
    rays = torch.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], torch.ones_like(u)], -1)
    normals = torch.tensor([[0.6, 0.1, -1.0], [-0.7, 0.2, -1.0], [0.1, -0.8, -1.0]], dtype=torch.float64)
    depth0 = (3.0 / (rays @ (-normals).T)).min(-1).values[None, None]
    target = view_from_frame(prepare_frame(depth0, K), torch.eye(4, dtype=torch.float64))
    odometry = ICPOdometry(solver=DifferentiableLM(), iterations=3, min_inliers=10, min_conditioning=0,
                           coarse_to_fine=(1.0,), kernel=kernel, max_distance=max_distance)
    T_init = se3_exp(torch.tensor([0.01, -0.02, 0.01, 0.005, 0.0, -0.004], dtype=torch.float64))

    def pose(depth):
        return odometry.estimate(prepare_frame(depth, K), target, T_init).T_world_cam

    depth = (depth0 * (1 + 0.001 * torch.sin(u + v))).requires_grad_()
    assert torch.autograd.gradcheck(pose, (depth,), eps=1e-7, atol=1e-5)
    grad = torch.autograd.grad(pose(depth)[:3, 3].sum(), depth)[0]
    assert torch.isfinite(grad).all() and grad.abs().sum() > 0
