"""``dcslam reproduce --executor slurm`` on a real (single-node) Slurm: the stages run as Slurm jobs and give the
tables the local executor gives; a failed job names its stage, drive, seed and log; SIGTERM cancels the jobs and the
rerun resubmits only what is missing.

Drives: three tiny KITTI-format drives (16 frames of 64 × 96, tests.fixtures.smoke), through ``--kitti``; the local
run to compare with is the session's (the ``tiny_smoke`` fixture)."""
from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
import tomllib
from collections import Counter
from pathlib import Path

import pytest

from dcslam.errors import DcslamError
from dcslam.executor import SlurmExecutor, SlurmSettings
from dcslam.stages import slam, train
from dcslam.stages.pipeline import Pipeline, Stage
from dcslam.workspace import Workspace
from tests.fixtures.smoke import env

pytestmark = [pytest.mark.cluster, pytest.mark.timeout(1800)]

# Table 5.2 runs once per recipe on Slurm (every kind of job, one SLAM array); the trained runs of a second seed go
# through Slurm in the SIGTERM test (Table 5.1 with --seeds 2: its trainings and predictions twice), whose table is
# compared with a local run of the same (each job is a fresh Python that imports torch: seeds 2 on Table 5.2 doubled
# this file's time)
PROFILE = ["--profile", "smoke"]
SEEDS = ["--seeds", "2"]
# One CPU and 1 GB per job: the node is this machine; the local run has one thread too. The stages share jobs (each
# job is a fresh Python that imports torch, 2-3 CPU-s): a round's SLAM runs (17) in two jobs, its trainings,
# predictions and filters two or four to a job.
SLURM_CONFIG = """\
[slurm]
poll_seconds = 1
[slurm.train]
cpus = 1
mem_gb = 1
time_min = 30
stages_per_job = 2
[slurm.predict]
cpus = 1
mem_gb = 1
stages_per_job = 4
[slurm.filter]
mem_gb = 1
stages_per_job = 4
[slurm.slam]
mem_gb = 1
stages_per_job = 9
"""
SETTINGS = tomllib.loads(SLURM_CONFIG)["slurm"]
JOB_STAGES = ("train-", "predict-", "filter-", "slam-")  # what runs through the executor; the rest in reproduce
MESSAGE = "interrupted: the stages that finished are kept in "


def dcslam(*args, timeout: float = 1200) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "dcslam", *map(str, args)], capture_output=True, text=True,
                          env=env(), timeout=timeout)


def queued() -> list[str]:
    """This user's jobs in the queue: 'id name state' lines."""
    done = subprocess.run(["squeue", "--me", "-h", "-r", "-o", "%i %j %T"], capture_output=True, text=True,
                          check=True)
    return done.stdout.split("\n")[:-1] if done.stdout else []


def stamps(ws: Path) -> dict[str, dict]:
    return {p.stem: json.loads(p.read_text()) for p in (ws / ".reproduce").glob("*.json") if p.stem != "splits"}


@pytest.fixture(scope="module")
def runs(slurm_cluster, tiny_smoke, tmp_path_factory):
    """The smoke profile on the tiny drives as Slurm jobs, beside the session's local run of it (``tiny_smoke``, in
    the ``reproduce`` process; shared with the fault test: read only)."""
    root = tmp_path_factory.mktemp("cluster")
    config = root / "slurm.toml"
    config.write_text(SLURM_CONFIG)
    common = ["reproduce", *PROFILE, "--kitti", tiny_smoke.kitti]
    start = time.perf_counter()
    on_slurm = dcslam(*common, "--executor", "slurm", "--config", config, "-w", root / "slurm")
    seconds = time.perf_counter() - start
    assert on_slurm.returncode == 0, on_slurm.stderr
    print(f"smoke profile: local {tiny_smoke.seconds:.0f} s, slurm {seconds:.0f} s")
    return {"root": root, "kitti": tiny_smoke.kitti, "config": config, "common": common, "local": tiny_smoke.workspace,
            "slurm": root / "slurm", "log": on_slurm.stderr, "ctld": slurm_cluster}


def test_slurm_gives_the_tables_of_the_local_run(runs):
    for table in ("table_5_2.md", "table_5_1.md"):
        got, want = (runs[kind] / "results" / table for kind in ("slurm", "local"))
        assert got.read_text() == want.read_text(), table
    assert set(stamps(runs["slurm"])) == set(stamps(runs["local"]))
    assert all(stamp["complete"] for stamp in stamps(runs["slurm"]).values())


