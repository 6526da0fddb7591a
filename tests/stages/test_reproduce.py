"""The reproduction pipeline: stage skipping (unit) and the whole experiment at the smoke profile (end to end),
every stage run in this process."""
import json
import os
import signal
import time

import pytest

from dcslam.errors import DcslamError
from dcslam import __version__
from dcslam.stages.config import code_version
from dcslam.stages.experiments.table_5_2 import PROFILES, Profile
from dcslam.stages.pipeline import Pipeline, Stage
from dcslam.stages.reproduce import reproduce
from dcslam.stages.reproduce_plan import planned_stages, read_stage_configs
from dcslam.stages.slam import SlamStageConfig
from dcslam.workspace import Workspace

def _fake_stage(calls, outputs):
    """Stand-in for a stage's run(): records the call and writes the stage's outputs."""
    def run(ws, config, *, force=False):
        calls.append((config, force))
        for path in outputs:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text("made")
        return "result"
    return run


def test_stage_runs_once_then_is_skipped_until_its_inputs_config_or_code_change(tmp_path, monkeypatch):
    ws = Workspace(tmp_path)
    source, made = tmp_path / "in.txt", tmp_path / "out" / "made.txt"
    source.write_text("input")
    os.utime(source, (1_000_000, 1_000_000))
    calls = []
    pipe = Pipeline(ws, log=lambda line: None)
    fake = _fake_stage(calls, [made])
    stage = Stage("demo", fake, SlamStageConfig(frames=3), outputs=lambda: [made], inputs=lambda: [source])

    assert pipe.run(stage) == "result"
    assert calls == [(SlamStageConfig(frames=3), True)]  # in this process, with force
    stamp = json.loads((tmp_path / ".reproduce" / "demo.json").read_text())
    assert stamp["config"]["frames"] == 3 and stamp["dcslam"] == code_version()
    assert pipe.run(stage) is None
    assert len(calls) == 1  # up to date: skipped

    os.utime(source, None)  # the input changed after the output was made
    os.utime(made, (1_000_000, 1_000_000))
    pipe.run(stage)
    assert len(calls) == 2

    pipe.run(Stage("demo", fake, SlamStageConfig(frames=4), outputs=lambda: [made], inputs=lambda: [source]))
    assert len(calls) == 3  # another configuration: rerun

    monkeypatch.setattr("dcslam.stages.pipeline.code_version", lambda: "0.0.0+other")
    pipe.run(Stage("demo", fake, SlamStageConfig(frames=4), outputs=lambda: [made], inputs=lambda: [source]))
    assert len(calls) == 4  # other dcslam code: rerun
    monkeypatch.undo()

    made.unlink()
    pipe.run(stage)
    assert len(calls) == 5  # output missing: rerun


def test_a_moved_workspace_keeps_its_stages_whose_configs_name_paths_inside_it(tmp_path):
    def stage_in(root):
        out = root / "slam-long" / "sparse"
        made = out / "d.json"
        return Stage("long", _fake_stage(calls, [made]), SlamStageConfig(out=out), outputs=lambda: [made])

    calls = []
    first = tmp_path / "first"
    Pipeline(Workspace(first)).run(stage_in(first))
    stamp = json.loads((first / ".reproduce" / "long.json").read_text())
    assert stamp["config"]["out"] == "<workspace>/slam-long/sparse"  # not the absolute path

    moved = tmp_path / "moved"
    first.rename(moved)
    assert Pipeline(Workspace(moved)).run(stage_in(moved)) is None and len(calls) == 1  # up to date after the move
    outside = tmp_path / "elsewhere"
    pipe = Pipeline(Workspace(moved))
    made = outside / "d.json"
    pipe.run(Stage("long", _fake_stage(calls, [made]), SlamStageConfig(out=outside), outputs=lambda: [made]))
    assert len(calls) == 2  # a path outside the workspace is another configuration


def test_code_version_changes_with_the_sources(tmp_path, monkeypatch):
    import dcslam.stages.config as config

    before = code_version()
    assert before.startswith(__version__ + "+")
    fake_root = tmp_path / "dcslam"
    (fake_root / "stages").mkdir(parents=True)
    (fake_root / "a.py").write_text("x = 1\n")
    monkeypatch.setattr(config, "__file__", str(fake_root / "stages" / "config.py"))
    first = code_version()
    (fake_root / "a.py").write_text("x = 2\n")
    assert code_version() != first != before
    second = code_version()
    (fake_root / "kernels.c").write_text("int x;\n")      # the native kernels make outputs too
    assert code_version() != second


