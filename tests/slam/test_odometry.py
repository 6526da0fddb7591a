import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from dcslam.geometry.se3 import pose_error, se3_exp
from dcslam.slam.association import NearestNeighbourAssociation, ProjectiveAssociation, view_from_frame
from dcslam.slam.frame import prepare_frame, valid_points
from dcslam.errors import DcslamError
from dcslam.slam.odometry import DENSE_COARSE_ITERATIONS, GroundTruthOdometry, ICPOdometry, coarse_iterations_for
from dcslam.slam.scene import StreetScene, kitti_K, street_trajectory
from dcslam.slam.solvers import DifferentiableLM, GaussNewton, LevenbergMarquardt

H, W = 64, 208


@pytest.fixture(scope="module")
def pair():
    scene, K = StreetScene(0), kitti_K(H, W)
    T = street_trajectory(2, step=0.6)
    frames = [prepare_frame(scene.render(T[i], K, H, W).float(), K) for i in range(2)]
    return frames, T.float(), K


@pytest.mark.parametrize("solver", [GaussNewton(), LevenbergMarquardt(), DifferentiableLM()],
                         ids=["gn", "lm", "dlm"])
@pytest.mark.parametrize("association", [ProjectiveAssociation(), NearestNeighbourAssociation()],
                         ids=["projective", "nn"])
def test_recovers_known_motion(pair, solver, association):
    (f0, f1), T, _ = pair
    result = ICPOdometry(solver=solver, association=association).estimate(f1, view_from_frame(f0, T[0]), T[0])
    assert result.accepted, result.reason
    dt, dr = pose_error(result.T_world_cam.double(), T[1].double())
    assert float(dt) < 0.02 and math.degrees(float(dr)) < 0.1


def test_coarse_iterations_bound_the_wide_gate_stages(pair):
    """Each wide-gate stage runs at most ``coarse_iterations``; the last stage ``iterations``."""
    (f0, f1), T, _ = pair
    odo = ICPOdometry(solver=GaussNewton(tolerance=0.0), iterations=5, coarse_iterations=1)
    result = odo.estimate(f1, view_from_frame(f0, T[0]), T[0])
    assert result.iterations == 1 + 1 + 5
    full = ICPOdometry(solver=GaussNewton(tolerance=0.0), iterations=5, coarse_iterations=5)
    assert full.estimate(f1, view_from_frame(f0, T[0]), T[0]).iterations == 15
    with pytest.raises(DcslamError, match="coarse_iterations"):
        ICPOdometry(coarse_iterations=-1)


@pytest.mark.parametrize("source_voxel", [0.0, 0.2])
def test_dense_frames_get_the_dense_coarse_iterations(pair, source_voxel):
    """The density is the frame's, not that of the sources left after voxel thinning."""
    (f0, f1), T, _ = pair
    assert float(f1.valid.float().mean()) > 0.8
    odo = ICPOdometry(solver=GaussNewton(tolerance=0.0), iterations=8, source_voxel=source_voxel)
    result = odo.estimate(f1, view_from_frame(f0, T[0]), T[0])
    assert result.iterations == 2 * min(DENSE_COARSE_ITERATIONS, 8) + 8


def test_coarse_iterations_follow_the_density():
    """0 means: from the frame's density. Sparse depth (LiDAR, annotated) keeps ``iterations`` in every stage;
    dense depth gets :data:`DENSE_COARSE_ITERATIONS` (never more than ``iterations``)."""
    assert coarse_iterations_for(0.05, 20) == 20 and coarse_iterations_for(0.2, 20) == 20
    assert coarse_iterations_for(0.9, 20) == min(DENSE_COARSE_ITERATIONS, 20)
    assert coarse_iterations_for(0.9, 1) == 1


def test_recovers_perturbation_of_same_frame(pair):
    (f0, _), T, _ = pair
    T_true = se3_exp(torch.tensor([0.05, -0.03, 0.2, 0.01, -0.02, 0.015]))
    result = ICPOdometry().estimate(f0, view_from_frame(f0, torch.eye(4)), torch.linalg.inv(T_true))
    dt, dr = pose_error(result.T_world_cam.double(), torch.eye(4, dtype=torch.float64))
    assert result.accepted and float(dt) < 0.01 and math.degrees(float(dr)) < 0.05


