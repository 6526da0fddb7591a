"""The degeneracy analysis of ICP steps and the drift bound it feeds (dcslam.slam.health): a direction the scan
leaves unconstrained is found, named, and carried into a bound that flags the run."""
import json
import math

import numpy as np
import pytest
import torch

from dcslam.geometry.se3 import pose_error
from dcslam.slam.health import (AXIS_NAMES, HealthRules, _position_covariances, axis_name, drift_bound,
                                prediction_bound, step_degeneracy, summarise)
from dcslam.slam.pipeline import StepReport

#: Rules whose drift bound is three standard deviations, so that the expected bounds below are round numbers.
THREE = HealthRules(drift_sigmas=3.0)


def _report(index, z, covariance=None, information=None, verdict="accepted"):
    """A step at (0, 0, z), camera axes along the world's. Shape: covariance, information (6, 6) or None."""
    T = torch.eye(4, dtype=torch.float64)
    T[2, 3] = z
    return StepReport(index, T, verdict != "rejected", "", 0, 0, 0.0, 0, 0.0, verdict, (),
                      covariance=None if covariance is None else torch.as_tensor(covariance, dtype=torch.float64),
                      information=None if information is None else torch.as_tensor(information,
                                                                                  dtype=torch.float64))


def _corridor_information(along: float = 0.0):
    """J^T J of point-to-plane pairs on two walls (normals +-x), a road (normal y) and, with ``along`` > 0, that
    many pairs on something facing the direction of travel (normal z): 100 pairs each on walls and road."""
    rng = np.random.default_rng(0)
    normals = [np.array([1.0, 0, 0])] * 100 + [np.array([0, -1.0, 0])] * 100 + [np.array([0, 0, 1.0])] * int(along)
    H = np.zeros((6, 6))
    for n in normals:
        s = rng.uniform([-5, -2, 2], [5, 2, 30])
        j = np.concatenate([n, np.cross(s, n)])
        H += np.outer(j, j)
    return H


def test_a_corridor_leaves_the_road_direction_unconstrained():
    d = step_degeneracy(_corridor_information())
    assert d["translation"] == pytest.approx(0.0, abs=1e-12)
    assert abs(d["translation_direction"][2]) == pytest.approx(1.0)
    assert axis_name(d["translation_direction"]) == "along the road (camera z)"
    some = step_degeneracy(_corridor_information(along=10))
    assert some["translation"] == pytest.approx(10 / 210, rel=1e-6)      # its share of the pairs' normal weight
    assert step_degeneracy(None) is None and step_degeneracy(np.full((6, 6), np.nan)) is None


def test_position_covariance_is_the_linearised_position_error():
    """a + b x d for a twist (a, b) of covariance C: the map [I, -[d]x] applied to C."""
    rng = np.random.default_rng(1)
    M = rng.normal(size=(6, 6))
    C = M @ M.T
    d = np.array([3.0, -1.0, 7.0])
    skew = np.array([[0, -d[2], d[1]], [d[2], 0, -d[0]], [-d[1], d[0], 0]])
    J = np.hstack([np.eye(3), -skew])
    got = _position_covariances(C[None, :3, :3], C[None, :3, 3:], C[None, 3:, 3:], d[None])[0]
    assert np.allclose(got, J @ C @ J.T)
    b = rng.normal(size=3)                                    # the lever's sign: a rotation b moves d to d + b x d
    assert np.allclose(J @ np.concatenate([np.zeros(3), b]), np.cross(b, d))


def test_steps_add_as_correlated_errors_and_rejected_ones_add_nothing():
    """Four steps of 1 cm along x: 3 x 4 x 1 cm, not 3 x sqrt(4) x 1 cm; a rejected step adds nothing."""
    C = np.diag([1e-4, 1e-8, 1e-8, 0, 0, 0])
    reports = [_report(0, 0.0)] + [_report(i, float(i), C) for i in range(1, 5)]
    bound = drift_bound(reports, THREE)
    assert bound["bound_m"] == pytest.approx(0.12, rel=1e-3) and bound["sigmas"] == 3.0
    assert bound["direction"] == "across the road (camera x)"
    with_rejected = reports + [_report(5, 5.0, np.eye(6), verdict="rejected")]
    assert drift_bound(with_rejected, THREE)["bound_m"] == pytest.approx(0.12, rel=1e-3)
    assert drift_bound([_report(0, 0.0)])["bound_m"] == 0.0
    assert drift_bound(reports)["bound_m"] == pytest.approx(HealthRules().drift_sigmas * 0.04, rel=1e-3)


