import math

import pytest
import torch

from dcslam.geometry.se3 import pose_error
from dcslam.slam.association import NearestNeighbourAssociation, ProjectiveAssociation, view_from_frame
from dcslam.slam.frame import FrameSettings, prepare_frame
from dcslam.slam.odometry import ICPOdometry
from dcslam.slam.robust import GemanMcClure
from dcslam.slam.scene import StreetScene, kitti_K, lidar_mask, street_trajectory
from dcslam.slam.solvers import DifferentiableLM, GaussNewton, LevenbergMarquardt

H, W = 64, 208


@pytest.fixture(scope="module")
def sparse_pair():
    scene, K = StreetScene(0), kitti_K(H, W)
    T = street_trajectory(2, step=0.5)
    mask = lidar_mask(H, W, row_step=3, col_step=2)
    settings = FrameSettings(normal_search=12)
    frames = [prepare_frame(scene.render(T[i], K, H, W).float() * mask, K, settings=settings) for i in range(2)]
    return frames, T.float()


@pytest.mark.parametrize("solver", [GaussNewton(), LevenbergMarquardt(), DifferentiableLM()], ids=["gn", "lm", "dlm"])
@pytest.mark.parametrize("association", [ProjectiveAssociation(), NearestNeighbourAssociation()],
                         ids=["projective", "nn"])
@pytest.mark.parametrize("kernel", [None, GemanMcClure()], ids=["l2", "gm"])
def test_known_motion_on_sparse_depth(sparse_pair, solver, association, kernel):
    """0.5 m of motion between two sparse frames (1/6 of the pixels). Projective association pairs only the points
    that land on a measured pixel (about 1 in 6 here, 3-6 cm error measured); nearest-neighbour pairs them all."""
    (f0, f1), T = sparse_pair
    tolerance_m = 0.07 if isinstance(association, ProjectiveAssociation) else 0.02
    result = ICPOdometry(solver=solver, association=association, kernel=kernel, min_inliers=50).estimate(
        f1, view_from_frame(f0, T[0]), T[0])
    assert result.accepted, result.reason
    dt, dr = pose_error(result.T_world_cam.double(), T[1].double())
    assert float(dt) < tolerance_m and math.degrees(float(dr)) < 0.3


@pytest.mark.parametrize("association", [ProjectiveAssociation(), NearestNeighbourAssociation()],
                         ids=["projective", "nn"])
def test_pairs_point_into_the_target(sparse_pair, association):
    (f0, _), T = sparse_pair
    target = view_from_frame(f0, T[0])
    points = target.vertex[target.valid]
    src, q, n = association.prepare(target)(points)
    assert src.numel() == points.shape[0]
    torch.testing.assert_close(q, points[src])
    assert torch.allclose(n.norm(dim=1), torch.ones(len(n)), atol=1e-5)


@pytest.mark.parametrize("association", [ProjectiveAssociation(), NearestNeighbourAssociation()],
                         ids=["projective", "nn"])
def test_empty_target_gives_no_pairs(sparse_pair, association):
    (f0, _), T = sparse_pair
    empty = view_from_frame(prepare_frame(torch.zeros(1, 1, H, W), f0.K), T[0])
    src, _, _ = association.prepare(empty)(f0.vertex[f0.valid])
    assert src.numel() == 0


def test_projective_pairs_are_those_of_project(sparse_pair):
    """The association projects with the pose and K taken once per target: each source point gets the target of the
    pixel project() rounds it to (inside the image, in front of the camera), the same pairs bit for bit, points
    behind the camera and outside the image unpaired."""
    from dcslam.geometry.camera import project
    from dcslam.geometry.se3 import inverse, transform_points

    (f0, f1), T = sparse_pair
    target = view_from_frame(f0, T[0])
    g = torch.Generator().manual_seed(3)
    points = transform_points(T[1], f1.vertex[f1.valid])
    points = torch.cat([points, points[:50] + torch.randn(50, 3, generator=g) * 5])          # some outside
    src, q, n = ProjectiveAssociation().prepare(target)(points)
    uv, z = project(transform_points(inverse(target.T_world_cam), points), target.K)
    px = torch.round(uv)
    inside = (z > 0) & (px[:, 0] >= 0) & (px[:, 0] <= W - 1) & (px[:, 1] >= 0) & (px[:, 1] <= H - 1)
    index = target.index.reshape(-1)
    lin = torch.where(inside, px[:, 1] * W + px[:, 0], 0).long()
    expected = torch.nonzero(inside & (index[lin] >= 0)).squeeze(1)
    assert torch.equal(src, expected) and 0 < src.numel() < points.shape[0]
    assert torch.equal(q, target.points[index[lin[src]]]) and torch.equal(n, target.normals[index[lin[src]]])
