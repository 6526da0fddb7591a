"""Slurm resources no partition can satisfy are refused before submission, naming the partition's limits; read
from a parsed ``sinfo`` (no cluster needed)."""
import pytest

from dcslam.errors import DcslamError
from dcslam.executor import DEFAULT_RESOURCES, Resources, SlurmSettings, check_resources, parse_sinfo

ONE_NODE = "debug* 2 7950 infinite (null)\n"
MIXED = """\
cpu* 32 128000 2-00:00:00 (null)
cpu* 64 256000 2-00:00:00 (null)
gpu 16 64000 12:00:00 gpu:a100:4(S:0-1)
short 8 16000 30:00 gpu:2
"""


def test_sinfo_is_read_per_partition_with_the_largest_node():
    parts = parse_sinfo(MIXED + "garbage line\n")
    assert set(parts) == {"cpu", "gpu", "short"}
    assert (parts["cpu"].cpus, parts["cpu"].mem_gb, parts["cpu"].time_min, parts["cpu"].default) == \
        (64, 250.0, 2880, True)
    assert (parts["gpu"].gpus, parts["gpu"].time_min, parts["gpu"].default) == (4, 720, False)
    assert (parts["short"].gpus, parts["short"].time_min) == (2, 30)
    assert parse_sinfo(ONE_NODE)["debug"].time_min is None


def test_the_default_resources_on_a_one_node_cluster_are_refused_with_its_limits():
    with pytest.raises(DcslamError, match=r"^the train jobs ask 4 CPUs, 16 GB, 720 min, 0 GPUs, more CPUs, GB than a "
                                          r"node of partition debug offers \(2 CPUs, 7\.8 GB, no time limit, 0 GPUs\); "
                                          r"set cpus, mem_gb and time_min within those in \[slurm\.train\]"):
        check_resources("train", DEFAULT_RESOURCES["train"], 0, parse_sinfo(ONE_NODE))


def test_resources_that_fit_pass_and_the_named_partition_decides():
    small = SlurmSettings.from_table({"train": {"cpus": 2, "mem_gb": 6}, "predict": {"mem_gb": 6}})
    for kind, res in small.resources.items():
        check_resources(kind, res, 0, parse_sinfo(ONE_NODE))
    parts = parse_sinfo(MIXED)
    check_resources("train", Resources(cpus=8, mem_gb=32, time_min=600), 4, parts, "gpu")
    with pytest.raises(DcslamError, match=r"more GPUs, minutes than a node of partition short offers"):
        check_resources("train", Resources(cpus=8, mem_gb=8, time_min=60), 4, parts, "short")
    with pytest.raises(DcslamError, match=r"partition 'big' is not one of this cluster's \(cpu, gpu, short\)"):
        check_resources("slam", Resources(), 0, parts, "big")


def test_the_executor_checks_before_it_submits(tmp_path, monkeypatch):
    import shutil
    import sys
    import types

    from dcslam import executor
    from dcslam.executor import SlurmExecutor, Task

    monkeypatch.setitem(sys.modules, "submitit", types.SimpleNamespace(AutoExecutor=None))
    monkeypatch.setattr(shutil, "which", lambda name: "/usr/bin/" + name)
    monkeypatch.setattr(executor, "_partitions", lambda: parse_sinfo(ONE_NODE))
    task = Task("train-x", lambda *a, **k: None, types.SimpleNamespace(device="cpu"), tmp_path, kind="train")
    with pytest.raises(DcslamError, match="the train jobs ask 4 CPUs"):
        next(SlurmExecutor(tmp_path, log=lambda line: None).submit([task]))
