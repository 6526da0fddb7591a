"""The scripts under benchmarks/ call dcslam, and no other test runs them: every name they import from dcslam (at the
top or inside a function, where a removed name only fails when the script runs) and from each other must exist."""
from __future__ import annotations

import ast
import importlib
import importlib.util
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
SCRIPTS = sorted(BENCHMARKS.glob("*.py"))


def imported_names(tree: ast.AST) -> list[tuple[str, str | None, int]]:
    """``(module, name or None, line)`` of every ``import`` and ``from … import`` in ``tree``, at any depth."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and not node.level:
            found += [(node.module, alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.Import):
            found += [(alias.name, None, node.lineno) for alias in node.names]
    return found


def missing(module: str, name: str | None) -> str | None:
    """What of ``from module import name`` (``import module`` when ``name`` is None) does not exist, or None."""
    try:
        loaded = importlib.import_module(module)
    except ModuleNotFoundError as exc:
        return f"module {exc.name}"
    if name is None or name == "*" or hasattr(loaded, name):
        return None
    try:
        importlib.import_module(f"{module}.{name}")  # a submodule
    except ModuleNotFoundError:
        return f"{module}.{name}"
    return None


def sibling_missing(module: str, name: str) -> str | None:
    """What of ``from <benchmark script> import name`` does not exist (the scripts import each other by file name)."""
    tree = ast.parse((BENCHMARKS / f"{module}.py").read_text())
    defined = {node.name for node in tree.body if isinstance(node, (ast.FunctionDef, ast.ClassDef))}
    for node in tree.body:
        targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(
            node, ast.AnnAssign) else []
        defined |= {t.id for t in targets if isinstance(t, ast.Name)}
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            defined |= {(alias.asname or alias.name).split(".")[0] for alias in node.names}
    return None if name in defined else f"{module}.{name}"


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.stem)
def test_every_dcslam_name_a_benchmark_imports_exists(script):
    siblings = {p.stem for p in SCRIPTS}
    problems = []
    for module, name, line in imported_names(ast.parse(script.read_text())):
        if module.split(".")[0] == "dcslam":
            gone = missing(module, name)
        elif module in siblings and name is not None:
            gone = sibling_missing(module, name)
        else:
            continue
        if gone:
            problems.append(f"{script.name}:{line}: {gone} does not exist")
    assert not problems, "\n".join(problems)


def test_the_check_finds_a_removed_name(tmp_path):
    """The check fails where it should: a name dcslam does not have, a module it does not have, a sibling's name."""
    assert missing("dcslam.slam.health", "summarise") is None and missing("dcslam.slam", "health") is None
    assert missing("dcslam.slam.health", "no_such_function") == "dcslam.slam.health.no_such_function"
    assert missing("dcslam.no_such_module", None) == "module dcslam.no_such_module"
    assert sibling_missing("slam_drives", "score") is None
    assert sibling_missing("slam_drives", "no_such_function") == "slam_drives.no_such_function"
    tree = ast.parse("def f():\n    from dcslam.slam.drive import run_drive\n")
    assert imported_names(tree) == [("dcslam.slam.drive", "run_drive", 2)]  # inside a function too


def test_bench_slam_counts_the_fastest_repeat_and_says_when_repeats_disagree(capsys):
    """``bench_slam.py --repeat``: a run's figures are its fastest repeat's, with every repeat's CPU seconds and the
    largest peak memory; repeats whose ATE differ are reported."""
    spec = importlib.util.spec_from_file_location("bench_slam", BENCHMARKS / "bench_slam.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    repeats = [{"cpu_s": 2.0, "ate_m": 0.1, "peak_rss_mb": 300.0, "frames": 30},
               {"cpu_s": 1.5, "ate_m": 0.1, "peak_rss_mb": 310.0, "frames": 30},
               {"cpu_s": 1.8, "ate_m": 0.1, "peak_rss_mb": 305.0, "frames": 30}]
    best = bench.fastest(repeats, "dcslam on sparse of drive 1000")
    assert best["cpu_s"] == 1.5 and best["cpu_s_repeats"] == [2.0, 1.5, 1.8] and best["peak_rss_mb"] == 310.0
    assert capsys.readouterr().err == ""
    bench.fastest([{**repeats[0], "ate_m": 0.2}, repeats[1]], "KISS-ICP on velodyne 360 of drive 1001")
    assert "KISS-ICP on velodyne 360 of drive 1001: the repeats' ATE differ (0.200000, 0.100000)" in \
        capsys.readouterr().err


