"""The training loop's hooks: an added writer sees the rows metrics.jsonl holds, a hook can stop the run after an
epoch, ``after_train`` runs when a step fails, the learning-rate schedule, and the training modules import no cycle."""
import ast
import json
import math
from pathlib import Path

import pytest

from dcslam.depth.hooks import Hook, lr_factor
from dcslam.depth.train import TrainConfig
from dcslam.errors import DcslamError
from dcslam.stages.train import train


def _config(ws, **kw):
    drives = ws / "drives"
    base = dict(train_drives=[drives / "drive_a.h5"], val_drives=[drives / "drive_c.h5"],
                model_hparams={"channels": 4}, batch_size=3, device="cpu")
    base.update(kw)
    return TrainConfig(**base)


def _rows(run):
    return [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]


class _Recorder(Hook):
    def __init__(self):
        self.rows, self.calls = [], []

    def before_train(self, state):
        self.calls.append("before_train")

    def after_epoch(self, state):
        self.calls.append(f"after_epoch {state.epoch}")

    def after_train(self, state):
        self.calls.append("after_train")

    def write(self, state, row):
        self.rows.append(row)


def test_an_added_writer_sees_every_row_of_metrics_jsonl(workspace):
    recorder = _Recorder()
    run = workspace / "runs" / "w"
    result = train(run, _config(workspace, epochs=2), hooks=[recorder])
    assert recorder.rows == _rows(run) and result.steps == 4
    assert [r["kind"] for r in recorder.rows] == ["train", "train", "val"] * 2
    assert recorder.calls == ["before_train", "after_epoch 0", "after_epoch 1", "after_train"]


class _StopAfterFirstValidation(Hook):
    def after_epoch(self, state):
        state.stop = state.last_val is not None


def test_a_hook_stops_the_run_after_an_epoch(workspace):
    run = workspace / "runs" / "early"
    result = train(run, _config(workspace, epochs=3), hooks=[_StopAfterFirstValidation()])
    assert result.epochs == 1 and result.steps == 2
    assert {r["epoch"] for r in _rows(run)} == {0}
    assert (run / "model.pt").exists() and (run / "last.pt").exists()


class _FailingStep(Hook):
    def after_step(self, state):
        if state.step == 3:  # after the first step of epoch 1
            raise DcslamError("stop here")


def test_after_train_runs_when_a_step_fails(workspace):
    recorder = _Recorder()
    run = workspace / "runs" / "fails"
    with pytest.raises(DcslamError, match="stop here"):
        train(run, _config(workspace, epochs=2), hooks=[_FailingStep(), recorder])
    assert recorder.calls == ["before_train", "after_epoch 0", "after_train"]
    assert [r["step"] for r in _rows(run) if r["kind"] == "train"] == [0, 1, 2]  # rows up to the failure, flushed


def test_lr_factor():
    assert lr_factor("constant", 7, 10) == 1.0
    assert lr_factor("cosine", 0, 10) == 1.0
    assert lr_factor("cosine", 5, 10) == pytest.approx(0.5)
    assert lr_factor("cosine", 10, 10) == pytest.approx(0.0, abs=1e-12)
    assert lr_factor("cosine", 3, 10) == pytest.approx(0.5 * (1 + math.cos(0.3 * math.pi)))
    with pytest.raises(DcslamError, match="lr schedule"):
        lr_factor("step", 0, 10)


def test_the_cosine_schedule_reaches_the_optimizer(workspace):
    run = workspace / "runs" / "cos"
    train(run, _config(workspace, epochs=2, lr=1e-2, lr_schedule="cosine"))
    lrs = [r["lr"] for r in _rows(run) if r["kind"] == "train"]
    assert lrs == pytest.approx([1e-2 * lr_factor("cosine", s, 4) for s in range(4)])


TRAINING_MODULES = ("train", "train_pose", "objective", "hooks", "forward")


def _imports(module: str) -> set[str]:
    """The training modules that ``dcslam.depth.<module>`` imports anywhere (function bodies and TYPE_CHECKING
    blocks included)."""
    tree = ast.parse((Path(__file__).parents[2] / "dcslam" / "depth" / f"{module}.py").read_text())
    found = set()
    for node in ast.walk(tree):
        names = [node.module or ""] if isinstance(node, ast.ImportFrom) else \
            [a.name for a in node.names] if isinstance(node, ast.Import) else []
        found |= {n.rsplit(".", 1)[-1] for n in names if n.startswith("dcslam.depth.")} & set(TRAINING_MODULES)
    return found


def test_the_training_modules_import_no_cycle():
    graph = {m: _imports(m) for m in TRAINING_MODULES}
    assert graph["train_pose"] == {"forward"} and "hooks" in graph["train"]  # the graph is read at all
    done, active = set(), []

    def visit(m):
        assert m not in active, f"import cycle: {' -> '.join(active + [m])}"
        if m not in done:
            active.append(m)
            for n in graph[m]:
                visit(n)
            active.pop()
            done.add(m)

    for m in TRAINING_MODULES:
        visit(m)


def test_the_early_stopping_example_of_extending_md():
    import re
    from types import SimpleNamespace

    page = (Path(__file__).parents[2] / "docs" / "extending.md").read_text()
    block = next(b for b in re.findall(r"```python\n(.*?)```", page, re.S) if b.startswith("# mypkg/stopping.py"))
    namespace = {}
    exec(compile(block, "docs/extending.md stopping block", "exec"), namespace)
    hook = namespace["EarlyStopping"](patience=2)
    assert isinstance(hook, Hook)
    state = SimpleNamespace(stop=False, last_val={"mse": 1.0}, best=None)
    stops = []
    for epoch, best_epoch in enumerate([0, 1, 1, 3, 3, 3]):  # improves in epochs 0, 1 and 3
        state.epoch, state.best = epoch, {"epoch": best_epoch}
        hook.after_epoch(state)
        stops.append(state.stop)
    assert stops == [False, False, False, False, False, True]
