"""The executors of independent stages (dcslam.executor) without a Slurm cluster: the [slurm] table, the kinds and
resources of tasks, the error when submitit or sbatch is missing, local workers stopped when the caller gives up,
and what Pipeline.run_all does with an executor's outcomes. On a real Slurm: tests/cluster/."""
import json
import os
import sys
import time
import tomllib
from pathlib import Path

import pytest

from dcslam.errors import DcslamError
from dcslam.executor import (DEFAULT_RESOURCES, LocalExecutor, Outcome, Resources, SlurmExecutor, SlurmSettings,
                             Task, packs, slurm_job)
from dcslam.stages import filter as filter_stage
from dcslam.stages import predict, prepare, score, slam, synth, train
from dcslam.stages.config import to_toml
from dcslam.stages.pipeline import Pipeline, Stage
from dcslam.stages.reproduce import ReproduceConfig
from dcslam.stages.slam import SlamStageConfig
from dcslam.workspace import Workspace



def test_slurm_table_is_read_with_each_kinds_resources():
    settings = SlurmSettings.from_table({"partition": "gpu", "account": "proj", "qos": "high",
                                         "sbatch": {"constraint": "a100", "exclusive": True},
                                         "setup": ["module load cuda"], "poll_seconds": 0.5,
                                         "train": {"cpus": 8, "mem_gb": 32, "time_min": 600, "gpus": 2},
                                         "slam": {"mem_gb": 2.5}})
    assert (settings.partition, settings.account, settings.qos) == ("gpu", "proj", "high")
    assert settings.sbatch == {"constraint": "a100", "exclusive": True} and settings.setup == ("module load cuda",)
    assert settings.resources["train"] == Resources(cpus=8, mem_gb=32, time_min=600, gpus=2)
    assert settings.resources["slam"] == Resources(cpus=1, mem_gb=2.5, time_min=DEFAULT_RESOURCES["slam"].time_min)
    assert settings.resources["predict"] == DEFAULT_RESOURCES["predict"]
    assert SlurmSettings.from_table({}) == SlurmSettings()
    assert all(res.stages_per_job == 1 for res in SlurmSettings().resources.values())  # a job per stage by default
    assert SlurmSettings.from_table({"slam": {"stages_per_job": 8}}).resources["slam"].stages_per_job == 8


@pytest.mark.parametrize("table, message", [
    ({"partiton": "gpu"}, "unknown key 'partiton'"),
    ({"partition": 3}, "partition: expected a string"),
    ({"train": {"cpu": 2}}, "train: unknown key 'cpu'"),
    ({"slam": {"cpus": 0}}, "slam cpus: expected a whole number >= 1"),
    ({"slam": {"time_min": 1.5}}, "slam time_min: expected a whole number"),
    ({"train": 4}, "train: expected a table"),
    ({"sbatch": ["--exclusive"]}, "sbatch: expected a table of sbatch options"),
    ({"setup": "module load cuda"}, "setup: expected a list of shell lines"),
    ({"poll_seconds": 0}, "poll_seconds: must be > 0"),
    ({"slam": {"stages_per_job": 0}}, "slam stages_per_job: expected a whole number >= 1"),
])
def test_slurm_table_mistakes_name_the_key(table, message):
    with pytest.raises(DcslamError, match=message):
        SlurmSettings.from_table(table)


def test_a_mistake_in_the_slurm_table_of_the_config_file_is_one_line_before_anything_runs(cli, tmp_path):
    config = tmp_path / "reproduce.toml"
    config.write_text('executor = "slurm"\n[slurm]\nqueue = "gpu"\n')
    result = cli("reproduce", "--config", str(config), "--workspace", str(tmp_path / "ws"))
    assert result.exit_code == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: [slurm]: unknown key 'queue'; expected one of partition")
    assert not (tmp_path / "ws").exists()


def test_the_slurm_table_is_printed_back_as_toml(cli, tmp_path):
    table = {"partition": "gpu", "sbatch": {"constraint": "a100"}, "train": {"cpus": 8, "gpus": 1}}
    config = ReproduceConfig(executor="slurm", slurm=table)
    assert tomllib.loads(to_toml(config))["slurm"] == table
    path = tmp_path / "reproduce.toml"
    path.write_text(to_toml(config))
    result = cli("reproduce", "--config", str(path), "--print-config", "-w", str(tmp_path / "ws"))
    assert result.exit_code == 0, result.output
    assert tomllib.loads(result.stdout)["slurm"] == table and tomllib.loads(result.stdout)["executor"] == "slurm"