@pytest.mark.parametrize("script", sorted(BENCHMARKS.glob("bench_*.py")), ids=lambda p: p.stem)
def test_every_bench_script_takes_the_options_make_bench_hands_to_all(script):
    """``run_all.py`` (``make bench BENCH_ARGS=...``) passes the same options to every ``bench_*.py``: each must parse
    the options it knows and leave the others (``parse_known_args``), or one script's option stops another."""
    calls = [node.func.attr for node in ast.walk(ast.parse(script.read_text()))
             if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
             and node.func.attr in ("parse_args", "parse_known_args")]
    assert calls and set(calls) == {"parse_known_args"}, f"{script.name} parses with {calls}"


def test_bench_slam_gives_the_sparse_ratio_drive_by_drive_beside_kiss_icps_error():
    """The ratio over all drives can rest on a drive KISS-ICP loses (it then iterates to its cap): each drive's
    ratio is printed with KISS-ICP's ATE there, and every ratio says whether it reaches the 1.5 x target."""
    spec = importlib.util.spec_from_file_location("bench_slam", BENCHMARKS / "bench_slam.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    results = {("dcslam", "sparse"): [{"frames": 30, "cpu_s": 1.0, "drive": "d0"},
                                      {"frames": 30, "cpu_s": 2.0, "drive": "d1"}],
               ("KISS-ICP", "velodyne 360"): [{"frames": 30, "cpu_s": 2.0, "ate_m": 1.2, "drive": "d0"},
                                             {"frames": 30, "cpu_s": 10.0, "ate_m": 13.5, "drive": "d1"}]}
    assert bench.sparse_ratios(results, "dcslam") == \
        "4.00 (meets 1.5) over all drives; 2.00 (meets 1.5) on d0 (KISS-ICP ATE 1.200 m), 5.00 (meets 1.5) on d1 " \
        "(KISS-ICP ATE 13.500 m)"
    results["dcslam", "sparse"][0]["cpu_s"] = 1.5        # 20 frames per CPU-second against KISS-ICP's 15
    assert bench.sparse_ratios(results, "dcslam").split("; ")[1].startswith("1.33 (BELOW 1.5) on d0")