def test_code_version_is_kept_while_no_source_changes_and_read_again_when_one_does(tmp_path, monkeypatch):
    """Settled sources (changed more than SETTLED_NS ago) are not read again while their sizes and times stay; a
    touched one is; one changed just now is read on every call (within its timestamp's granularity it could change
    again unseen)."""
    from pathlib import Path

    import dcslam.stages.config as config

    fake_root = tmp_path / "dcslam"
    (fake_root / "stages").mkdir(parents=True)
    source = fake_root / "a.py"
    source.write_text("x = 1\n")
    old = time.time() - 10
    os.utime(source, (old, old))
    monkeypatch.setattr(config, "__file__", str(fake_root / "stages" / "config.py"))
    first = code_version()
    reads = []
    read_bytes = Path.read_bytes
    monkeypatch.setattr(Path, "read_bytes", lambda self: reads.append(self.name) or read_bytes(self))
    assert code_version() == first and reads == []
    os.utime(source, (old + 1, old + 1))
    assert code_version() == first and reads == ["a.py"]  # touched: read again, the same sources
    source.write_text("x = 22\n")
    now = code_version()
    assert now != first and code_version() == now and reads == ["a.py"] * 3  # just changed: read each time


def test_failed_stage_stops_the_pipeline_with_one_line(tmp_path, monkeypatch):
    def fail(ws, config, *, force=False):
        raise DcslamError("no luck")

    monkeypatch.setattr("dcslam.stages.synth.run", fail)
    with pytest.raises(DcslamError, match="stage synth failed \\(no luck\\)"):
        reproduce(Workspace(tmp_path), PROFILES["smoke"], log=lambda line: None)
    stamp = tmp_path / ".reproduce" / "synth.json"
    assert json.loads(stamp.read_text())["complete"] is False  # claims nothing: the next run redoes it


def test_unknown_profile_and_table_fail_with_exit_code(cli, tmp_path):
    result = cli("reproduce", "--profile", "huge", "--workspace", tmp_path)
    assert result.exit_code == 2 and "huge" in result.stderr  # a usage error, like every unknown choice
    result = cli("reproduce", "--table", "9.9", "--workspace", tmp_path)
    assert result.exit_code == 2 and "9.9" in result.stderr
    result = cli("reproduce", "--kitti", tmp_path / "nowhere", "--workspace", tmp_path)
    assert result.exit_code == 1 and "does not exist" in result.stderr