def test_agrees_with_open3d_point_to_plane(pair):
    o3d = pytest.importorskip("open3d")
    (f0, f1), T, _ = pair
    target = view_from_frame(f0, T[0])
    iterations, gate = 30, 0.5
    ours = ICPOdometry(association=NearestNeighbourAssociation(), max_distance=gate, max_normal_angle_deg=180,
                       iterations=iterations, coarse_to_fine=(1.0,)).estimate(f1, target, T[0])
    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(f1.vertex[f1.valid].double().numpy()))
    tgt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(target.vertex[target.valid].double().numpy()))
    tgt.normals = o3d.utility.Vector3dVector(target.normal[target.valid].double().numpy())
    reg = o3d.pipelines.registration.registration_icp(
        src, tgt, gate, T[0].double().numpy(), o3d.pipelines.registration.TransformationEstimationPointToPlane(),
        o3d.pipelines.registration.ICPConvergenceCriteria(1e-9, 1e-9, iterations))
    dt, dr = pose_error(ours.T_world_cam.double(), torch.from_numpy(np.asarray(reg.transformation)))
    assert float(dt) < 0.01 and math.degrees(float(dr)) < 0.1


def test_empty_and_zero_frames_are_rejected_not_nan(pair):
    (f0, _), T, K = pair
    zero = prepare_frame(torch.zeros(1, 1, H, W), K)
    for model in (None, view_from_frame(f0, T[0])):
        result = ICPOdometry().estimate(zero, model, T[0])
        assert not result.accepted and torch.equal(result.T_world_cam, T[0])
    result = ICPOdometry().estimate(f0, view_from_frame(zero, T[0]), T[0])
    assert not result.accepted and torch.isfinite(result.T_world_cam).all()


@pytest.mark.parametrize("solver", [GaussNewton(), LevenbergMarquardt(), DifferentiableLM()], ids=["gn", "lm", "dlm"])
def test_planar_scene_is_rejected_as_degenerate(solver):
    K = kitti_K(H, W)
    plane = prepare_frame(torch.full((1, 1, H, W), 6.0), K)
    start = se3_exp(torch.tensor([0.1, 0.0, 0.0, 0.0, 0.0, 0.02]))
    result = ICPOdometry(solver=solver).estimate(plane, view_from_frame(plane, torch.eye(4)), start)
    assert not result.accepted and "degenerate" in result.reason
    assert torch.isfinite(result.T_world_cam).all() and torch.equal(result.T_world_cam, start)


def test_ground_truth_odometry(pair):
    (f0, _), T, _ = pair
    assert torch.equal(GroundTruthOdometry().estimate(f0, None, T[0], T[1]).T_world_cam, T[1])


_spec = importlib.util.spec_from_file_location("slam_fixtures", Path(__file__).with_name("slam_fixtures.py"))
slam_fixtures = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(slam_fixtures)


def test_differentiable_lm_pose_gradcheck():
    """The pose estimated by ICP with the differentiable LM is a differentiable function of the source depth."""
    slam_fixtures.pose_gradcheck()