def test_slurm_is_not_a_command_line_option(cli):
    result = cli("reproduce", "--slurm", "x")
    assert result.exit_code == 2


@pytest.mark.parametrize("table", ["5.2", "beams"])
def test_every_stage_of_an_experiment_declares_its_kind(tmp_path, table):
    from dcslam.stages.experiments import experiment
    from dcslam.stages.experiments.beams import run_table
    from dcslam.stages.reproduce_plan import planned_stages

    kinds = {train.run: "train", predict.run: "predict", filter_stage.run: "filter", slam.run: "slam",
             score.run_tables: "score", run_table: "score", synth.run: "other", prepare.run: "other"}
    stages = planned_stages(Workspace(tmp_path), experiment(table).profile("smoke"), table)
    assert {s.run for s in stages} <= set(kinds)
    assert [s.kind for s in stages] == [kinds[s.run] for s in stages]


def test_tasks_carry_the_kind_they_are_given_and_name_drive_and_seed(tmp_path):
    ws = Workspace(tmp_path)
    assert Task("x", slam.run, None, ws).kind == "other"  # a kind is declared, never guessed from the function
    assert Task("x", synth.run, None, ws, kind="slam").kind == "slam"
    with pytest.raises(DcslamError, match="task x: unknown kind 'gpu'; expected one of train, predict"):
        Task("x", train.run, None, ws, kind="gpu")
    assert Task("s", slam.run, SlamStageConfig(drive=["d1"]), ws).labels() == ["drive d1"]
    assert Task("t", train.run, train.TrainStageConfig(seed=3), ws).labels() == ["seed 3"]
    assert Task("o", synth.run, None, ws).labels() == []


def test_gpus_follow_the_device_and_the_processes_of_a_training(tmp_path):
    ws = Workspace(tmp_path)
    res = DEFAULT_RESOURCES["train"]
    assert res.gpus_for(Task("t", train.run, train.TrainStageConfig(device="cuda", nproc=2), ws, "train")) == 2
    assert res.gpus_for(Task("t", train.run, train.TrainStageConfig(device="cpu"), ws, "train")) == 0
    assert res.gpus_for(Task("t", train.run, train.TrainStageConfig(), ws, "train")) == 0  # auto: no GPU asked
    assert DEFAULT_RESOURCES["predict"].gpus_for(Task("p", predict.run, predict.PredictConfig(run="r", device="cuda"),
                                                      ws, "predict")) == 1
    assert DEFAULT_RESOURCES["slam"].gpus_for(Task("s", slam.run, SlamStageConfig(), ws, "slam")) == 0
    assert Resources(gpus=3).gpus_for(Task("s", slam.run, SlamStageConfig(), ws, "slam")) == 3


def test_slurm_executor_without_submitit_is_one_line(cli, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "submitit", None)  # import submitit now raises ImportError
    with pytest.raises(DcslamError, match=r"--executor slurm needs submitit: pip install 'dcslam\[slurm\]'"):
        SlurmExecutor(tmp_path)
    result = cli("reproduce", "--executor", "slurm", "--profile", "smoke", "-w", str(tmp_path / "w"))
    assert result.exit_code == 1
    assert len(result.stderr.strip().splitlines()) == 1 and "needs submitit" in result.stderr
    assert not (tmp_path / "w" / ".reproduce").exists()  # nothing ran


def test_slurm_executor_without_sbatch_says_where_to_run(tmp_path, monkeypatch):
    pytest.importorskip("submitit")
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(DcslamError, match="sbatch is not on PATH.*--executor local"):
        SlurmExecutor(tmp_path)


def _sleep_then_touch(ws, config, *, force=False):
    """A stage for the worker tests (module level, so a spawned worker can import it): ``frames`` 0 waits (its pid
    in ``out``) until terminated; otherwise it writes ``out``."""
    if config.frames == 0:
        config.out.write_text(str(os.getpid()))
        time.sleep(600)
    config.out.write_text("done")


