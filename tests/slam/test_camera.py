"""The camera as a witness (dcslam.slam.camera): on a generated drive (textured street, moving cars, 8-beam returns)
each step started away from the truth comes back to it, a run that sank is measured by the camera's gap, a step with
no returns in view is left as estimated, and mismatched sizes are refused."""
from __future__ import annotations

import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.geometry.rotations import rotation_from_rpy
from dcslam.io.drive import DriveFile
from dcslam.slam.camera import (CameraRules, CameraStep, camera_gap, camera_step, camera_trajectory, grey_pyramid,
                                judge_camera, merge_camera, witness)
from tests.fixtures.street import write_generated_drive

FRAMES = 8


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    path = write_generated_drive(tmp_path_factory.mktemp("camera") / "2011_09_26_drive_7301_sync.h5", seed=7301,
                                 frames=FRAMES, beams=8)
    with DriveFile(path) as d:
        yield d


def truth(d) -> np.ndarray:
    return np.linalg.inv(d.poses[0]) @ d.poses[:FRAMES]


def nudge(T: np.ndarray, down_m: float, pitch_deg: float, along_m: float = 0.0) -> np.ndarray:
    """T (4, 4) moved by a motion in its own camera frame: down (camera y), forward (z), pitched about x."""
    M = np.eye(4)
    M[:3, :3] = rotation_from_rpy(np.radians(pitch_deg), 0.0, 0.0)
    M[:3, 3] = (0.0, down_m, along_m)
    return M @ T


def test_each_step_started_off_the_truth_comes_back_to_it(drive):
    T = truth(drive)
    errors = []
    for k in range(1, FRAMES):
        true_step = np.linalg.solve(T[k], T[k - 1])
        step = camera_step(grey_pyramid(drive.rgb(k - 1)), grey_pyramid(drive.rgb(k)), drive.depth("sparse@8", k - 1),
                           drive.K, nudge(true_step, 0.06, 0.4, 0.1))
        assert step.measured and step.returns > 200
        errors.append(np.linalg.solve(true_step, step.T)[:3, 3])
    errors = np.abs(np.array(errors))
    # started 0.06 m low, 0.1 m along and 0.4 degrees pitched (a 0.06 m height error at 9 m): back within 2 cm at
    # half size (a step that stayed would be 0.06-0.1 m off), a few millimetres on most steps
    assert errors.max() < 0.03 and np.median(errors) < 0.01, errors


def test_a_run_that_sank_is_measured_by_the_camera_gap(drive):
    T = truth(drive)
    run = T.copy()
    for k in range(1, FRAMES):                     # every step 0.08 m low, all in the first camera's down (y)
        run[k, 1, 3] += 0.08 * k
    camera, steps = witness(drive, "sparse@8", run)
    figure = camera_gap(run, camera, steps, over_m=0.3)
    assert np.linalg.norm(camera[-1, :3, 3] - T[-1, :3, 3]) < 0.05      # the camera's trajectory: the truth's
    assert figure["gap_m"] == pytest.approx(0.08 * (FRAMES - 1), abs=0.05)
    assert figure["direction"] == "vertical (camera y)"
    assert figure["from_frame"] == int(np.flatnonzero(np.linalg.norm(run[:, :3, 3] - camera[:, :3, 3], axis=1)
                                                       > 0.3)[0])
    assert figure["steps_measured"] == figure["steps"] == FRAMES - 1
    assert 0 < figure["sigma_m"] < 0.2
    tracked = camera_gap(T, *witness(drive, "sparse@8", T))
    assert tracked["gap_m"] < 0.05 and tracked["from_frame"] is None


def test_a_step_without_returns_is_left_as_estimated(drive):
    start = nudge(np.eye(4), 0.0, 0.0, 1.0)
    empty = np.zeros(drive.shape[1:], np.float32)
    step = camera_step(grey_pyramid(drive.rgb(0)), grey_pyramid(drive.rgb(1)), empty, drive.K, start)
    assert not step.measured and step.returns == 0
    np.testing.assert_array_equal(step.T, start)
    T = np.stack([np.eye(4), np.linalg.inv(start)])
    np.testing.assert_allclose(camera_trajectory(T, [step]), T)
    assert camera_gap(T, camera_trajectory(T, [step]), [step])["steps_measured"] == 0


def test_images_unrelated_to_the_depth_measure_no_step(drive):
    """Frame k+1's image replaced by noise: Gauss-Newton converges somewhere, but the grey levels do not agree at any
    pose (correlation about 0.05), so the step is left as estimated; the true next image agrees (about 0.97)."""
    T = truth(drive)
    true_step = np.linalg.solve(T[1], T[0])
    before, depth = grey_pyramid(drive.rgb(0)), drive.depth("sparse@8", 0)
    noise = np.random.default_rng(0).integers(0, 255, drive.rgb(1).shape, dtype=np.uint8)
    step = camera_step(before, grey_pyramid(noise), depth, drive.K, true_step)
    assert not step.measured
    np.testing.assert_array_equal(step.T, true_step)
    assert camera_step(before, grey_pyramid(drive.rgb(1)), depth, drive.K, true_step).measured