def test_the_node_offers_every_cpu_of_this_machine(runs):
    """slurm.sh sizes the node by the CPUs this process may use, not by OMP_NUM_THREADS (which `make test` sets to
    1 and GNU nproc obeys): a one-CPU node would run the jobs one at a time."""
    cpus = subprocess.run(["sinfo", "-h", "-N", "-o", "%c"], capture_output=True, text=True, check=True).stdout
    assert int(cpus.split()[0]) == len(os.sched_getaffinity(0))


def test_every_independent_stage_ran_as_a_slurm_job(runs):
    jobs = dict(re.findall(r"^\[slurm\] (\S+): job (\S+)$", runs["log"], flags=re.M))  # stage → job id
    expected = {name for name in stamps(runs["local"]) if name.startswith(JOB_STAGES)}
    assert set(jobs) == expected and len(expected) >= 30
    ctld = runs["ctld"].read_text()
    for stage, job in jobs.items():
        folder = runs["slurm"] / "logs" / "slurm" / job
        assert (folder / f"{job}_0_result.pkl").exists() and (folder / f"{job}_0_log.err").exists(), stage
        pattern = re.escape(job) + r"(\(\d+\))?"
        started = rf"(sched: Allocate JobId={pattern} NodeList=|sched/backfill: _start_job: Started JobId={pattern} )"
        assert re.search(started, ctld), (stage, job)
        assert re.search(rf"_job_complete: JobId={pattern} WEXITSTATUS 0", ctld), (stage, job)
    arrays = {job.split("_")[0] for stage, job in jobs.items() if stage.startswith("slam-")}
    assert len(arrays) == 1 and all("_" in jobs[s] for s in jobs if s.startswith("slam-"))  # one array for SLAM
    for kind in ("train", "slam", "predict", "filter"):  # up to stages_per_job of a kind share a job
        per_job = Counter(job for stage, job in jobs.items() if stage.startswith(f"{kind}-"))
        size = SETTINGS[kind]["stages_per_job"]
        assert max(per_job.values()) <= size and len(per_job) < sum(per_job.values()), (kind, per_job)
    slam_jobs = Counter(job for stage, job in jobs.items() if stage.startswith("slam-"))  # one round: fewest jobs
    assert len(slam_jobs) == -(-sum(slam_jobs.values()) // SETTINGS["slam"]["stages_per_job"]), slam_jobs
    assert queued() == []


def test_a_rerun_on_slurm_submits_nothing(runs):
    again = dcslam(*runs["common"], "--executor", "slurm", "--config", runs["config"], "-w", runs["slurm"])
    assert again.returncode == 0, again.stderr
    assert "[slurm]" not in again.stderr and "[run]" not in again.stderr, again.stderr


def test_a_failed_job_names_its_stage_drive_seed_and_log(runs, tmp_path):
    shutil.copytree(runs["slurm"] / "drives", tmp_path / "drives")
    ws = Workspace(tmp_path)
    submitted = []
    pipe = Pipeline(ws, executor=SlurmExecutor(tmp_path / "logs", SlurmSettings.from_table(SETTINGS),
                                               log=submitted.append))
    broken_train = Stage("train-broken", train.run, train.TrainStageConfig(name="broken", init="absent", seed=5),
                         outputs=lambda: [tmp_path / "runs" / "broken" / "model.pt"], kind="train")
    broken_slam, after = (Stage(f"slam-broken{i}", slam.run, slam.SlamStageConfig(drive=[drive], frames=2),
                                outputs=lambda d=drive: [tmp_path / "slam" / "dense" / f"{d}.json"], kind="slam")
                          for i, drive in ((1, "absent_drive"), (2, "other_drive")))
    for stages, label in (([broken_train], "seed 5"), ([broken_slam, after], "drive absent_drive")):
        stage = stages[0]
        with pytest.raises(DcslamError) as failed:
            pipe.run_all(stages)  # the two SLAM stages in one job: the first fails, the second is not run
        message = str(failed.value)
        assert message.startswith(f"stage {stage.name} failed (") and f"; {label}; Slurm job " in message, message
        log = Path(re.search(r", log (\S+);", message).group(1))
        assert log.is_file() and log.is_relative_to(tmp_path / "logs")
        for each in stages:
            assert not json.loads((tmp_path / ".reproduce" / f"{each.name}.json").read_text())["complete"]
    jobs = dict(re.findall(r"^\[slurm\] (\S+): job (\S+)$", "\n".join(submitted), flags=re.M))
    assert jobs["slam-broken1"] == jobs["slam-broken2"], submitted
    assert queued() == []


def test_a_job_that_can_never_start_is_a_failure_not_a_wait(runs, tmp_path):
    table = {**SETTINGS, "slam": {"cpus": 4096}}  # more CPUs than any node of the partition
    pipe = Pipeline(Workspace(tmp_path), executor=SlurmExecutor(tmp_path / "logs", SlurmSettings.from_table(table)))
    stage = Stage("slam-huge", slam.run, slam.SlamStageConfig(drive=["absent_drive"], frames=2),
                  outputs=lambda: [tmp_path / "slam" / "dense" / "absent_drive.json"], kind="slam")
    with pytest.raises(DcslamError, match=r"stage slam-huge failed \(job \S+ can never start: Slurm says \w+ "
                                          r"\(it asks 4096 CPUs|sbatch refused the slam jobs|the slam jobs ask 4096 "
                                          r"CPUs, .* more CPUs than a node of partition"):
        pipe.run_all([stage])
    assert not json.loads((tmp_path / ".reproduce" / "slam-huge.json").read_text())["complete"]
    assert queued() == []


def test_sigterm_cancels_the_jobs_and_the_rerun_submits_only_what_is_missing(runs, tmp_path):
    """Table 5.1 with two training seeds on Slurm, in a copy of the fixture's Slurm workspace (the first seed up to
    date there: the second seed's trainings and predictions are the jobs): SIGTERM among the trainings cancels the
    jobs; the rerun submits what is missing and gives the table of a local run (the fixture's local workspace,
    copied, with its second seed)."""
    shutil.copytree(runs["slurm"], tmp_path, dirs_exist_ok=True)
    copied = stamps(tmp_path)
    args = [*runs["common"], "--table", "5.1", *SEEDS, "--executor", "slurm", "--config", runs["config"], "-w",
            tmp_path]
    err = tmp_path.parent / f"{tmp_path.name}.stderr"
    with open(err, "w") as stderr:
        proc = subprocess.Popen([sys.executable, "-m", "dcslam", *map(str, args)], stdout=subprocess.DEVNULL,
                                stderr=stderr, text=True, env=env())
        try:
            while proc.poll() is None and not any(line.endswith(" RUNNING") and " dcslam-train " in line
                                                  for line in queued()):
                time.sleep(0.2)
            assert proc.poll() is None, err.read_text()
            submitted = re.findall(r"^\[slurm\] (train-\S+): job (\S+)$", err.read_text(), flags=re.M)
            proc.send_signal(signal.SIGTERM)
            proc.wait(timeout=180)
        finally:
            if proc.poll() is None:
                proc.kill()
    log = err.read_text()
    assert proc.returncode == 143, log
    assert log.strip().splitlines()[-1].startswith(MESSAGE) and "Traceback" not in log, log
    assert queued() == []  # cancelled, and gone from the queue before reproduce exited
    assert submitted and "[slurm] cancelled" in log
    made = {name: stamp for name, stamp in stamps(tmp_path).items() if copied.get(name) != stamp}  # this run's
    assert all(name.endswith("-s1") for name, _ in submitted)  # the first seed's were up to date
    cancelled = [name for name, _ in submitted if not made[name]["complete"]]
    assert cancelled, made  # the interrupt fell among the trainings
    for name, stamp in made.items():  # what claims completion was made
        if stamp["complete"] and name.startswith("train-"):
            run = tmp_path / "runs" / name.removeprefix("train-")
            assert (run / "model.pt").exists() and (run / "metrics.jsonl").exists(), name
    ctld = runs["ctld"].read_text()
    for _, job in submitted:
        if not made[next(n for n, j in submitted if j == job)]["complete"]:
            assert re.search(rf"JobId={re.escape(job)}(\(\d+\))?.*(CANCELLED|KILL)|"
                             rf"(REQUEST_KILL_JOB|kill).*JobId={re.escape(job.split('_')[0])}", ctld), job

    again = dcslam(*args)
    assert again.returncode == 0, again.stderr
    rerun = dict(re.findall(r"^\[slurm\] (\S+): job (\S+)$", again.stderr, flags=re.M))
    skipped = set(re.findall(r"^\[skip\] (\S+): up to date$", again.stderr, flags=re.M))
    assert set(cancelled) <= set(rerun)
    assert {name for name, stamp in made.items() if stamp["complete"]} <= skipped
    assert [name for name, stamp in stamps(tmp_path).items()  # the second seed's runs, trained as Slurm jobs
            if name.startswith("train-") and name.endswith("-s1") and stamp["complete"]]
    local = tmp_path.parent / f"{tmp_path.name}-local"
    shutil.copytree(runs["local"], local)  # seed 0 up to date there: only the second seed's stages run
    second = dcslam(*runs["common"], "--table", "5.1", *SEEDS, "--jobs", 2, "-w", local)
    assert second.returncode == 0, second.stderr
    assert (tmp_path / "results" / "table_5_1.md").read_text() == (local / "results" / "table_5_1.md").read_text()
    assert "mean ± std of 2 seeds" in (local / "results" / "table_5_1.md").read_text()
    assert queued() == []
