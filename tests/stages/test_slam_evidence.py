"""A completed depth that is wrong in a consistent way (the exact depth scaled by 1.2: every step pairs thousands of
points with a tight covariance and agrees with the motion prediction, yet the trajectory stretches) is trusted by
the per-step checks and caught by the companion run on the measured pixels."""
import json

import numpy as np
import pytest

from dcslam.io.drive import DriveFile, Layer, load_depth, write_layer
from dcslam.io.slam_summary import read_verdict
from dcslam.stages import slam
from dcslam.workspace import Workspace
from tests.fixtures.street import write_analytic_street

H, W, N = 96, 320, 8


@pytest.fixture(scope="module")
def scaled(tmp_path_factory):
    """(workspace, drive file, layer folder): an 8-frame street at 0.8 m per frame and a layer of its dense depth
    times 1.2 that says it completed the drive's sparse depth."""
    root = tmp_path_factory.mktemp("evidence")
    path = root / "street.h5"
    write_analytic_street(path, N, H, W, step=0.8)
    with DriveFile(path) as drive:
        dense = load_depth(drive, "dense")
    layer = root / "layer"
    layer.mkdir()
    write_layer(layer / "street.h5", Layer(depth=(1.2 * dense).astype(np.float32), drive="street",
                                           made_by="test", config={"input": "sparse"}))
    return Workspace(root / "ws"), path, layer


def _run(ws, path, layer, out, evidence):
    return slam.run(ws, slam.SlamStageConfig(depth=str(layer), drive=[str(path)], out=out, evidence=evidence))[0]


def test_consistently_wrong_completion_is_flagged_by_its_companion(scaled, tmp_path, capsys):
    from dcslam.cli.slam import report

    ws, path, layer = scaled
    alone = _run(ws, path, layer, tmp_path / "none", "none")
    health = alone.summary["health"]
    assert alone.summary["translation_error_m"]["final"] > 0.5
    assert not health["suspect"] and health["accepted"] == N - 1 and health["evidence"]["verdict"] == "off"
    assert not read_verdict(alone.written["summary"]).suspect  # what every table reads

    checked = _run(ws, path, layer, tmp_path / "auto", "auto")
    health = checked.summary["health"]
    evidence = health["evidence"]
    assert health["suspect"] and evidence["verdict"] == "departs" and evidence["companion"] == "sparse"
    assert evidence["gap_m"] > evidence["bound_m"] and evidence["companion_final_error_m"] < 0.5
    assert health["reasons"][-1].startswith(f"ends {evidence['gap_m']:.2f} m from the sparse companion "
                                            "(road-corrected), past the bound from frame")
    assert np.allclose(checked.summary["translation_error_m"]["final"], alone.summary["translation_error_m"]["final"])
    written = json.loads(checked.written["summary"].read_text())
    assert written["health"]["suspect"] and written["health"]["evidence"]["verdict"] == "departs"
    verdict = read_verdict(checked.written["summary"])
    assert verdict.suspect and evidence["reason"] in verdict.reasons

    report([alone, checked])
    lines = capsys.readouterr().out.splitlines()
    assert "UNVERIFIED (no evidence bounds the drift (--evidence none))" in lines[0]
    assert f"SUSPECT ({evidence['reason']})" in lines[1]


def test_a_sparse_input_is_its_own_evidence_and_a_foreign_layer_has_none(scaled, tmp_path, capsys):
    from dcslam.cli.slam import report

    ws, path, layer = scaled
    own = _run(ws, path, "sparse", tmp_path / "sparse", "auto")
    assert own.summary["health"]["evidence"]["verdict"] == "own"
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    with DriveFile(path) as drive:
        write_layer(foreign / "street.h5", Layer(depth=load_depth(drive, "dense"), drive="street", made_by="other"))
    unknown = _run(ws, path, foreign, tmp_path / "foreign-out", "auto")
    evidence = unknown.summary["health"]["evidence"]
    assert evidence["verdict"] == "unavailable" and not unknown.summary["health"]["suspect"]
    report([own, unknown])
    lines = capsys.readouterr().out.splitlines()
    # the fixture's colours are noise, unrelated to its depth: the camera measures no step and says so
    assert lines[0].split(", ")[-1].startswith("ok; the camera abstained: 0 of 7 steps measured from images ->")
    assert "UNVERIFIED (no evidence bounds the drift (" in lines[1] and "does not say which measured depth" in lines[1]