def test_unconstrained_directions_are_held_at_the_prediction():
    """A plane facing the camera fixes depth and two tilts; sliding along it is unobservable. With ``hold_below``
    the step corrects what the plane constrains and leaves the slide where the prediction put it."""
    K = kitti_K(H, W)
    plane = prepare_frame(torch.full((1, 1, H, W), 6.0), K)
    target = view_from_frame(plane, torch.eye(4))
    start = se3_exp(torch.tensor([0.3, -0.2, 0.15, 0.0, 0.0, 0.0]))
    odometry = ICPOdometry(min_conditioning=-math.inf, hold_below=1e-2, coarse_to_fine=(1.0,))
    held = odometry.estimate(plane, target, start)
    T = held.T_world_cam
    assert abs(float(T[2, 3])) < 1e-3                                     # depth corrected
    assert torch.allclose(T[:2, 3], start[:2, 3], atol=1e-3)              # slide kept at the prediction
    # the step says what it held: the two slides and the spin about the plane's normal, as unit twists
    from dcslam.slam.health import held_names

    assert held.held is not None and held.held.shape == (3, 6) and held.held.dtype == torch.float64
    assert sorted(held_names(held.held)) == ["across the road (camera x)", "rotation about camera z",
                                             "vertical (camera y)"]
    scale = float(valid_points(plane)[1].norm(dim=1).mean())
    D = torch.tensor([1, 1, 1, scale, scale, scale], dtype=torch.float64)
    assert torch.allclose((held.held * D).norm(dim=1), torch.ones(3, dtype=torch.float64))
    assert ICPOdometry(min_conditioning=-math.inf, coarse_to_fine=(1.0,)).estimate(plane, target, start).held is None


def _box_pairs(n: int, residual: float):
    """Points on the six faces of a box centred on the camera, paired with themselves moved along their normals
    by +-``residual`` in turn: translation and rotation decouple, so the translation covariance is known."""
    g = torch.linspace(-1.0, 1.0, n, dtype=torch.float64)
    a, b = [t.reshape(-1) for t in torch.meshgrid(g, g, indexing="ij")]
    points, normals = [], []
    for axis in range(3):
        for side in (-2.0, 2.0):
            p = torch.zeros(a.numel(), 3, dtype=torch.float64)
            p[:, axis], p[:, (axis + 1) % 3], p[:, (axis + 2) % 3] = side, a, b
            nrm = torch.zeros_like(p)
            nrm[:, axis] = 1.0
            points.append(p)
            normals.append(nrm)
    points, normals = torch.cat(points), torch.cat(normals)
    signs = torch.ones(len(points), dtype=torch.float64)
    signs[1::2] = -1
    targets = points + residual * signs[:, None] * normals
    index = torch.arange(len(points))
    return points, normals, lambda p: (index, targets, normals)


def test_covariance_known_answer():
    """s^2 (J^T J)^-1 with s^2 = sum r^2 / (M - 6): on the box, each translation axis is fixed by the 2 n^2 points
    of the two faces across it, so its standard deviation is s / sqrt(2 n^2)."""
    from dcslam.slam.odometry import PointToPlane

    n, e = 5, 0.01
    source, normals, associate = _box_pairs(n, e)
    problem = PointToPlane(source, normals, associate, max_distance=1.0, cos_max_angle=0.5)
    T = torch.eye(4, dtype=torch.float64)
    lin = problem.linearize(T)
    cov = problem.covariance(T, lin)
    M = len(source)
    s2 = M * e ** 2 / (M - 6)
    assert cov.shape == (6, 6)
    assert torch.allclose(torch.diagonal(cov)[:3], torch.full((3,), s2 / (2 * n * n), dtype=torch.float64),
                          rtol=1e-6)
    assert torch.allclose(cov[:3, 3:], torch.zeros(3, 3, dtype=torch.float64), atol=1e-12)
    assert torch.equal(problem.covariance(T, lin, problem._fixed_residuals(T)), cov)  # the caller's residuals


def test_step_reports_its_uncertainty(pair):
    """An accepted step carries its first-order standard deviations of position and rotation."""
    (f0, f1), T, _ = pair
    result = ICPOdometry().estimate(f1, view_from_frame(f0, T[0]), T[0])
    assert result.accepted and 0 < result.sigma_m < 0.05 and 0 < result.sigma_deg < 1.0


@pytest.mark.parametrize("association", [ProjectiveAssociation(), NearestNeighbourAssociation()],
                         ids=["projective", "nn"])