def test_local_workers_are_stopped_when_the_caller_gives_up(tmp_path):
    ws = Workspace(tmp_path)
    waiting = tmp_path / "waiting.pid"
    tasks = [Task("wait", _sleep_then_touch, SlamStageConfig(frames=0, out=waiting), ws),
             Task("quick", _sleep_then_touch, SlamStageConfig(frames=1, out=tmp_path / "quick.txt"), ws)]
    outcomes = LocalExecutor(jobs=2).run(tasks)
    first = next(outcomes)
    assert first.task.name == "quick" and first.ok and (tmp_path / "quick.txt").read_text() == "done"
    while not waiting.exists() or not waiting.read_text():
        time.sleep(0.05)
    pid = int(waiting.read_text())
    outcomes.close()
    with pytest.raises(ProcessLookupError):  # terminated and reaped, not left running
        os.kill(pid, 0)


def _pack_stage(ws, config, *, force=False):
    """A stage for the job tests (module level, so a job process can import it): ``frames`` 2 raises a DcslamError,
    3 a bug; otherwise it writes ``out``."""
    if config.frames == 2:
        raise DcslamError(f"no drive {config.drive[0]}")
    if config.frames == 3:
        raise ZeroDivisionError("division by zero")
    config.out.write_text("done")


def _pack(tmp_path, *frames):
    ws = Workspace(tmp_path)
    return [Task(f"slam-{i}", _pack_stage, SlamStageConfig(drive=[f"d{i}"], frames=n, out=tmp_path / f"{i}.txt"), ws,
                 "slam") for i, n in enumerate(frames)]


def test_packs_cut_a_kinds_stages_into_jobs_of_nearly_equal_size():
    tasks = list(range(17))
    assert [len(p) for p in packs(tasks, 8)] == [6, 6, 5] and sum(packs(tasks, 8), []) == tasks
    assert packs(tasks, 1) == [[t] for t in tasks] and packs(tasks, 17) == [tasks] and packs(tasks, 99) == [tasks]
    assert [len(p) for p in packs(tasks[:3], 2)] == [2, 1] and packs([], 4) == []


def test_a_job_runs_its_stages_in_turn_and_the_first_failure_ends_it(tmp_path, capsys):
    """Each stage's result, the first that fails last: a known error by its message, a bug by its type and message
    with its traceback in the job's log (stderr); the stages after it never run."""
    tasks = _pack(tmp_path, 1, 2, 1)
    results = slurm_job([(t.run, t.workspace, t.config) for t in tasks])
    assert [status for status, _ in results] == ["ok", "error"] and results[1][1] == "no drive d1"
    assert all(isinstance(x, float) for x in results[0][1])
    assert (tmp_path / "0.txt").exists() and not (tmp_path / "2.txt").exists()
    tasks = _pack(tmp_path / "bug", 3, 1)
    (tmp_path / "bug").mkdir()
    bug = ("bug", "ZeroDivisionError: division by zero")
    assert slurm_job([(t.run, t.workspace, t.config) for t in tasks]) == [bug]
    err = capsys.readouterr().err
    assert "Traceback" in err and "ZeroDivisionError: division by zero" in err
    assert not (tmp_path / "bug" / "1.txt").exists()


def test_a_finished_jobs_result_gives_each_of_its_stages_an_outcome(tmp_path):
    """A real submitit job (its local executor: the same result file and logs as a Slurm job) running a pack of
    three stages whose second fails: the first is done, the second failed with its message, the third not run;
    each names the job and its log."""
    submitit = pytest.importorskip("submitit")
    from dcslam.executor import _finished

    tasks = _pack(tmp_path, 1, 2, 1)
    executor = submitit.LocalExecutor(folder=tmp_path / "logs" / "%j")
    executor.update_parameters(timeout_min=5)
    job = executor.submit(slurm_job, [(t.run, t.workspace, t.config) for t in tasks])
    job.wait()
    done, failed, unrun = _finished(job, tasks)
    assert done.ok and done.seconds > 0 and done.cpu_seconds > 0 and done.task is tasks[0]
    assert failed.error == "no drive d1" and failed.task is tasks[1]
    assert unrun.error == "not run: stage slam-1 before it in the same job failed" and unrun.task is tasks[2]
    assert {o.job for o in (done, failed, unrun)} == {job.job_id} and done.log == failed.log == Path(job.paths.stderr)
    assert not (tmp_path / "2.txt").exists()


class _Scripted:
    """An executor whose outcomes are given: the first task ok, every other one failed in a 'job'."""

    def __init__(self):
        self.closed = False
        self.given: list[Task] = []

    def in_process(self, tasks: int) -> bool:
        return False

    def run(self, tasks):
        self.given = tasks
        try:
            yield Outcome(tasks[0], seconds=1.5, job="7_0", log=Path("/logs/7_0_0_log.err"))
            for task in tasks[1:]:
                yield Outcome(task, error="no luck", job="7_1", log=Path("/logs/7_1_0_log.err"))
        finally:
            self.closed = True