def test_the_companion_beside_the_main_run_gives_the_verdict_it_gives_after_it(scaled, tmp_path, monkeypatch):
    ws, path, layer = scaled
    evidences = {}
    for beside in (False, True):
        monkeypatch.setattr(slam, "companion_beside", lambda config, pixels, beside=beside: beside)
        run = _run(ws, path, layer, tmp_path / f"beside-{beside}", "auto")
        evidences[beside] = {k: v for k, v in run.summary["health"]["evidence"].items() if k != "companion_seconds"}
    assert evidences[True]["verdict"] == "departs"
    assert evidences[True] == evidences[False]


def test_a_companion_worker_that_dies_leaves_the_companion_to_this_process(scaled, tmp_path, monkeypatch, capfd):
    """A worker that dies (killed for memory, say: here it exits as it starts) breaks its pool; the companion runs in
    this process instead, to the verdict it gives there, and one line says so."""
    import multiprocessing
    import os
    from concurrent.futures import ProcessPoolExecutor

    ws, path, layer = scaled
    monkeypatch.setattr(slam, "companion_beside", lambda config, pixels: False)
    after = _run(ws, path, layer, tmp_path / "after", "auto").summary["health"]["evidence"]
    monkeypatch.setattr(slam, "companion_beside", lambda config, pixels: True)
    monkeypatch.setattr("dcslam.workers.process_pool", lambda jobs, tasks: ProcessPoolExecutor(
        1, mp_context=multiprocessing.get_context("spawn"), initializer=os._exit, initargs=(1,)))
    capfd.readouterr()
    died = _run(ws, path, layer, tmp_path / "died", "auto").summary["health"]["evidence"]
    assert "note: the companion worker of street.h5 stopped; running the companion in this process" in \
        capfd.readouterr().err
    assert died["verdict"] == "departs"
    assert {k: v for k, v in died.items() if k != "companion_seconds"} == \
        {k: v for k, v in after.items() if k != "companion_seconds"}


def test_the_companion_waits_for_the_main_run_where_no_core_is_free_or_the_run_is_short(monkeypatch):
    config, long = slam.SlamStageConfig(threads=1), slam.BESIDE_MIN_PIXELS
    monkeypatch.setattr(slam.OWN_LOAD, "read", lambda: 0.0)  # this test process's own load set aside
    monkeypatch.setattr("os.cpu_count", lambda: 2)
    monkeypatch.setattr("os.getloadavg", lambda: (0.2, 0.2, 0.2))
    monkeypatch.delenv("DCSLAM_SHARED_CORES", raising=False)
    assert slam.companion_beside(config, long)
    assert not slam.companion_beside(config, long - 1)      # the worker's start would cost more than it hides
    assert not slam.companion_beside(slam.SlamStageConfig(threads=2), long)
    assert not slam.companion_beside(slam.SlamStageConfig(threads=1, device="cuda"), long)
    monkeypatch.setenv("DCSLAM_SHARED_CORES", "1")         # a pool worker: its siblings keep every core busy
    assert not slam.companion_beside(config, long)
    monkeypatch.delenv("DCSLAM_SHARED_CORES")
    monkeypatch.setattr("os.getloadavg", lambda: (0.7, 0.2, 0.2))  # other work holds the second core
    assert not slam.companion_beside(config, long)
    monkeypatch.setattr("os.getloadavg", lambda: (0.2, 0.2, 0.2))
    monkeypatch.setattr("os.cpu_count", lambda: 1)
    assert not slam.companion_beside(config, long)
    monkeypatch.setattr("os.cpu_count", lambda: 2)
    monkeypatch.setattr("os.getloadavg", lambda: (1.3, 1.3, 1.3))
    assert not slam.companion_beside(config, long)          # another process keeps the second core busy
    monkeypatch.setattr(slam.OWN_LOAD, "read", lambda: 1.0)
    assert slam.companion_beside(config, long)              # ... unless the load is this command's own earlier work


def test_the_stage_tells_measured_depth_from_a_completion(scaled, tmp_path, monkeypatch):
    """Dense and exact depth are judged as measured depth (their own steps, when the companion is suspect); a layer
    as a completion."""
    import dcslam.slam.drive as drive_module

    ws, path, layer = scaled
    seen, real = [], drive_module.companion_verdict

    def spy(main, companion, kind, rules=None, measured=False):
        seen.append(measured)
        return real(main, companion, kind, rules, measured)

    monkeypatch.setattr(drive_module, "companion_verdict", spy)
    dense = _run(ws, path, "dense", tmp_path / "dense", "auto")
    _run(ws, path, layer, tmp_path / "layer", "auto")
    assert seen == [True, False] and dense.summary["health"]["evidence"]["companion"] == "sparse"
