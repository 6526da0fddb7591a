"""What the SLAM loop (:class:`dcslam.slam.pipeline.SLAM`) asks of its parts: an :class:`Odometry` and a
:class:`Mapper`. The loop calls these methods on every part alike and reads these attributes instead of asking a
part what class it is; a part with nothing to do in a hook implements it as a no-op.

The scene scale: settings in metres (voxel sizes, the ICP gate) are chosen for streets; the SLAM measures the scale
of the scene it is in from its first frame (``scale`` in (0, 1], 1 for a street, ~0.2 for a room) and passes it to
every call that uses them. A part never has its settings rewritten: it multiplies its own settings by the ``scale``
it is given, and :meth:`Odometry.effective_settings` / :meth:`Mapper.effective_settings` say what they came to.
One sequence (from ``reset`` to the next) uses one scale.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Protocol, runtime_checkable

if TYPE_CHECKING:
    import torch

    from dcslam.slam.frame import Frame
    from dcslam.slam.odometry import OdometryResult
    from dcslam.slam.pointmap import ModelView, PointMap


@runtime_checkable
class Odometry(Protocol):
    """The pose of each new frame (:class:`~dcslam.slam.odometry.ICPOdometry`,
    :class:`~dcslam.slam.odometry.GroundTruthOdometry`).

    Attributes:
        first_pose_from_gt: the first frame of a sequence takes its ground-truth pose when the caller gives one
            (otherwise the SLAM's ``T_world_cam0``).
        assess_steps: the steps are estimates that can fail, to be judged by :mod:`dcslam.slam.health`; false for
            poses that are given.
    """

    first_pose_from_gt: bool
    assess_steps: bool

    def estimate(self, frame: Frame, model: ModelView | None, T_init: torch.Tensor,
                 T_gt: torch.Tensor | None = None, T_last: torch.Tensor | None = None,
                 scale: float = 1.0) -> OdometryResult:
        """The pose of ``frame`` against ``model`` (the map rendered at ``T_init``, None when empty), starting from
        the prediction ``T_init``; ``T_gt`` the frame's ground-truth pose if known, ``T_last`` the previous frame's
        estimate. Shape: T_init, T_gt, T_last (4, 4)."""
        ...

    def reset(self) -> None:
        """Forget what past steps taught; called at the start of a sequence."""
        ...

    def precompute(self, frame: Frame, scale: float = 1.0) -> None:
        """Work on ``frame`` that depends on the frame (and the scale) alone, kept in ``frame.cache``: safe on another
        thread while the previous frame is processed, with the results :meth:`estimate` would compute."""
        ...

    def effective_settings(self, scale: float) -> dict:
        """The metric settings :meth:`estimate` uses at ``scale`` (e.g. ``source_voxel``, ``max_distance``, metres),
        named as the requested settings they come from."""
        ...


@runtime_checkable
class Mapper(Protocol):
    """The map that frames are fused into and that odometry aligns to (:class:`~dcslam.slam.fusion.PointFusion`,
    :class:`~dcslam.slam.icpslam.ICPSLAM`). ``map``: the current (local) map, None before the first frame."""

    map: PointMap | None

    def reset(self) -> None:
        """Empty the map; called at the start of a sequence."""
        ...

    def integrate(self, frame: Frame, T_world_cam: torch.Tensor, scale: float = 1.0) -> PointMap:
        """Fuse ``frame`` seen from ``T_world_cam`` (4, 4); returns the new map."""
        ...

    def model(self, T_world_cam: torch.Tensor, K: torch.Tensor, height: int, width: int) -> ModelView | None:
        """The map rendered into a camera at ``T_world_cam`` (4, 4) with intrinsics ``K`` (3, 3); None when empty."""
        ...

    def precompute(self, frame: Frame) -> None:
        """Work on ``frame`` that depends on the frame alone (see :meth:`Odometry.precompute`)."""
        ...

    def global_map(self) -> PointMap | None:
        """The whole map, including points that left the local map."""
        ...

    def effective_settings(self, scale: float) -> dict:
        """The metric settings :meth:`integrate` uses at ``scale`` (e.g. ``voxel_size``, metres)."""
        ...
