"""The SLAM's parts declare what the loop needs (dcslam.slam.parts); the loop asks nothing else of them."""
import pytest
import torch

from dcslam.depth.pose import default_mapper, default_odometry
from dcslam.slam.config import MAPPERS, ODOMETRIES, SlamSettings, build_slam
from dcslam.slam.odometry import GroundTruthOdometry, ICPOdometry, OdometryResult
from dcslam.slam.parts import Mapper, Odometry
from dcslam.slam.pipeline import SLAM
from dcslam.slam.fusion import PointFusion
from dcslam.slam.scene import StreetScene, kitti_K, street_trajectory

H, W = 48, 160


@pytest.mark.parametrize("odometry", ODOMETRIES)
@pytest.mark.parametrize("mapper", MAPPERS)
def test_every_built_part_follows_its_protocol(odometry, mapper):
    slam = build_slam(SlamSettings(odometry=odometry, mapper=mapper))
    assert isinstance(slam.odometry, Odometry) and isinstance(slam.mapper, Mapper)
    assert isinstance(slam.odometry.first_pose_from_gt, bool) and isinstance(slam.odometry.assess_steps, bool)


def test_the_pose_loss_parts_follow_the_protocols():
    assert isinstance(default_odometry(), Odometry) and isinstance(default_mapper(), Mapper)


def test_ground_truth_and_icp_declare_their_steps():
    assert GroundTruthOdometry.first_pose_from_gt and not GroundTruthOdometry.assess_steps
    assert not ICPOdometry.first_pose_from_gt and ICPOdometry.assess_steps
    assert GroundTruthOdometry().effective_settings(0.5) == {}
    assert ICPOdometry(max_distance=0.5, source_voxel=0.2).effective_settings(0.5) == {
        "source_voxel": 0.1, "max_distance": 0.25, "gates": [1.0, 0.5, 0.25]}


class _OffsetGroundTruth:
    """An odometry the loop has never heard of: the ground truth moved 1 cm, reported with no inliers (which the
    health rules would reject), declaring that its first pose is the ground truth's and its steps need no check."""

    first_pose_from_gt = True
    assess_steps = False

    def __init__(self):
        self.calls = []

    def estimate(self, frame, model, T_init, T_gt=None, T_last=None, scale=1.0) -> OdometryResult:
        self.calls.append(scale)
        T = T_gt.clone()
        T[0, 3] += 0.01
        return OdometryResult(T, inliers=0, sources=0)

    def reset(self) -> None:
        self.calls = []

    def precompute(self, frame, scale=1.0) -> None:
        pass

    def effective_settings(self, scale: float) -> dict:
        return {"offset": 0.01}


def _drive(n: int = 3):
    scene, K = StreetScene(3), kitti_K(H, W)
    T = street_trajectory(n, step=0.5)
    depth = torch.stack([scene.render(T[i], K, H, W) for i in range(n)]).float()[:, None]
    return depth, K, T.float()


def test_the_loop_follows_what_an_odometry_declares():
    depth, K, T = _drive()
    odometry = _OffsetGroundTruth()
    slam = SLAM(odometry, PointFusion(voxel_size=0.2), reference_depth_m=12.0)
    assert isinstance(odometry, Odometry)
    poses = slam.run(depth, K, T_gt=T)
    assert torch.equal(poses[0], T[0])                                 # first pose from the ground truth
    assert torch.allclose(poses[1:, 0, 3], T[1:, 0, 3] + 0.01)
    assert [r.verdict for r in slam.reports] == ["accepted"] * 3       # not assessed
    assert odometry.calls == [slam.scale] * 2 and 0 < slam.scale <= 1  # the scene scale, passed in
    assert slam.effective_settings()["offset"] == 0.01
    assessed = _OffsetGroundTruth()
    assessed.assess_steps, assessed.first_pose_from_gt = True, False
    slam = SLAM(assessed, PointFusion(voxel_size=0.2))
    poses = slam.run(depth, K, T_gt=T)
    assert torch.equal(poses[0], torch.eye(4))                         # T_world_cam0, not the ground truth
    assert [r.verdict for r in slam.reports][1:] == ["degraded"] * 2   # no pairs: the health rules flag it
