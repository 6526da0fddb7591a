import math

import pytest
import torch

from dcslam.geometry.se3 import pose_error
from dcslam.slam.config import SlamSettings, build_slam
from dcslam.slam.health import HealthRules, assess, drift_sigma_m, summarise
from dcslam.slam.pipeline import StepReport
from dcslam.slam.scene import kitti_K, lidar_mask

H, W = 64, 208


def _tunnel_depth(K: torch.Tensor, half_width: float = 3.0, floor: float = 1.6, ceiling: float = -2.5):
    """Depth of an endless straight tunnel (two walls, floor, ceiling; nothing along the direction of travel), so
    every frame looks the same wherever the camera is along it. Shape: (H, W)."""
    v, u = torch.meshgrid(torch.arange(H, dtype=torch.float64), torch.arange(W, dtype=torch.float64), indexing="ij")
    x, y = (u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1]
    big = torch.full_like(x, math.inf)
    t = torch.minimum(torch.where(x > 1e-9, half_width / x.clamp_min(1e-9), big),
                      torch.where(x < -1e-9, -half_width / x.clamp_max(-1e-9), big))
    t = torch.minimum(t, torch.where(y > 1e-9, floor / y.clamp_min(1e-9), big))
    t = torch.minimum(t, torch.where(y < -1e-9, ceiling / y.clamp_max(-1e-9), big))
    return torch.where(t < 80, t, torch.zeros_like(t)).float()


@pytest.mark.parametrize("sparse", [False, True], ids=["dense", "sparse"])
@pytest.mark.parametrize("odometry", ["icp", "gradicp"])
def test_featureless_tunnel_drive_is_flagged_never_silently_wrong(sparse, odometry):
    """The car drives 1 m per frame down a featureless tunnel, but the frames cannot show it: ICP must not return
    a trajectory as trustworthy that it cannot have measured."""
    K = kitti_K(H, W).double()
    depth = _tunnel_depth(K) * (lidar_mask(H, W, 4, 4) if sparse else 1)
    frames = 6
    slam = build_slam(SlamSettings(odometry=odometry))
    for _ in range(frames):
        slam.step(depth[None, None], K.float())
    truth = torch.eye(4, dtype=torch.float64).repeat(frames, 1, 1)
    truth[:, 2, 3] = torch.arange(frames, dtype=torch.float64)
    dt, _ = pose_error(slam.trajectory().double(), truth)
    summary = slam.health_summary()
    assert float(dt[-1]) > 0.5                       # the motion is not observable ...
    assert summary["suspect"] and summary["reasons"]  # ... and the run says so
    assert summary["accepted"] < frames - 1


def test_good_drive_is_not_flagged(street_drive):
    depth, K, T = street_drive
    slam = build_slam(SlamSettings())
    poses = slam.run(depth, K)
    dt, _ = pose_error(poses.double(), T)
    summary = slam.health_summary()
    assert float(dt.max()) < 0.2
    assert not summary["suspect"], summary
    assert summary["accepted"] == len(T) - 1
    assert summary["road"]["frames_seen"] == len(T) and summary["road"]["drift_m"] < 0.1   # the road, every frame


def test_too_few_pairs_to_measure_is_flagged(street_drive):
    """The good street drive seen through a few scan lines (every 24th row and 4th column: 124-134 pairs per step)
    under rules that trust 150 pairs (the default, 100, is the ICP odometry's own rejection bound): each step rests
    on fewer pairs than the rule trusts, and the run says so, whatever share of its points paired."""
    from dcslam.slam.health import HealthRules

    depth, K, T = street_drive
    sparse = depth * lidar_mask(depth.shape[-2], depth.shape[-1], row_step=24, col_step=4)
    slam = build_slam(SlamSettings())
    slam.health = HealthRules(min_pairs=150)
    slam.run(sparse, K)
    summary = slam.health_summary()
    assert summary["suspect"]
    assert any("pairs" in why for step in summary["flagged_steps"] for why in step["why"])


@pytest.fixture(scope="module")
def street_drive():
    from dcslam.slam.scene import StreetScene, street_trajectory

    h, w = 188, 621          # half KITTI size: at 64 x 208 the street's conditioning is ~3x lower than at full size
    scene, K = StreetScene(0), kitti_K(h, w)
    T = street_trajectory(5, step=1.0)
    depth = torch.stack([scene.render(T[i], K, h, w) for i in range(5)]).float()[:, None]
    return depth, K, T


