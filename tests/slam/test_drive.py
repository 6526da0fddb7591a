"""The drive loop as library code: frames in (any iterable, no files), trajectory, map and summary out."""
import numpy as np
import pytest

from dcslam.io.drive import DriveFile
from dcslam.io.drive_frames import DepthFrame, DriveFrames, drive_frames
from dcslam.slam.config import SlamSettings, build_slam
from dcslam.slam.drive import ConfidenceUse, companion_verdict, run_drive
from tests.fixtures.street import write_analytic_street

H, W, N = 32, 112, 4


def run_drive_file(path, source):
    with drive_frames(path, source) as frames:
        return run_drive(frames, build_slam(SlamSettings()))


def test_frames_from_memory_give_the_run_of_the_drive_file(tmp_path, monkeypatch):
    """A run over frames held in memory (a list, read on the prefetch thread) is the file-backed run, bit for bit;
    the confidence is applied as ConfidenceUse says and the kept fraction recorded."""
    from dcslam.workers import SHARED_CORES

    monkeypatch.delenv(SHARED_CORES, raising=False)  # as a command run on its own: with the prefetch thread
    path = tmp_path / "street.h5"
    write_analytic_street(path, N, H, W)
    with DriveFile(path) as d:
        dense = [d.depth("dense", i) for i in range(N)]
        frames = [DepthFrame(dense[i], d.rgb(i), np.full((H, W), 0.25 + 0.25 * i, np.float32)) for i in range(N)]
        drive = DriveFrames(str(path), d.name, d.K, d.poses.copy(), d.timestamps.copy(), True, iter(frames))
    use = ConfidenceUse("mask", 0.5)
    run = run_drive(drive, build_slam(SlamSettings()), confidence=use)
    measured = [int((d > 0).sum()) for d in dense]  # frame 0 (confidence 0.25) dropped, the others kept whole
    assert run.confidence == {**use.record(True), "kept_fraction": round(sum(measured[1:]) / sum(measured), 4)}
    assert len(run.reports) == N and np.isfinite(run.T_world_cam).all()

    plain = run_drive(DriveFrames(str(path), "street", drive.K, drive.T_world_cam, drive.timestamps, False,
                                  iter([DepthFrame(f.depth, f.rgb) for f in frames])), build_slam(SlamSettings()))
    from_file = run_drive_file(path, "dense")
    assert np.array_equal(plain.T_world_cam, from_file.T_world_cam)
    assert [r.iterations for r in plain.reports] == [r.iterations for r in from_file.reports]
    assert plain.summary()["points"] == from_file.summary()["points"]


def test_too_few_frames_is_an_error_naming_the_drive(tmp_path):
    from dcslam.errors import DcslamError

    T = np.stack([np.eye(4)] * 3)
    frame = DepthFrame(np.ones((H, W), np.float32), np.zeros((H, W, 3), np.uint8))
    drive = DriveFrames("memory", "m", np.array([[50.0, 0, W / 2], [0, 50.0, H / 2], [0, 0, 1]]), T,
                        np.arange(3.0), False, iter([frame, frame]))
    with pytest.raises(DcslamError, match="memory: fewer frames than its poses"):
        run_drive(drive, build_slam(SlamSettings(odometry="gt")))


def test_the_companion_verdict_carries_the_companions_error_and_time(tmp_path):
    path = tmp_path / "street.h5"
    write_analytic_street(path, N, H, W)
    main = run_drive_file(path, "dense")
    companion = run_drive_file(path, "sparse")
    verdict = companion_verdict(main, companion, "sparse")
    final = np.linalg.norm(companion.T_world_cam[-1, :3, 3] - companion.T_gt[-1, :3, 3])
    assert verdict["companion_final_error_m"] == round(float(final), 4)
    assert verdict["companion_seconds"] == round(companion.seconds, 3)
    assert verdict["companion"] == "sparse" and verdict["verdict"] in ("agrees", "departs", "unbounded")


def test_a_companion_that_sank_is_road_corrected_before_it_judges():
    """A companion that sinks 0.021 m a step ends 0.63 m below the truth: its road rule makes it suspect, and it would
    bound nothing. Corrected by the road planes of its own frames it is the truth again, and vouches for a main run
    that drove the truth; without the road rule it is left as run."""
    from dataclasses import replace

    from dcslam.slam.drive import DriveRun
    from dcslam.slam.health import HealthRules

    from tests.fixtures.road import step_reports, seen, sinking

    truth, sunk = sinking()
    planes = [seen(T) for T in truth]
    stamps = np.arange(len(truth)) * 0.1

    def run(T, reports, rules=None):
        return DriveRun("d", T, stamps, truth, None, reports, 1.0, health_rules=rules)

    main = run(truth, step_reports(truth, planes))
    verdict = companion_verdict(main, run(sunk, step_reports(sunk, planes)), "sparse@8")
    assert verdict["verdict"] == "agrees" and verdict["road_corrected"] and verdict["gap_m"] < 1e-6
    assert verdict["companion_final_error_m"] == pytest.approx(0.63, abs=1e-3)
    assert verdict["companion_corrected_error_m"] < 1e-6
    no_road = replace(HealthRules(), max_road_drift_m=0.0)
    as_run = companion_verdict(main, run(sunk, step_reports(sunk, planes), no_road), "sparse@8")
    assert not as_run["road_corrected"] and as_run["verdict"] == "departs"
    assert as_run["gap_m"] == pytest.approx(0.63, abs=1e-3)
