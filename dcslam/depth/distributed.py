"""Training on several processes or machines with PyTorch's own engine (DistributedDataParallel).

Launch with ``dcslam train --nproc N``, which runs ``torchrun --nproc-per-node N -m dcslam.stages.train --workspace
DIR --config FILE`` (:func:`launch`). Each process reads the ``RANK`` / ``WORLD_SIZE`` /
``MASTER_ADDR`` variables torchrun sets, joins the group (``gloo`` on CPU, ``nccl`` on GPUs), and
:func:`dcslam.depth.train.train` deals the steps of each epoch out to the ranks; DDP averages the gradients, so every
rank holds the same weights after every step.
"""
from __future__ import annotations

import os
import subprocess
import sys

from dcslam.errors import DcslamError


def in_torchrun() -> bool:
    """True inside a process started by torchrun with more than one process in the group."""
    return int(os.environ.get("WORLD_SIZE", "1")) > 1


def is_main_process() -> bool:
    """True outside torchrun and on its rank 0 (the process that writes files and prints)."""
    return int(os.environ.get("RANK", "0")) == 0


def init_from_env(device_type: str = "cpu") -> tuple[int, int]:
    """Join the process group described by torchrun's environment; returns (rank, world size)."""
    import torch.distributed as dist

    if dist.is_initialized():
        return dist.get_rank(), dist.get_world_size()
    backend = "nccl" if device_type == "cuda" else "gloo"
    if device_type == "cuda":  # one GPU per process: the job's (or machine's) GPU number LOCAL_RANK
        import torch

        torch.cuda.set_device(int(os.environ.get("LOCAL_RANK", "0")))
    dist.init_process_group(backend=backend)
    return dist.get_rank(), dist.get_world_size()


def shutdown() -> None:
    import torch.distributed as dist

    if dist.is_initialized():
        dist.destroy_process_group()


def launch(nproc: int, module: str, args: list[str]) -> int:
    """Run ``python -m <module> <args>`` on ``nproc`` local processes through torchrun; returns its exit code.

    This is dcslam's only child process: the distributed-training launcher.
    """
    if nproc < 1:
        raise DcslamError(f"--nproc must be >= 1, got {nproc}")
    command = [sys.executable, "-m", "torch.distributed.run", "--standalone", f"--nproc-per-node={nproc}",
               "-m", module, *args]
    return subprocess.call(command)