def test_bench_slam_runs_kiss_icp_on_its_own_threads_too_as_the_peer_of_dcslams_default():
    """dcslam's default row runs a prefetch thread beside its frame loop; its like-for-like peer is KISS-ICP as its
    users run it (registration on every core, ``threads=0``), a row of its own beside the one-thread one, and the
    ratio names the row it was taken against."""
    from argparse import Namespace
    from pathlib import Path

    spec = importlib.util.spec_from_file_location("bench_slam", BENCHMARKS / "bench_slam.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    args = Namespace(open3d_completed=[], open3d_completed_drives=0)
    drive = Path("d0.h5")
    layers = {("d0", row): Path(f"d0.{row}.h5") for row in bench.COMPLETERS}
    kiss = [t[0] for t in bench._tasks(args, [drive], layers, kiss=True) if t[1] == "velodyne 360"]
    assert kiss == ["KISS-ICP", bench.KISS_THREADS]
    assert not [t for t in bench._tasks(args, [drive], layers, kiss=False) if t[1] == "velodyne 360"]
    assert bench.CHILD[bench.KISS_THREADS] == "kissicp0"
    results = {("dcslam", "sparse"): [{"frames": 30, "cpu_s": 1.0, "drive": "d0"}],
               ("KISS-ICP", "velodyne 360"): [{"frames": 30, "cpu_s": 2.0, "ate_m": 1.2, "drive": "d0"}],
               (bench.KISS_THREADS, "velodyne 360"): [{"frames": 30, "cpu_s": 1.2, "ate_m": 1.2, "drive": "d0"}]}
    assert bench.sparse_ratios(results, "dcslam", bench.KISS_THREADS).startswith("1.20 (BELOW 1.5) over all drives")
    assert bench.sparse_ratios(results, "dcslam").startswith("2.00 (meets 1.5) over all drives")


def test_slam_evidence_judges_measured_depth_by_its_own_steps_when_its_companion_is_suspect():
    """``slam_evidence.py`` judges stored runs as ``dcslam slam`` does: a dense run whose sparse companion is suspect
    is judged by its own steps, a completion (a layer) beside the same companion is unbounded."""
    import numpy as np

    spec = importlib.util.spec_from_file_location("slam_evidence", BENCHMARKS / "slam_evidence.py")
    evidence = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(evidence)
    T = np.tile(np.eye(4), (3, 1, 1))

    def run(source, suspect=False):
        health = {"suspect": suspect, "reasons": ["1 of 2 steps rejected"] if suspect else [], "accepted": 2,
                  "degraded": 0, "rejected": int(suspect), "drift_sigma_m": 0.01}
        return {"record": {"health": health, "settings": {"source": source},
                           "translation_error_m": {"final": 0.1, "max": 0.1}}, "T": T}

    runs = {("sparse", "d"): run("sparse", suspect=True), ("dense", "d"): run("dense"),
            ("ip-basic-fast-sparse64", "d"): run("not-a-file.h5")}
    assert evidence.measured_depth(runs[("dense", "d")]["record"])
    assert not evidence.measured_depth(runs[("ip-basic-fast-sparse64", "d")]["record"])
    rows = {r["layer"]: r for r in evidence.verdicts(runs, None, evidence.EvidenceRules())}
    assert rows["dense"]["evidence"] == "own" and not rows["dense"]["flagged"]
    assert rows["ip-basic-fast-sparse64"]["evidence"] == "unbounded" and rows["ip-basic-fast-sparse64"]["flagged"]


def test_slam_evidence_lowers_the_floor_by_the_stored_gaps():
    """``--stored-floors``: a completion that agrees with its companion as stored departs when its stored gap exceeds
    the lowered floor (or the companion's sigma bound), and is flagged; every other row stays as stored."""
    spec = importlib.util.spec_from_file_location("slam_evidence", BENCHMARKS / "slam_evidence.py")
    evidence = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(evidence)

    def row(layer, final, gap, verdict="agrees", sigma=0.01, flagged=False):
        return {"layer": layer, "input": layer, "beams": "64", "final_m": final, "gap_m": gap, "evidence": verdict,
                "companion_sigma_m": sigma, "flagged": flagged, "reasons": []}

    rows = [row("near", 0.51, 0.485), row("below", 0.40, 0.47), row("sigma", 0.6, 0.49, sigma=0.17),
            row("departs", 0.7, 0.6, "departs", flagged=True), row("sparse", 0.2, None, "own")]
    moved = {r["layer"]: r for r in evidence.moved_floor(rows, 0.48)}
    assert moved["near"]["flagged"] and moved["near"]["evidence"] == "departs" and "floor 0.48 m" in moved["near"][
        "reasons"][0]
    assert not moved["below"]["flagged"] and moved["below"]["evidence"] == "agrees"
    assert not moved["sigma"]["flagged"]            # 3 x 0.17 m bounds it above the gap
    assert moved["departs"] == rows[3] and moved["sparse"] == rows[4]
    assert not rows[0]["flagged"]                   # the stored rows are not changed
    assert evidence.table(evidence.moved_floor(rows, 0.48), 0.5)[-1] == ("all", "", 5, 3, 2, 0)
    bias = evidence.gap_bias(rows, 0.5)
    assert "over the 4 completions" in bias and "median +0.062 m" in bias and "error above the gap in 75%" in bias


def test_slam_forward_backward_reverses_a_drive_and_measures_the_loop():
    """``slam_forward_backward.py``: the reversed drive takes the frames and poses last first, with timestamps that
    increase by the same steps; the loop of a trajectory and its exact reverse is the identity, and a backward run
    that comes short by 0.3 m leaves a gap of 0.3 m."""
    import numpy as np

    from dcslam.io.drive_frames import DepthFrame, DriveFrames

    spec = importlib.util.spec_from_file_location("slam_forward_backward", BENCHMARKS / "slam_forward_backward.py")
    fb = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(fb)
    T = np.tile(np.eye(4), (4, 1, 1))
    T[:, 2, 3] = [0.0, 1.0, 2.5, 4.0]
    T[3, :3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    frames = [DepthFrame(np.full((2, 3), float(i), np.float32), None) for i in range(4)]
    drive = DriveFrames("x.h5", "x", np.eye(3), T, np.array([10.0, 10.1, 10.3, 10.4]), False, iter(frames))
    back = fb.reversed_frames(drive)
    assert [f.depth[0, 0] for f in back.frames] == [3, 2, 1, 0]
    assert np.array_equal(back.T_world_cam, T[::-1]) and np.allclose(back.timestamps, [10.0, 10.1, 10.3, 10.4])
    assert fb.gap(T, T[::-1]) == pytest.approx((0.0, 0.0), abs=1e-12)
    short = T[::-1].copy()
    short[-1, 2, 3] += 0.3                          # the backward run ends 0.3 m short of the first frame
    metres, degrees = fb.gap(T, short)
    assert metres == pytest.approx(0.3) and degrees == pytest.approx(0.0, abs=1e-9)


def test_slam_camera_measures_a_stored_run_beside_its_truth(tmp_path, capsys):
    """``slam_camera.py`` on a workspace as ``slam_calibration.py`` leaves it: a real 8-beam SLAM run of a
    generated drive, written by dcslam; the row holds the run's stored error and verdict, and the camera's figure,
    whose trajectory ends near the truth and whose gap is the run's error within the camera's own."""
    import json


    from dcslam.slam.config import SlamSettings, build_slam
    from dcslam.stages.slam import run_drive_file, write_outputs
    from tests.fixtures.street import write_generated_drive

    spec = importlib.util.spec_from_file_location("slam_camera", BENCHMARKS / "slam_camera.py")
    cam = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(cam)
    ws, name = tmp_path / "calib-7302", "2011_09_26_drive_7302_sync"
    (ws / "drives").mkdir(parents=True)
    path = write_generated_drive(ws / "drives" / f"{name}.h5", seed=7302, frames=8, beams=8)
    (ws / "drives" / "splits.json").write_text(json.dumps({"train": [], "val": [], "test": [name]}))
    run = run_drive_file(path, "sparse@8", build_slam(SlamSettings()), colour=False, settings={"source": "sparse@8"})
    write_outputs(run, ws / "slam" / "sparse@8")
    assert cam.tasks([ws], ["sparse", "sparse@8"]) == [(ws, "sparse@8", name)]
    row = cam.measure(ws, "sparse@8", name)
    stored = json.loads((ws / "slam" / "sparse@8" / f"{name}.json").read_text())
    assert row["final_m"] == pytest.approx(stored["translation_error_m"]["final"], abs=1e-6)
    assert row["flagged"] == stored["health"]["suspect"] and row["steps_measured"] == 7
    assert row["camera_final_m"] < 0.05
    assert abs(row["gap_m"] - row["final_m"]) <= row["camera_final_m"] + 1e-6    # the triangle inequality's bound
    assert row["measured"] == "sparse@8" and row["verdict"] in ("agrees", "departs")
    assert row["camera_rule"] == (row["verdict"] == "departs")        # the camera's verdict decides, either way
    # the same run stored as `dcslam slam --camera` stores it: measured as before (its health read without the camera)
    from dcslam.slam.camera import merge_camera
    from dcslam.stages.slam import camera_evidence

    run.camera = camera_evidence(path, "sparse@8", None, run)
    write_outputs(run, ws / "slam" / "sparse@8", force=True)
    again = cam.measure(ws, "sparse@8", name)
    assert {k: again[k] for k in ("flagged", "camera_rule", "gap_m", "reasons")} == \
        {k: row[k] for k in ("flagged", "camera_rule", "gap_m", "reasons")}
    health = {"suspect": True, "reasons": ["2 consecutive steps degraded"], "rejected": 0}
    for figure in ({"verdict": "departs", "suspect": True, "reason": "the camera says the run ends 0.70 m off"},
                   {"verdict": "agrees", "suspect": False, "reason": None}):
        assert cam.before_camera(merge_camera(health, figure)) == health
    cam.separation([row], 0.5)
    cam.by_input([row], 0.5)
    out = capsys.readouterr().out
    assert "runs end more than 0.5 m off" in out and "| sparse@8 | 1 |" in out