def test_run_all_stamps_what_finished_and_names_the_failed_job(tmp_path):
    ws = Workspace(tmp_path)
    made = [tmp_path / "a.txt", tmp_path / "b.txt"]
    stages = [Stage("slam-a", slam.run, SlamStageConfig(drive=["drive_a"]), outputs=lambda: [made[0]], kind="slam"),
              Stage("train-b", train.run, train.TrainStageConfig(seed=4), outputs=lambda: [made[1]], kind="train")]
    executor = _Scripted()
    lines = []
    pipe = Pipeline(ws, log=lines.append, executor=executor)
    with pytest.raises(DcslamError) as failed:
        pipe.run_all(stages, jobs=1)  # an executor that is not in-process runs even one job's worth of stages
    assert str(failed.value) == ("stage train-b failed (no luck); seed 4; Slurm job 7_1, log /logs/7_1_0_log.err; "
                                 "fix it and rerun: finished stages will be skipped")
    assert [(t.name, t.kind) for t in executor.given] == [("slam-a", "slam"), ("train-b", "train")]
    assert executor.closed
    stamps = {name: json.loads((tmp_path / ".reproduce" / f"{name}.json").read_text()) for name in ("slam-a",
                                                                                                   "train-b")}
    assert stamps["slam-a"]["complete"] and stamps["slam-a"]["seconds"] == 1.5
    assert not stamps["train-b"]["complete"]  # claims nothing
    assert any(line.startswith("[run]  slam-a: slam") and line.endswith("(job)") for line in lines), lines


def _killed_or_waits(ws, config, *, force=False):
    """A stage for the worker-death test: ``frames`` 0 kills its own worker (SIGKILL, as the out-of-memory killer
    does) once the other has started (``out`` holds a pid); otherwise it writes its pid to ``out`` and waits."""
    import signal

    if config.frames == 0:
        while not config.out.exists() or not config.out.read_text():
            time.sleep(0.02)
        os.kill(os.getpid(), signal.SIGKILL)
    config.out.write_text(str(os.getpid()))
    time.sleep(600)


def test_a_worker_killed_mid_stage_fails_that_stage_in_one_line_and_stops_the_other(tmp_path):
    """A worker that dies (here SIGKILL) is an outcome naming its stage, how it ended and the stage stopped beside
    it, not a BrokenProcessPool; the other worker is not left running."""
    ws = Workspace(tmp_path)
    waiting = tmp_path / "waiting.pid"
    tasks = [Task("waits", _killed_or_waits, SlamStageConfig(frames=1, out=waiting), ws),
             Task("killed", _killed_or_waits, SlamStageConfig(frames=0, out=waiting), ws)]
    outcomes = list(LocalExecutor(jobs=2).run(tasks))
    assert len(outcomes) == 1 and outcomes[0].task.name == "killed" and not outcomes[0].ok
    assert outcomes[0].error == ("its worker process was killed by SIGKILL (what the out-of-memory killer sends: give "
                                 "it more memory or run fewer --jobs); stopped with it: waits")
    with pytest.raises(ProcessLookupError):
        os.kill(int(waiting.read_text()), 0)


def test_run_all_names_the_stage_whose_worker_died(tmp_path):
    """Through the pipeline: one line naming the stage and how its worker ended; neither stage stamped complete."""
    ws = Workspace(tmp_path)
    waiting = tmp_path / "waiting.pid"
    stages = [Stage("slam-waits", _killed_or_waits, SlamStageConfig(frames=1, out=waiting), outputs=lambda: [waiting],
                    kind="slam"),
              Stage("slam-killed", _killed_or_waits, SlamStageConfig(frames=0, out=waiting), outputs=lambda: [waiting],
                    kind="slam")]
    with pytest.raises(DcslamError) as failed:
        Pipeline(ws, log=lambda line: None).run_all(stages, jobs=2)
    assert str(failed.value).startswith("stage slam-killed failed (its worker process was killed by SIGKILL")
    assert "stopped with it: slam-waits); fix it and rerun" in str(failed.value)
    for name in ("slam-waits", "slam-killed"):
        assert not json.loads((tmp_path / ".reproduce" / f"{name}.json").read_text())["complete"]