@pytest.mark.slow  # every stage of Table 5.1 and 5.2, end to end, then the cost probe: ~2 min quiet, 10+ loaded
@pytest.mark.timeout(1500)
def test_smoke_profile_runs_every_stage_and_writes_the_tables(cli, tmp_path):
    """The whole experiment on a few tiny generated drives: every stage, then a rerun that skips them all (the worker
    processes of --jobs are tested on their own, below)."""
    import csv

    from dcslam.stages.slam import torch_threads

    with torch_threads(1):  # the cost model's CPU seconds are one thread's, as the probe measures them
        result = cli("reproduce", "--profile", "smoke", "--workspace", tmp_path)
    assert result.exit_code == 0, result.output
    results = tmp_path / "results"
    for name in ("table_5_1.md", "table_5_1.csv", "table_5_2.md", "table_5_2.csv", "table_5_2_per_drive.csv",
                 "table_5_2_correlation.md", "table_5_2_correlation.csv", "table_5_3.md", "depth_examples.png"):
        assert (results / name).stat().st_size > 0, name
    assert list(results.glob("trajectories_*.png"))
    table = (results / "table_5_2.md").read_text()
    assert "Table 5.2" in result.stdout
    test_drive = json.loads((tmp_path / "drives" / "splits.json").read_text())["test"][0]
    for layer in ("chamfer-1", "chamfer-8", "mse-sparse", "mse-dense", "sparse", "dense", "ip-basic-fast",
                  "mse-dense+edges", "pose", "pose-from-chamfer-8", "pose-from-mse-dense"):
        assert f"| {layer} |" in table, layer
        for suffix in (".txt", ".kitti.txt", ".json"):
            assert (tmp_path / "slam" / layer / f"{test_drive}{suffix}").exists(), (layer, suffix)
    with open(results / "table_5_2.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 14 and not any(row["missing"] for row in rows)  # no row lacks its inputs
    assert {"pose from scratch", "pose, fine-tuned from chamfer-8", "pose, fine-tuned from mse-dense"} <= \
        {row["method"] for row in rows}
    assert {row["slam_settings"] for row in rows} == {"as the others"}  # every row from the same SLAM settings
    assert all(row["drives"] == "1" for row in rows)
    for layer in PROFILES["smoke"].long_layers:  # and SLAM over the whole test drives, in the long-drive table
        summary = json.loads((tmp_path / "slam-long" / layer / f"{test_drive}.json").read_text())
        assert summary["frames"] == 12 - 10 and summary["settings"]["frames"] == 0, layer
    with open(results / "table_5_2_long.csv") as f:
        long_rows = list(csv.DictReader(f))
    assert [row["layer"] for row in long_rows] == ["sparse", "dense", "ip-basic-fast"]
    assert all("drives too short" in row["notes"] for row in long_rows)
    assert "Table 5.2, whole drives" in table and (results / "table_5_2_long_per_drive.csv").exists()
    ran = {p.stem for p in (tmp_path / ".reproduce").glob("*.json")} - {"splits"}
    assert ran == {stage.name for stage in planned_stages(Workspace(tmp_path), PROFILES["smoke"])}  # --print-config

    again = cli("reproduce", "--profile", "smoke", "--workspace", tmp_path)
    assert again.exit_code == 0, again.output
    assert "[run]" not in again.stderr and again.stderr.count("[skip]") >= 20
    _estimate_is_within_1_5_of_the_measured_cost(tmp_path)


def _estimate_is_within_1_5_of_the_measured_cost(root):
    """The cost the dry run estimates for the smoke profile, from the unit costs the probe measures on this machine
    (``--calibrate``), is within x1.5 of the CPU seconds the smoke run's stamps recorded; an estimate 3x too high
    fails the same check."""
    from dcslam.stages.reproduce_cost import UnitCosts, estimate, measure, planned_drives, unit_costs
    from dcslam.stages.reproduce_plan import planned_splits
    from dcslam.stages.reproduce_probe import calibrate

    stamps = [json.loads(p.read_text()) for p in (root / ".reproduce").glob("*.json") if p.stem != "splits"]
    assert all(isinstance(s["cpu_seconds"], float) and s["cpu_seconds"] > 0 for s in stamps)
    measured = measure(root)
    total = sum(seconds for seconds, _, _ in measured.values())
    probe = Workspace(root.parent / f"{root.name}-probe")
    calibrate(probe, PROFILES["smoke"])
    costs = unit_costs(probe.root, profile="smoke")
    assert costs.source.startswith("dcslam reproduce --calibrate --profile smoke")
    plan = Workspace(root.parent / f"{root.name}-plan")  # the plan as the dry run sees it, before anything ran
    stages = planned_stages(plan, PROFILES["smoke"])
    drives = planned_drives(plan, PROFILES["smoke"], None, planned_splits(plan, PROFILES["smoke"]))
    estimated = estimate(stages, drives, costs)

    def within(seconds: float) -> bool:
        return 1 / 1.5 <= seconds / total <= 1.5

    per_kind = {kind: (round(estimated.rows[kind][2], 1), round(measured[kind][0], 1)) for kind in measured}
    assert within(estimated.total_seconds), (estimated.total_seconds, total, per_kind)
    wrong = UnitCosts({k: 3 * v for k, v in costs.per_unit.items()}, "3x",
                      {k: 3 * v for k, v in costs.per_stage.items()})
    assert not within(estimate(stages, drives, wrong).total_seconds)


def test_quick_profile_has_four_test_drives_and_profiles_check_their_split():
    assert PROFILES["quick"].split[2] >= 4 and sum(PROFILES["quick"].split) == PROFILES["quick"].drives
    assert PROFILES["thesis"].split is None and PROFILES["thesis"].drives == 24  # the thesis's 15 / 4 / 5
    with pytest.raises(DcslamError, match="add up to"):
        Profile(name="bad", drives=5, frames=20, train={}, slam_frames=5, split=(3, 1, 4))


def test_independent_slam_stages_run_in_worker_processes(tmp_path):
    """run_all with jobs > 1: each stage runs in a worker, its stamp is written, a failure names the stage."""
    ws = Workspace(tmp_path)
    made = [tmp_path / f"out{i}.txt" for i in range(3)]
    stages = [Stage(f"touch-{i}", _touch, SlamStageConfig(frames=i + 1, out=path), outputs=lambda p=path: [p])
              for i, path in enumerate(made)]
    lines = []
    pipe = Pipeline(ws, log=lines.append)
    pipe.run_all(stages, jobs=2)
    assert all(p.read_text() == "1" for p in made)
    assert sorted(pipe.timings) == ["touch-0", "touch-1", "touch-2"]
    assert all((tmp_path / ".reproduce" / f"touch-{i}.json").exists() for i in range(3))
    pipe.run_all(stages, jobs=2)
    assert sum("[skip]" in line for line in lines) == 3
    failing = Stage("fail", _touch, SlamStageConfig(frames=99, out=tmp_path / "never"), outputs=lambda: [])
    with pytest.raises(DcslamError, match="stage fail failed \\(no luck\\)"):
        pipe.run_all([failing, Stage("touch-0", _touch, SlamStageConfig(frames=5, out=made[0]),
                                     outputs=lambda: [made[0]])], jobs=2)
    assert not json.loads((tmp_path / ".reproduce" / "fail.json").read_text())["complete"]  # claims nothing


def test_rounds_of_run_all_reuse_the_workers_until_a_stage_runs_here_a_round_fails_or_it_closes(tmp_path):
    """Each new worker imports torch again (2-3 CPU-s), so run_all keeps its workers up for the next round; a stage
    run in this process (an idle worker would take a Ctrl-C meant for it), a failed round and the end of the
    ``with`` block end them."""
    from dcslam.locks import process_alive as alive  # a process that runs here (a zombie does not)

    ws = Workspace(tmp_path)

    def round_of(tag: str, frames: int = 1) -> tuple[list, list]:
        outs = [tmp_path / f"{tag}{i}.txt" for i in range(2)]
        return outs, [Stage(f"{tag}-{i}", _pid, SlamStageConfig(frames=frames, out=out), outputs=lambda out=out: [out])
                      for i, out in enumerate(outs)]

    def pids(outs: list) -> set[int]:
        return {int(out.read_text()) for out in outs}

    with Pipeline(ws) as pipe:
        first, stages = round_of("a")
        pipe.run_all(stages, jobs=2)
        assert os.getpid() not in pids(first) and all(alive(pid) for pid in pids(first))  # idle, kept
        second, stages = round_of("b")
        pipe.run_all(stages, jobs=2)
        kept = pids(first) | pids(second)
        assert len(kept) <= 2 and all(alive(pid) for pid in kept)  # the same two workers at most, still up
        outs, stages = round_of("c")
        pipe.run(stages[0])
        assert pids(outs[:1]) == {os.getpid()} and not any(alive(pid) for pid in kept)
        failed, stages = round_of("d", frames=99)  # fails in its workers
        with pytest.raises(DcslamError, match="no luck"):
            pipe.run_all(stages, jobs=2)
        ended = {int(out.read_text()) for out in failed if out.exists()}
        assert ended and not any(alive(pid) for pid in ended)
        fourth, stages = round_of("e")
        pipe.run_all(stages, jobs=2)
        assert not pids(fourth) & (kept | ended)
        killed = next(iter(pids(fourth)))  # a kept worker killed while idle: the next round starts afresh
        os.kill(killed, signal.SIGKILL)
        fifth, stages = round_of("f")
        pipe.run_all(stages, jobs=2)
        assert killed not in pids(fifth)
        last = pids(fifth)
        assert all(alive(pid) for pid in last)
    assert not any(alive(pid) for pid in last)


def _pid(ws, config, *, force=False):
    """A stage that writes the pid of the process it runs in (frames 99: then fails); module level, for a worker."""
    config.out.write_text(str(os.getpid()))
    if config.frames == 99:
        raise DcslamError("no luck")


def test_stamps_record_the_cpu_seconds_of_the_process_that_ran_the_stage(tmp_path):
    """A stage that computes for 0.3 s and one that sleeps 0.3 s, in this process and in worker processes: both
    stamps record ~0.3 wall seconds, only the first ~0.3 CPU seconds (measured where the stage ran)."""
    for jobs in (1, 2):
        ws = Workspace(tmp_path / f"jobs{jobs}")
        stages = [Stage(f"{what}-{jobs}", _busy, SlamStageConfig(frames=frames, out=ws.root / f"{what}.txt"),
                        outputs=lambda p=ws.root / f"{what}.txt": [p])
                  for what, frames in (("compute", 1), ("sleep", 2))]
        Pipeline(ws).run_all(stages, jobs=jobs)
        compute, sleep = (json.loads((ws.root / ".reproduce" / f"{s.name}.json").read_text()) for s in stages)
        assert compute["seconds"] >= 0.3 and sleep["seconds"] >= 0.3
        assert compute["cpu_seconds"] >= 0.25, (jobs, compute)  # in a worker: its CPU, not the parent's idle wait
        assert sleep["cpu_seconds"] < 0.2, (jobs, sleep)


def _busy(ws, config, *, force=False):
    """A stage that computes (frames 1) or sleeps (frames 2) for 0.3 s (module level, for a spawned worker)."""
    import time

    if config.frames == 1:
        start = time.process_time()
        while time.process_time() - start < 0.3:
            pass
    else:
        time.sleep(0.3)
    config.out.parent.mkdir(parents=True, exist_ok=True)
    config.out.write_text("done")


def _touch(ws, config, *, force=False):
    """A stage for the worker test (module level, so a spawned worker can import it)."""
    import torch

    if config.frames == 99:
        raise DcslamError("no luck")
    config.out.write_text(str(torch.get_num_threads()))


def test_print_config_lists_every_stage_config_as_toml_and_runs_nothing(cli, tmp_path):
    import tomllib

    ws = tmp_path / "ws"
    result = cli("reproduce", "--print-config", "--workspace", ws)
    assert result.exit_code == 0, result.output
    printed = tomllib.loads(result.stdout)  # still a --config file of reproduce: the stages are comments
    assert printed == {"table": "5.2", "profile": "quick", "seed": 0, "force": False, "jobs": 1, "executor": "local",
                       "slurm": {}, "camera": True, "dry_run": False, "calibrate": False}
    assert not ws.exists()  # nothing run, nothing written
    stages = read_stage_configs(result.stdout)
    names = list(stages)
    assert names[:2] == ["synth", "prepare-kitti"] and names[-1] == "score-tables"
    assert stages["synth"]["drives"] == 8 and stages["synth"]["frames"] == 42
    assert stages["train-chamfer-8"]["map_frames"] == 8 and stages["train-mse-sparse"]["mask"] == "sparse"
    test = [f"2011_09_26_drive_{n}_sync" for n in (1004, 1005, 1006, 1007)]  # the profile's split: 3 / 1 / 4
    short = {n: c for n, c in stages.items() if n.startswith("slam-") and not n.startswith("slam-long-")}
    whole = {n: c for n, c in stages.items() if n.startswith("slam-long-")}
    assert len(short) == 14 * 4 and len(whole) == 3 * 4  # 11 thesis layers + 3 pose-loss runs
    assert {c["drive"][0] for c in short.values()} == set(test)
    assert {c["frames"] for c in short.values()} == {30} and {c["frames"] for c in whole.values()} == {0}
    long_ip = stages["slam-long-ip-basic-fast-2011_09_26_drive_1004_sync"]
    assert long_ip["out"] == str(ws / "slam-long" / "ip-basic-fast")
    assert stages["slam-mse-dense+edges-2011_09_26_drive_1007_sync"]["depth"] == "filtered/mse-dense+edges"

    thesis = read_stage_configs(cli("reproduce", "--profile", "thesis", "--table", "5.1", "--print-config",
                                    "--workspace", ws).stdout)
    assert list(thesis)[-1] == "score-tables" and not any(n.startswith("slam") for n in thesis)
    assert thesis["train-mse-dense"]["max_frames"] == 200


@pytest.mark.parametrize("table", ["5.2", "beams", "surface"])
def test_camera_judges_every_slam_run_by_default_and_no_camera_names_the_profile(cli, tmp_path, table):
    """The camera is on in every SLAM stage by default; ``--no-camera`` turns it off there and in nothing else, and
    the plan then names the profile ``<profile>+no-camera`` and estimates it with the unit costs measured without
    the camera (shipped for quick), not with those of the profile that runs it."""
    ws = tmp_path / "ws"
    base = read_stage_configs(cli("reproduce", "--table", table, "--print-config", "--workspace", ws).stdout)
    result = cli("reproduce", "--table", table, "--no-camera", "--print-config", "--workspace", ws)
    assert result.exit_code == 0, result.output
    stages = read_stage_configs(result.stdout)
    assert list(stages) == list(base) and not ws.exists()
    slam = [n for n in stages if n.startswith("slam-")]
    assert slam and all(stages[n]["camera"] is False and base[n]["camera"] is True for n in slam)
    assert all(stages[n] == base[n] for n in stages if n not in slam)
    plan = cli("reproduce", "--table", table, "--no-camera", "--dry-run", "--workspace", ws)
    assert plan.exit_code == 0, plan.output
    assert "--profile quick+no-camera:" in plan.stdout
    assert "--calibrate --profile quick+no-camera on" in plan.stdout and "not quick+no-camera's" not in plan.stdout


def test_two_seeds_at_smoke_scale_write_the_seed_and_interval_columns(cli, tmp_path, monkeypatch):
    """--seeds 2 on one thesis recipe (the other recipes left out to keep it short: their rows say so), on three
    tiny KITTI-format drives split as generated ones (the seeds, not the drives, are under test): each seed's run is
    trained, predicted, filtered and run through SLAM; Table 5.2 gives the recipe one row over both seeds with its
    interval and seed-to-seed spread, the per-drive CSV a seed column, Table 5.1 a row per seed."""
    import csv

    from dcslam.stages.experiments import table_5_2 as module
    from tests.fixtures.kitti import write_tiny_drive

    monkeypatch.setattr(module, "RECIPES", {"mse-sparse": module.RECIPES["mse-sparse"]})
    monkeypatch.setattr(module, "POSE_RECIPES", {})
    kitti = tmp_path.parent / f"{tmp_path.name}-kitti"
    for i in range(3):
        write_tiny_drive(kitti, name=f"2011_09_26_drive_{1000 + i:04d}_sync", n_frames=16, size=(64, 96), seed=i)
    (kitti / "SYNTHETIC").write_text("tiny drives split as generated ones\n")
    result = cli("reproduce", "--profile", "smoke", "--seeds", "2", "--kitti", kitti, "--workspace", tmp_path)
    assert result.exit_code == 0, result.output
    assert "2 training seed(s) per trained run (seeds 0, 1)" in result.stderr and "CPU-hours" in result.stderr
    for run, seed in (("mse-sparse", 0), ("mse-sparse-s1", 1)):
        assert json.loads((tmp_path / "runs" / run / "config.json").read_text())["settings"]["seed"] == seed
    test_drive = json.loads((tmp_path / "drives" / "splits.json").read_text())["test"][0]
    for layer in ("mse-sparse-s1", "mse-sparse-s1+edges", "sparse"):
        assert (tmp_path / "slam" / layer / f"{test_drive}.txt").exists(), layer
    assert not (tmp_path / "slam" / "sparse-s1").exists()  # untrained layers once
    results = tmp_path / "results"
    with open(results / "table_5_2.csv") as f:
        rows = {row["method"]: row for row in csv.DictReader(f)}
    trained, sparse = rows["MSE sparse mask"], rows["sparse depth"]
    assert trained["seeds"] == "2" and trained["layer"] == "mse-sparse (seeds 0, 1)" and sparse["seeds"] == ""
    low, mean, high = (float(trained[k]) for k in ("localisation_ci_low", "localisation", "localisation_ci_high"))
    assert low <= mean <= high and float(trained["localisation_seed_std"]) >= 0
    assert rows["MSE sparse mask + best filter"]["seeds"] == "2"
    with open(results / "table_5_2_per_drive.csv") as f:
        per_drive = list(csv.DictReader(f))
    assert sorted((r["layer"], r["seed"]) for r in per_drive if r["method"] == "MSE sparse mask") == [
        ("mse-sparse", "0"), ("mse-sparse-s1", "1")]
    assert "mean ± std of 2 seeds" in (results / "table_5_1.md").read_text()
    stages = planned_stages(Workspace(tmp_path), PROFILES["smoke"], kitti_root=kitti, seeds=2)
    assert {p.stem for p in (tmp_path / ".reproduce").glob("*.json")} - {"splits"} == {s.name for s in stages}
    assert {(s.name, s.seed) for s in stages if s.name.startswith("train-")} == {
        ("train-mse-sparse", 0), ("train-mse-sparse-s1", 1)}
    assert {s.seed for s in stages if "sparse-s1" in s.name} == {1} and \
        {s.seed for s in stages if s.name.startswith(("prepare", "slam-dense", "predict-ip-basic"))} == {None}
