"""dcslam.workers: the spawned worker pool of synth, reproduce and the beams table."""
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
