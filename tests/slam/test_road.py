"""The road figure (dcslam.slam.road) and its rule in the health verdict (dcslam.slam.health): known answers on
synthetic road planes, and the verdict it gives."""
import json
import math

import numpy as np
import pytest
import torch

from dcslam.slam.health import HealthRules, summarise
from dcslam.slam.pipeline import StepReport
from dcslam.slam.road import fit_road, frame_road, road_corrected, road_drift
from tests.fixtures.road import HEIGHT, pose, step_reports, seen, sinking

def test_the_road_corrected_trajectory_of_a_sinking_run_is_the_truth():
    truth, estimated = sinking()
    corrected = road_corrected(estimated, [seen(T) for T in truth])
    assert np.allclose(corrected, truth, atol=1e-9)                  # height and pitch from the road, the rest kept
    assert np.allclose(road_corrected(estimated, [None] * len(truth)), estimated)   # no road: as estimated
    pitched = np.stack([pose(float(k), pitch_rad=0.002 * k) for k in range(len(truth))])
    assert np.allclose(road_corrected(pitched, [seen(T) for T in truth])[:, :3, :3], truth[:, :3, :3], atol=1e-9)


def test_a_run_sinking_by_steps_is_measured_by_the_road():
    truth, estimated = sinking()
    road = road_drift(estimated, [seen(T) for T in truth], over_m=0.5)
    assert road["drift_m"] == pytest.approx(0.63, abs=1e-9) and road["vertical"] == "sank"
    assert road["from_frame"] == 24                                  # 0.021 m x 24 > 0.5 m, x 23 is not
    assert road["frames_seen"] == 31 and road["frames_skipped"] == 0
    rising = road_drift(truth, [seen(T) for T in estimated])        # the truth, against planes of a sunk camera
    assert rising["drift_m"] == pytest.approx(0.63, abs=1e-9) and rising["vertical"] == "rose"


def test_a_pitch_drift_is_measured_as_the_height_it_costs():
    """Each step pitches the estimate 0.05 deg nose-down more than the truth: after 20 steps of 1 m it has sunk by
    sum_{j < 20} sin(0.05 deg j) (each step drives forward along the pitch of the frame it leaves)."""
    frames, step = 21, math.radians(0.05)
    truth = np.stack([pose(float(k)) for k in range(frames)])
    estimated = [pose(0.0)]
    for k in range(1, frames):
        rel = np.linalg.solve(truth[k - 1], truth[k])
        estimated.append(estimated[-1] @ rel @ pose(0.0, pitch_rad=-step))
    estimated = np.stack(estimated)
    sank = float((estimated[-1, :3, 3] - truth[-1, :3, 3]) @ np.array([0.0, 1.0, 0.0]))
    assert sank == pytest.approx(sum(math.sin(step * j) for j in range(frames - 1)), rel=1e-6) and sank > 0.1
    road = road_drift(estimated, [seen(T) for T in truth])
    assert road["drift_m"] == pytest.approx(sank, abs=1e-4) and road["vertical"] == "sank"


def test_a_consistent_run_gives_nothing_and_frames_without_road_are_skipped():
    truth, _ = sinking()
    assert road_drift(truth, [seen(T) for T in truth])["drift_m"] == pytest.approx(0.0, abs=1e-9)
    truth, estimated = sinking(frames=11)
    planes = [seen(T) for T in truth]
    planes[4] = planes[5] = None                     # steps 3-4, 4-5 and 5-6 taken as estimated: 3 x 0.021 m stay
    road = road_drift(estimated, planes, over_m=0.5)
    assert road["frames_seen"] == 9 and road["frames_skipped"] == 2
    assert road["drift_m"] == pytest.approx(0.021 * 7, abs=1e-9) and road["from_frame"] is None


def test_the_road_plane_of_a_vertex_map():
    """A flat road 1.6 m below the camera, seen in a vertex map with a wall beside it and noise of 2 cm: the plane
    is found within a centimetre; a vertex map without returns below the camera has no road."""
    rng = np.random.default_rng(3)
    x, z = rng.uniform(-8, 8, 5000), rng.uniform(4, 28, 5000)
    road = np.stack([x, HEIGHT + rng.normal(0, 0.02, 5000), z], 1)
    wall = np.stack([np.full(3000, 4.0), rng.uniform(-3, HEIGHT, 3000), rng.uniform(4, 28, 3000)], 1)
    vertex = np.concatenate([road, wall, np.zeros((2000, 3))])          # zeros: pixels without depth
    plane = frame_road(torch.from_numpy(vertex).float().reshape(100, 100, 3))
    assert plane is not None and plane.normal @ [0, -1, 0] > math.cos(math.radians(0.5))
    assert plane.offset == pytest.approx(HEIGHT, abs=0.01) and plane.inliers >= 1000
    assert frame_road(np.where(vertex[:, 1:2] > 0.8, 0.0, vertex)) is None
    assert fit_road(road[:10]) is None


def test_a_sinking_run_is_flagged_with_the_road_reason():
    truth, estimated = sinking()
    s = summarise(step_reports(estimated, [seen(T) for T in truth]))
    assert s["suspect"]
    assert ("the road says the run sank 0.63 m (vertical, camera y), past 0.5 m from frame 24 (road seen in 31 of "
            "31 frames)") in s["reasons"]
    assert s["road"] == {"drift_m": 0.63, "vertical": "sank", "frames_seen": 31, "frames_skipped": 0,
                         "from_frame": 24}
    assert json.loads(json.dumps(s))["road"] == s["road"]             # written as is in the run's summary
    assert not summarise(step_reports(truth, [seen(T) for T in truth]))["suspect"]
    assert summarise(step_reports(estimated, [seen(T) for T in truth]), HealthRules(max_road_drift_m=0))["road"] is None


def test_the_drift_bound_counts_only_where_a_step_is_degenerate():
    """Steps of 5 cm standard deviation, well measured in every direction (their information an even share each):
    the bound exceeds 0.5 m and is written, but only degenerate steps would make the run suspect: by the
    prediction's uncertainty along what they left degenerate (the rule), or, with ``prediction_bound`` off, by the
    whole bound then counted (the previous rule)."""
    C, H = np.diag([0.05 ** 2] * 3 + [1e-10] * 3), np.eye(6)
    estimated = np.stack([pose(float(k)) for k in range(8)])
    reports = [StepReport(i, torch.from_numpy(T), True, "", 0, 0, 0.0, 0, 0.0, covariance=torch.from_numpy(C),
                          information=torch.from_numpy(H)) for i, T in enumerate(estimated)]
    s = summarise(reports)
    assert s["drift"]["bound_m"] > 0.5 and s["drift"]["counted"] is False and not s["suspect"]
    assert s["drift"]["weakest_share"] == pytest.approx(1 / 3, abs=1e-5)
    H_corridor = np.diag([1.0, 1.0, 0.001, 1.0, 1.0, 1.0])           # a share of 0.0005 along the road
    for r in reports[1:]:
        r.information = torch.from_numpy(H_corridor)
    s = summarise(reports)
    assert s["drift"]["counted"] is False and s["suspect"] and s["prediction"]["frames"] == list(range(1, 8))
    assert s["prediction"]["bound_m"] == pytest.approx(2.5 * (0.5 + 6 * 0.05), rel=1e-6)
    previous = summarise(reports, HealthRules(prediction_bound=False))
    assert previous["drift"]["counted"] is True and previous["suspect"]
    assert "along the road (camera z) left unconstrained" in s["reasons"][0]