class TestAssess:
    def test_rejected_keeps_reason(self):
        assert assess(False, "diverged", 0, 0, math.nan, 0, 0, True) == ("rejected", ["diverged"])

    def test_accepted(self):
        assert assess(True, "", 900, 1000, 0.1, 0.05, 0.2, True) == ("accepted", [])

    @pytest.mark.parametrize("args,word", [((50, 1000, 0.1, 0.0, 0.0, True), "paired"),
                                           ((900, 1000, 1e-4, 0.0, 0.0, True), "conditioning"),
                                           ((900, 1000, 0.1, 0.9, 0.0, True), "prediction"),
                                           ((900, 1000, 0.1, 0.0, 5.0, True), "prediction")])
    def test_degraded_says_why(self, args, word):
        verdict, why = assess(True, "", *args)
        assert verdict == "degraded" and word in why[0]

    def test_pairs_are_counted_not_shared(self):
        """A dense frame pairs a small share of its many points and is still well measured; a sparse one with few
        pairs is not, whatever its share."""
        assert assess(True, "", 800, 16000, 0.02, 0.0, 0.0, True)[0] == "accepted"      # 5 % of a dense frame
        verdict, why = assess(True, "", 90, 180, 0.02, 0.0, 0.0, True)                    # half of a sparse one
        assert verdict == "degraded" and "fewer than 100 pairs" in why[0]

    def test_prediction_gap_needs_a_velocity(self):
        assert assess(True, "", 900, 1000, 0.1, 0.9, 0.0, False)[0] == "accepted"


def _report(index, verdict, sigma_m=math.nan, sigma_deg=math.nan, x=0.0):
    T = torch.eye(4)
    T[0, 3] = x
    return StepReport(index, T, verdict != "rejected", "", 0, 0, 0.0, 0, 0.0, verdict, ("x",),
                      sigma_m=sigma_m, sigma_deg=sigma_deg)


class TestDriftSigma:
    def test_position_errors_add_as_a_random_walk(self):
        reports = [_report(i, "accepted", 0.1, 0.0, float(i)) for i in range(5)]
        assert drift_sigma_m(reports) == pytest.approx(0.2)      # 4 steps of 0.1 m: sqrt(4) * 0.1

    def test_heading_errors_grow_with_the_road_still_to_drive(self):
        """1 m steps along x: the heading error of step i moves the last pose by (4 - i) m times the angle."""
        deg = 0.5
        reports = [_report(i, "accepted", 0.0, deg, float(i)) for i in range(5)]
        expected = math.radians(deg) * math.sqrt(3 ** 2 + 2 ** 2 + 1 ** 2 + 0 ** 2)
        assert drift_sigma_m(reports) == pytest.approx(expected, rel=1e-6)

    def test_slow_drift_no_step_shows_makes_a_run_suspect(self):
        """Every step accepted, each a little uncertain: the drift bound adds the steps' errors as correlated
        ones, so 30 steps of 8 mm reach 0.24 m and 2.5 sigma of that is past the 0.5 m bound (30 steps of 6 mm,
        0.45 m, are not), where a random walk would have said 0.11 m."""
        slow = [_report(i, "accepted", 0.008, 0.0, float(i)) for i in range(31)]
        fine = [_report(i, "accepted", 0.006, 0.0, float(i)) for i in range(31)]
        s = summarise(slow)
        assert s["suspect"] and "2.5 sigma" in s["reasons"][0] and s["accepted"] == 30
        assert s["drift"]["bound_m"] == pytest.approx(0.6, rel=1e-3) and s["drift_sigma_m"] < 0.05
        assert not summarise(fine)["suspect"]
        assert not summarise(slow, HealthRules(max_drift_m=0))["suspect"]

    def test_rejected_and_unmeasured_steps_add_nothing(self):
        reports = [_report(0, "accepted", 0.1, 0.0), _report(1, "rejected", 5.0, 0.0), _report(2, "accepted"),
                   _report(3, "accepted", 0.3, 0.0)]
        assert drift_sigma_m(reports) == pytest.approx(0.3)
        assert summarise(reports)["drift_sigma_m"] == pytest.approx(0.3)


class TestSummarise:
    def test_counts_skip_the_first_frame(self):
        s = summarise([_report(0, "accepted")] + [_report(i, "accepted") for i in range(1, 11)])
        assert (s["accepted"], s["degraded"], s["rejected"], s["suspect"]) == (10, 0, 0, False)

    def test_one_rejected_step_makes_a_run_suspect(self):
        s = summarise([_report(i, "rejected" if i == 3 else "accepted") for i in range(11)])
        assert s["suspect"] and "rejected" in s["reasons"][0] and s["flagged_steps"][0]["frame"] == 3

    def test_degraded_fraction(self):
        reports = [_report(i, "degraded" if i in (1, 3) else "accepted") for i in range(21)]
        assert not summarise(reports)["suspect"]
        assert summarise(reports, HealthRules(max_degraded_fraction=0.05))["suspect"]

    def test_a_streak_of_degraded_steps(self):
        streak = [_report(i, "degraded" if i in (20, 21, 22) else "accepted") for i in range(41)]
        pair = [_report(i, "degraded" if i in (1, 2) else "accepted") for i in range(41)]   # 16-beam drive 1007
        apart = [_report(i, "degraded" if i in (5, 20, 35) else "accepted") for i in range(41)]
        assert summarise(streak)["suspect"] and "consecutive" in summarise(streak)["reasons"][0]
        assert summarise(pair)["suspect"] and "2 consecutive" in summarise(pair)["reasons"][0]
        assert not summarise(apart)["suspect"]

    def test_empty(self):
        assert summarise([])["suspect"] is False