def test_a_heading_error_moves_the_road_still_to_drive():
    """A yaw error (about camera y) at step i moves the last position across the road by the road from frame i."""
    s = math.radians(0.1)
    C = np.diag([0, 0, 0, 0, s * s, 0])
    reports = [_report(0, 0.0)] + [_report(i, float(i), C) for i in range(1, 5)]
    bound = drift_bound(reports, THREE)
    assert bound["bound_m"] == pytest.approx(3 * s * (3 + 2 + 1 + 0), rel=1e-3)
    assert bound["direction"] == "across the road (camera x)"


def test_a_degenerate_direction_carries_the_predictions_uncertainty():
    """The corridor's steps are precise on paper (1 mm) but say nothing along the road: the bound there is the
    prediction's (0.5 m at the first step, which has no velocity, 0.05 m later), it names the direction, and it
    says from which frame the run may be past 0.5 m."""
    C = np.diag([1e-6] * 3 + [1e-10] * 3)
    corridor = _corridor_information()
    reports = [_report(0, 0.0)] + [_report(i, float(i), C, corridor) for i in range(1, 6)]
    bound = drift_bound(reports, THREE)
    assert bound["bound_m"] == pytest.approx(3 * (0.5 + 4 * 0.05), rel=1e-2)
    assert bound["direction"] == "along the road (camera z)" and bound["weakest_direction"] == bound["direction"]
    s = summarise(reports, THREE)
    assert s["suspect"] and s["prediction"]["from_frame"] == 1 and s["prediction"]["frames"] == [1, 2, 3, 4, 5]
    assert s["prediction"]["bound_m"] == pytest.approx(3 * (0.5 + 4 * 0.05), rel=1e-6)   # the prediction alone
    assert s["reasons"][-1].startswith("5 steps left a direction degenerate (frames 1-5): the prediction there may "
                                       "have put it 2.10 m off (3 sigma of 0.05 m a step, 0.5 m at the first)")
    assert "along the road (camera z) left unconstrained, past 0.5 m from frame 1" in s["reasons"][-1]
    previous = summarise(reports, HealthRules(drift_sigmas=3.0, prediction_bound=False))
    assert previous["suspect"] and previous["drift"]["counted"] and previous["prediction"] is None
    assert "accumulated uncertainty 2.10 m" in previous["reasons"][-1]
    walled = [_report(0, 0.0)] + [_report(i, float(i), C, _corridor_information(along=50)) for i in range(1, 6)]
    assert not summarise(walled, THREE)["suspect"] and summarise(walled, THREE)["drift"]["bound_m"] < 0.05
    late = [_report(0, 0.0), _report(1, 1.0, C, _corridor_information(along=50))] + \
        [_report(i, float(i), C, corridor) for i in range(2, 5)]
    assert not summarise(late, THREE)["suspect"]                            # 3 x 3 x 0.05 m
    longer = late + [_report(i, float(i), C, corridor) for i in range(5, 8)]
    assert summarise(longer, THREE)["suspect"] and summarise(longer, THREE)["prediction"]["from_frame"] == 5  # 3x4x5cm
    assert not summarise(reports, HealthRules(max_drift_m=0))["suspect"]
    assert json.loads(json.dumps(s))["drift"] == s["drift"]                 # written as is in the run's summary
    assert json.loads(json.dumps(s))["prediction"] == s["prediction"]


def test_one_degenerate_step_among_loose_measured_ones_is_judged_by_the_prediction_alone():
    """At 8 beams every measured step's covariance is wide, and their correlated sum passes 0.5 m on runs that end
    0.1 m off; one degenerate step among them adds the prediction's 5 cm (2.5 sigma: 0.125 m), not that sum. The
    previous rule (``prediction_bound`` off) counted the whole sum as soon as one step was degenerate."""
    loose = np.diag([4e-3, 4e-3, 4e-3, 1e-8, 1e-8, 1e-8])                  # 6.3 cm a step, every direction measured
    walled = _corridor_information(along=50)
    reports = [_report(0, 0.0)] + [_report(i, float(i), loose, _corridor_information() if i == 12 else walled)
                                   for i in range(1, 30)]
    s = summarise(reports)
    assert s["drift"]["bound_m"] > 1.0 and s["drift"]["degenerate_frames"] == [12] and not s["drift"]["counted"]
    assert s["prediction"]["bound_m"] == pytest.approx(2.5 * 0.05, rel=1e-6) and s["prediction"]["frames"] == [12]
    assert not s["suspect"]
    assert prediction_bound(reports)["bound_m"] == s["prediction"]["bound_m"]
    previous = summarise(reports, HealthRules(prediction_bound=False))
    assert previous["suspect"] and previous["drift"]["counted"]
    assert "accumulated uncertainty" in previous["reasons"][0]
    first = [_report(0, 0.0)] + [_report(i, float(i), loose, _corridor_information() if i == 1 else walled)
                                 for i in range(1, 30)]
    s = summarise(first)                                                    # the first step has no velocity: 0.5 m
    assert s["suspect"] and s["prediction"]["bound_m"] == pytest.approx(1.25, rel=1e-6)
    assert "1 steps left a direction degenerate (frames 1)" in s["reasons"][0]


