"""dcslam: depth completion trained through a differentiable dense SLAM.

The front door (:mod:`dcslam.api`), loaded on first use so that ``dcslam --help`` stays fast::

    import dcslam

    completed = dcslam.complete(sparse_m, "planefit")         # complete one depth map (or a drive: complete_drive)
    run = dcslam.run_slam("workspace/drives/<drive>.h5", depth="sparse", frames=30)   # or slam_arrays(depths, K)
    print(dcslam.score_trajectory(run.T_gt, run.T_world_cam).localisation)
    trained = dcslam.load_run("workspace/runs/mse-dense")    # a training run: settings, metrics, its completer
"""
import os

from dcslam.version import __version__

# MKL's conditional numerical reproducibility, unless the caller chose a mode: the same bits on every x86 CPU. MKL
# otherwise picks its kernels by CPU (AVX-512, AVX2, ...), and the ICP's normal equations (J^T J) summed in another
# order move a SLAM run's localisation in the third digit between machines; the compatible kernels cost a 30-frame
# SLAM run nothing measurable (docs/architecture.md). Read by MKL when torch first calls it: set before torch loads.
os.environ.setdefault("MKL_CBWR", "COMPATIBLE")

__all__ = ["__version__", "SlamSettings", "TrainedRun", "TrajectoryScores", "complete", "complete_drive",
           "load_completer", "load_run", "run_slam", "score_trajectory", "slam_arrays"]


def __getattr__(name: str):
    # the public names live in dcslam.api, which imports NumPy and the SLAM settings: load it only when asked
    if name in __all__:
        from dcslam import api

        return getattr(api, name)
    raise AttributeError(f"module 'dcslam' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
