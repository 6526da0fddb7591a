"""dcslam.workers: the spawned worker pool of synth, reproduce and the beams table."""
import pytest

from dcslam.workers import THREAD_VARIABLES, process_pool


def _threads() -> tuple:
    import os

    import torch

    return tuple(os.environ.get(name) for name in THREAD_VARIABLES), torch.get_num_threads()


def test_workers_use_one_thread_each():
    with process_pool(jobs=4, tasks=2) as pool:
        assert pool._max_workers == 2  # never more workers than tasks
        results = [pool.submit(_threads).result() for _ in range(2)]
    assert results == [(("1",) * len(THREAD_VARIABLES), 1)] * 2


def test_own_load_averages_this_process_cpu_as_the_kernel_averages_the_load():
    """Two busy threads for 60 s make 2 (1 - 1/e) of the load; a minute idle after takes that down by 1/e."""
    import math

    from dcslam.workers import OwnLoad

    clock, cpu = [100.0], [5.0]
    load = OwnLoad(clock=lambda: clock[0], cpu=lambda: cpu[0])
    assert load.read() == 0.0
    clock[0], cpu[0] = 160.0, 125.0
    assert load.read() == pytest.approx(2 * (1 - math.exp(-1)))
    clock[0] += 60.0
    assert load.read() == pytest.approx(2 * (1 - math.exp(-1)) * math.exp(-1))
    assert load.read() == pytest.approx(2 * (1 - math.exp(-1)) * math.exp(-1))    # no time passed: unchanged