def test_axis_names():
    assert [axis_name(v) for v in np.eye(3)] == list(AXIS_NAMES)
    assert axis_name([0.1, -0.9, 0.3]) == "vertical (camera y)"


def _walled_road(frames: int, H: int, W: int, rows: int):
    """A straight road between two parallel walls, 8 m apart, with a thin post on one side every 10 m (the only
    thing facing the direction of travel), seen through ``rows`` scan lines while the car drives 1 m per frame
    down the middle -> (depth (frames, 1, H, W), K (3, 3), T_world_cam (frames, 4, 4))."""
    from dcslam.slam.scene import StreetScene, kitti_K, lidar_mask

    scene = StreetScene.__new__(StreetScene)   # the analytic street's ray caster, with these boxes
    scene.ground_y = 1.65
    boxes = [[4.0, -4.0, -20.0, 5.0, 1.65, 200.0], [-5.0, -4.0, -20.0, -4.0, 1.65, 200.0]]
    boxes += [[3.6, -3.0, z, 4.0, 1.65, z + 0.4] for z in np.arange(6.0, 200.0, 10.0)]
    scene.boxes = torch.tensor(boxes, dtype=torch.float64)
    K = kitti_K(H, W)
    T = torch.eye(4, dtype=torch.float64).repeat(frames, 1, 1)
    T[:, 2, 3] = torch.arange(frames, dtype=torch.float64)
    mask = lidar_mask(H, W, H // rows, 2)
    depth = torch.stack([scene.render(T[i], K, H, W, mask=mask) for i in range(frames)]).float()[:, None]
    return depth, K, T


def test_an_8_beam_drive_between_two_walls_is_flagged_along_the_road():
    """Eight scan lines see the walls and the road, which constrain everything but the direction of travel; the
    posts barely do. The run ends off along the road, and its summary says so and from which frame."""
    from dcslam.slam.config import SlamSettings, build_slam

    depth, K, T = _walled_road(8, 96, 320, 8)
    slam = build_slam(SlamSettings())
    poses = slam.run(depth, K)
    dt, _ = pose_error(poses.double(), T)
    error = (poses[-1, :3, 3].double() - T[-1, :3, 3]).abs()
    assert float(dt[-1]) > 0.5 and int(error.argmax()) == 2        # it drifted, along the road
    s = slam.health_summary()
    assert s["suspect"] and s["prediction"]["bound_m"] > 0.5 and 1 in s["prediction"]["frames"]
    assert s["prediction"]["direction"] == "along the road (camera z)" and s["prediction"]["from_frame"] is not None
    reason = [r for r in s["reasons"] if "left a direction degenerate" in r]
    assert reason and "along the road (camera z) left unconstrained, past 0.5 m from frame" in reason[0]


# --- steps held at the constant-velocity prediction (StepReport.held): the hold bound ------------------------------

#: A held direction: one metre along the camera's z (the direction of travel), and one across the road (x).
ALONG, ACROSS = [0, 0, 1.0, 0, 0, 0], [1.0, 0, 0, 0, 0, 0]
WEAK_WHY = ("weakly constrained (conditioning 1.0e-03), held at the prediction (along the road (camera z))",)


def _held_report(index, z, held, why=WEAK_WHY, covariance=None):
    """A degraded step at (0, 0, z) that held ``held`` (rows of 6) at the prediction (no other weakness unless ``why``
    says so); its covariance 1 mm in every direction unless given."""
    T = torch.eye(4, dtype=torch.float64)
    T[2, 3] = z
    C = np.diag([1e-6] * 3 + [1e-10] * 3) if covariance is None else covariance
    return StepReport(index, T, True, "", 0, 500, 0.0, 0, 0.0, "degraded", why,
                      covariance=torch.as_tensor(C, dtype=torch.float64),
                      held=torch.as_tensor(held, dtype=torch.float64).reshape(-1, 6))


def _measured(index, z):
    return _report(index, z, np.diag([1e-6] * 3 + [1e-10] * 3))


def _hold_run(steps: int, held=ALONG, measured: int = 1):
    """Frame 0, ``measured`` measured steps, then ``steps`` held ones, 1 m per frame."""
    reports = [_report(0, 0.0)] + [_measured(i, float(i)) for i in range(1, measured + 1)]
    return reports + [_held_report(i, float(i), [held]) for i in range(measured + 1, measured + 1 + steps)]


def test_a_hold_after_a_measured_velocity_grows_with_the_vehicles_acceleration():
    """The k-th held step misses k frames of the acceleration along the held direction: a_z dt^2 k, so 7 steps held
    along the road add (1 + ... + 7) x 1 m/s^2 x 0.01 s^2 and 2.5 sigma of that (0.70 m) is past 0.5 m, while 5
    (0.375 m) are not; the held steps are not counted as degraded (5 in a row would otherwise flag the run)."""
    seven, five = summarise(_hold_run(7)), summarise(_hold_run(5))
    assert seven["hold"]["bound_m"] == pytest.approx(2.5 * 0.01 * 28, rel=1e-6)
    assert five["hold"]["bound_m"] == pytest.approx(2.5 * 0.01 * 15, rel=1e-6)
    assert not five["suspect"] and five["held"] == 5 and five["degraded"] == 5 and five["reasons"] == []
    assert seven["suspect"] and len(seven["reasons"]) == 1
    reason = seven["reasons"][0]
    assert reason.startswith("7 steps held at the constant-velocity prediction (frames 2-8)")
    assert "along the road (camera z) held" in reason and "the vehicle's acceleration" in reason
    assert seven["hold"]["held"] == ["along the road (camera z)"] and seven["hold"]["frames"] == list(range(2, 9))
    assert seven["flagged_steps"][0]["held"] == ["along the road (camera z)"]
    assert json.loads(json.dumps(seven))["hold"] == seven["hold"]


def test_a_car_barely_changes_its_sideways_velocity():
    """Across the road the acceleration is a fifth of the forward one (0.2 m/s^2): 7 steps held there stay far
    inside 0.5 m."""
    s = summarise(_hold_run(7, ACROSS))
    assert s["hold"]["bound_m"] == pytest.approx(2.5 * 0.2 * 0.01 * 28, rel=1e-6) and not s["suspect"]
    assert s["hold"]["direction"] == "across the road (camera x)"


def test_a_hold_before_any_velocity_counts_as_degraded():
    """Held from the first step, the prediction is no motion and misses the vehicle's whole motion: those steps are
    not modelled by the hold bound but counted as degraded, as before (two of them in a row flag the run); once a
    step has measured a velocity, a later hold is the bound's."""
    s = summarise(_hold_run(2, measured=0))
    assert s["hold"]["steps"] == 0 and s["held"] == 0 and s["reasons"] == ["2 of 2 steps degraded (more than 10%)",
                                                                           "2 consecutive steps degraded"]
    late = _hold_run(2, measured=0) + [_measured(3, 3.0)] + [_held_report(i, float(i), [ALONG]) for i in (4, 5)]
    assert summarise(late)["hold"]["frames"] == [4, 5] and summarise(late)["held"] == 2


def test_the_frame_interval_scales_the_hold():
    """At 30 Hz the same 7 held steps last a third of the time: dt^2 is a ninth."""
    s = summarise(_hold_run(7), interval_s=1 / 30)
    assert s["hold"]["bound_m"] == pytest.approx(2.5 * 28 / 900, abs=1e-4) and not s["suspect"]
    assert s["hold"]["interval_s"] == pytest.approx(1 / 30, rel=1e-5)


def test_a_measured_step_ends_the_hold_and_a_rejected_one_continues_it():
    broken = _hold_run(4) + [_measured(6, 6.0)] + [_held_report(i, float(i), [ALONG]) for i in (7, 8, 9)]
    assert summarise(broken)["hold"]["bound_m"] == pytest.approx(2.5 * 0.01 * (10 + 6), rel=1e-6)
    rejected = _report(6, 6.0, verdict="rejected")
    continued = _hold_run(4) + [rejected] + [_held_report(i, float(i), [ALONG]) for i in (7, 8, 9)]
    assert summarise(continued)["hold"]["bound_m"] == pytest.approx(2.5 * 0.01 * (10 + 6 + 7 + 8), rel=1e-6)


def test_a_held_step_with_another_weakness_is_still_degraded():
    few = ("90 of 900 points paired (fewer than 100 pairs)",) + WEAK_WHY
    reports = _hold_run(1, measured=20) + [_held_report(22, 22.0, [ALONG], few)]
    s = summarise(reports)
    assert s["held"] == 1 and s["degraded"] == 2 and not s["suspect"]
    assert summarise(reports + [_held_report(23, 23.0, [ALONG], few)])["reasons"] == ["2 consecutive steps degraded"]


def test_a_mostly_rotational_hold_is_judged_as_a_degraded_step():
    """The bound models a vehicle's translation: a step that held a direction that is mostly a rotation (a yaw at
    10 m: the unit direction's translation part 0.4, under half) counts as degraded, as before holds were modelled."""
    yaw = [0.4, 0, 0, 0, 0.0917, 0]                    # (v_t, v_w) with |v_t|^2 + (10 |v_w|)^2 = 1
    reports = _hold_run(2, [yaw], measured=20)
    s = summarise(reports)
    assert s["held"] == 0 and s["hold"]["steps"] == 0 and s["reasons"] == ["2 consecutive steps degraded"]
    assert s["flagged_steps"][0]["held"] == ["rotation about camera y"]


def test_a_held_direction_adds_nothing_to_the_drift_bound():
    """The pairs' covariance of a held step says metres along the direction it held (the pairs do not constrain it);
    the pose there is the prediction's, so the drift bound conditions it away and the hold bound carries it."""
    C = np.diag([1e-6, 1e-6, 4.0, 1e-10, 1e-10, 1e-10])       # 2 m along the road: what J^T J's inverse says there
    loose = [_report(0, 0.0), _measured(1, 1.0)] + [_report(i, float(i), C) for i in (2, 3, 4)]
    held = [_report(0, 0.0), _measured(1, 1.0)] + [_held_report(i, float(i), [ALONG], covariance=C) for i in (2, 3, 4)]
    assert drift_bound(loose)["bound_m"] > 10
    assert drift_bound(held)["bound_m"] < 0.02


def test_a_degenerate_direction_needs_few_pairs_as_well_as_a_small_share():
    """A share of 1.5 % of a dense frame's 5,000 pairs is 75 pairs' worth of normals facing the direction: measured,
    no prior added and the bound not counted; of 200 pairs, 3 pairs' worth: degenerate."""
    def information(pairs):
        H = np.zeros((6, 6))
        H[0, 0], H[1, 1], H[2, 2] = 0.5 * pairs, 0.485 * pairs, 0.015 * pairs
        H[3:, 3:] = np.eye(3) * pairs
        return H
    C = np.diag([1e-6] * 3 + [1e-10] * 3)
    dense = [_report(0, 0.0)] + [_report(i, float(i), C, information(5000)) for i in (1, 2)]
    sparse = [_report(0, 0.0)] + [_report(i, float(i), C, information(200)) for i in (1, 2)]
    assert step_degeneracy(information(5000))["translation_pairs"] == pytest.approx(75)
    d, s = summarise(dense), summarise(sparse)
    assert d["drift"]["degenerate_frames"] == [] and not d["drift"]["counted"] and d["drift"]["bound_m"] < 0.01
    assert d["prediction"]["frames"] == [] and d["prediction"]["bound_m"] == 0.0
    assert s["drift"]["degenerate_frames"] == [1, 2] and s["prediction"]["frames"] == [1, 2]
    assert s["prediction"]["bound_m"] == pytest.approx(2.5 * 0.55, rel=1e-2) and s["suspect"]


def test_without_the_hold_bound_held_steps_count_as_degraded():
    """``hold_bound`` off is the rule before it: the 5 held steps the bound clears are 5 degraded ones in a row."""
    s = summarise(_hold_run(5), HealthRules(hold_bound=False))
    assert s["suspect"] and "5 consecutive steps degraded" in s["reasons"] and s["held"] == 0
    assert s["hold"]["steps"] == 0 and s["hold"]["bound_m"] == 0.0