def test_icp_in_each_dtype_and_on_each_device(device, dtype, association):
    """ICP recovers a known motion in float32 and float64, on the CPU and on a GPU, with each solver; the pose
    comes back in the frames' dtype, on their device."""
    scene, K = StreetScene(0), kitti_K(H, W, dtype=torch.float64)
    T = street_trajectory(2, step=0.6)
    depth = [scene.render(T[i], K, H, W).to(device=device, dtype=dtype) for i in range(2)]
    K, T = K.to(device=device, dtype=dtype), T.to(device=device, dtype=dtype)
    f0, f1 = (prepare_frame(d, K) for d in depth)
    for solver in (GaussNewton(), LevenbergMarquardt(), DifferentiableLM()):
        result = ICPOdometry(solver=solver, association=association).estimate(f1, view_from_frame(f0, T[0]), T[0])
        assert result.accepted, (type(solver).__name__, result.reason)
        assert result.T_world_cam.dtype == dtype and result.T_world_cam.device.type == device.type
        dt, dr = pose_error(result.T_world_cam.double().cpu(), T[1].double().cpu())
        assert float(dt) < 0.02 and math.degrees(float(dr)) < 0.1, type(solver).__name__


def _weak_by_eigh(problem, lin):
    """What PointToPlane._weak gave before its Cholesky test: the eigenvectors below the floor, by eigh alone."""
    DD = problem._D[1]
    values, vectors = torch.linalg.eigh(lin.H.detach() / DD / max(lin.weight or lin.count, 1e-12))
    return vectors[:, values < problem.hold_below]


@pytest.mark.parametrize("seed", range(6))
def test_the_conditioning_check_holds_what_eigh_holds(seed):
    """Normal equations whose smallest normalised eigenvalue lies anywhere from far below the floor to far above it
    (through the Cholesky test's margin of twice the floor): the directions held are eigh's, bit for bit, and the
    test alone answers where every eigenvalue is clearly above."""
    from dcslam.slam.odometry import PointToPlane, _clear_above
    from dcslam.slam.solvers import Linearization

    g = torch.Generator().manual_seed(seed)
    problem = PointToPlane(torch.zeros(10, 3), torch.zeros(10, 3), None, max_distance=1.0, cos_max_angle=0.5,
                           hold_below=0.0025)
    problem.scale = 7.5
    fast = 0
    for smallest in (1e-5, 1e-3, 0.0024, 0.0026, 0.0049, 0.00501, 0.006, 0.02, 0.5):
        Q = torch.linalg.qr(torch.randn(6, 6, generator=g, dtype=torch.float64))[0]
        values = torch.tensor([smallest, 0.03, 0.1, 0.4, 1.0, 2.0], dtype=torch.float64)
        D = torch.tensor([1, 1, 1, 7.5, 7.5, 7.5], dtype=torch.float64)
        count = 1234
        H = (Q * values) @ Q.T * (D[:, None] * D[None, :]) * count
        lin = Linearization(H, torch.zeros(6, dtype=torch.float64), torch.tensor(0.0), count)
        weak, _ = problem._weak(lin)
        expected = _weak_by_eigh(problem, lin)
        assert weak.shape == expected.shape and torch.equal(weak, expected), smallest
        fast += _clear_above(H.tolist(), D.tolist(), float(count), 2 * problem.hold_below)
        if smallest >= 0.006:
            assert _clear_above(H.tolist(), D.tolist(), float(count), 2 * problem.hold_below), smallest
        if smallest <= 0.005:
            assert not _clear_above(H.tolist(), D.tolist(), float(count), 2 * problem.hold_below), smallest
    assert fast == 4      # 0.00501 and up: just past twice the floor


def test_the_conditioning_test_leaves_doubt_to_eigh():
    from dcslam.slam.odometry import _clear_above

    eye = torch.eye(6, dtype=torch.float64).tolist()
    assert _clear_above(eye, [1.0] * 6, 1.0, 0.5)
    assert not _clear_above(eye, [1.0] * 6, 1.0, 1.0)                 # on the floor: not clearly above
    nan = [row[:] for row in eye]
    nan[3][3] = math.nan
    assert not _clear_above(nan, [1.0] * 6, 1.0, 0.5)
    assert not _clear_above(eye, [1.0, 1.0, 1.0, 0.0, 0.0, 0.0], 1.0, 0.5)