def test_depth_and_images_of_other_sizes_are_refused(drive):
    pyramid = grey_pyramid(drive.rgb(0))
    with pytest.raises(DcslamError, match="one size"):
        camera_step(pyramid, pyramid, np.ones((10, 10), np.float32), drive.K, np.eye(4))


def test_the_verdict_departs_past_the_gap_agrees_within_and_abstains_when_unmeasured(drive):
    T = truth(drive)
    sank = T.copy()
    sank[1:, 1, 3] += 0.1 * np.arange(1, FRAMES)                 # 0.7 m low at the end
    camera, steps = witness(drive, "sparse@8", sank)
    off = judge_camera(sank, camera, steps)
    assert off["verdict"] == "departs" and off["suspect"]
    assert off["reason"].startswith("the camera says the run ends 0.") and "vertical (camera y)" in off["reason"]
    on = judge_camera(T, camera, steps)
    assert on["verdict"] == "agrees" and not on["suspect"] and on["reason"] is None
    unmeasured = [CameraStep(s.T, s.covariance, 0, False) for s in steps]
    assert judge_camera(sank, camera, unmeasured)["verdict"] == "unmeasured"
    assert judge_camera(sank, camera, steps, CameraRules(max_gap_m=1.0))["verdict"] == "agrees"


def test_the_camera_overrules_the_other_reasons_when_it_agrees_and_adds_its_own_when_it_departs():
    health = {"suspect": True, "reasons": ["1 of 29 steps rejected (pose predicted, not measured)"], "rejected": 1}
    agrees = {"verdict": "agrees", "suspect": False, "reason": None, "gap_m": 0.1}
    merged = merge_camera(health, agrees)
    assert not merged["suspect"] and merged["reasons"] == [] and merged["overruled"] == health["reasons"]
    assert merged["camera"] is agrees and health["reasons"] == ["1 of 29 steps rejected (pose predicted, not measured)"]
    departs = {"verdict": "departs", "suspect": True, "reason": "the camera says the run ends 0.70 m off"}
    merged = merge_camera({"suspect": False, "reasons": []}, departs)
    assert merged["suspect"] and merged["reasons"] == [departs["reason"]]
    unmeasured = {"verdict": "unmeasured", "suspect": False, "reason": None}
    assert merge_camera(health, unmeasured)["reasons"] == health["reasons"]
    assert merge_camera(health, unmeasured)["suspect"]


def test_an_agreeing_camera_does_not_overrule_the_road_or_the_companion():
    """The camera starts from the run's own steps, so it outweighs their checks, not the independent witnesses."""
    road = "the road says the run rose 3.26 m (vertical, camera y), past 0.5 m from frame 26"
    companion = "ends 2.44 m from the sparse@8 companion (road-corrected), past the bound from frame 28"
    steps = "2 consecutive steps degraded"
    health = {"suspect": True, "reasons": [steps, road, companion],
              "evidence": {"verdict": "departs", "suspect": True, "reason": companion}}
    merged = merge_camera(health, {"verdict": "agrees", "suspect": False, "reason": None})
    assert merged["suspect"] and merged["reasons"] == [road, companion] and merged["overruled"] == [steps]
    agreeing = {**health, "reasons": [steps], "evidence": {"verdict": "agrees", "suspect": False, "reason": None}}
    assert not merge_camera(agreeing, {"verdict": "agrees", "suspect": False, "reason": None})["suspect"]


def test_a_run_that_jumps_does_not_take_the_camera_along(drive):
    """A run whose third step dropped 1 m: each camera step after the first starts from the camera's own previous
    one, so the camera stays on the truth and its gap is the drop. (Started from the run's own steps, as it was
    first built, the camera ended 0.64 m off here: taken along.)"""
    T = truth(drive)
    run = T.copy()
    run[3:, :3, 3] += T[3, :3, :3] @ np.array([0.0, 1.0, 0.0])        # 1 m down frame 3's camera y
    camera, steps = witness(drive, "sparse@8", run)
    assert np.linalg.norm(camera[-1, :3, 3] - T[-1, :3, 3]) < 0.05
    figure = judge_camera(run, camera, steps)
    assert figure["gap_m"] == pytest.approx(1.0, abs=0.05) and figure["from_frame"] == 3
    assert figure["direction"] == "vertical (camera y)"
