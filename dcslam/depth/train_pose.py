"""The pose loss inside training (docs/training.md, "The pose loss"): the :class:`dcslam.depth.pose.PoseLoss` of a
training configuration and the validation pass of the pose loss; the network's prediction with its confidence (the
pose loss's per-pixel ICP weights) is :func:`dcslam.depth.forward.run_model_with_confidence`.
:mod:`dcslam.depth.objective` composes them into the training objective and :mod:`dcslam.depth.hooks` into the
validation; nothing here imports the training loop.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import torch

from dcslam.depth.data import DriveFrames, frame_windows
from dcslam.depth.forward import run_model_with_confidence
from dcslam.errors import DcslamError

if TYPE_CHECKING:
    from dcslam.depth.config import TrainConfig


def pose_loss_of(config: TrainConfig):
    """The :class:`dcslam.depth.pose.PoseLoss` of a configuration."""
    from dcslam.depth.pose import PoseLoss, PoseLossSettings, default_odometry

    odometry = default_odometry(config.pose_iterations, config.pose_grad_iterations, config.pose_source_voxel)
    return PoseLoss(odometry, settings=PoseLossSettings(config.pose_translation_weight, config.pose_rotation_weight,
                                                        config.pose_max_sources))


#: Seed of the random pixel subsets that the pose loss aligns during validation (see :func:`validate_pose`).
VALIDATION_SEED = 0


def validate_pose(model, drives: list[DriveFrames], pose, frames_per_window: int, device,
                  use_confidence: bool = True) -> dict:
    """The pose loss of the validation drives without back-propagation: its mean over the windows of
    ``frames_per_window`` frames (those of >= 2 frames) of each drive, averaged over the drives, with the mean
    translation (m) and rotation (rad) error per step. The pose loss aligns a random subset of each frame's pixels
    (``pose_max_sources``); validation draws it from a fixed seed, so that two checkpoints (or a model before and
    after fine-tuning) are compared on the same pixels, and the caller's random stream is left as it was."""
    per_drive = []
    model.eval()
    with torch.no_grad(), torch.random.fork_rng(devices=[]):
        torch.manual_seed(VALIDATION_SEED)
        for frames in drives:
            rows = []
            for window in frame_windows(len(frames), frames_per_window):
                if len(window) < 2:
                    continue
                batch = frames.load(window).to(device)
                pred, confidence = run_model_with_confidence(model, batch, use_confidence)
                loss, details = pose(pred, batch.K, batch.T_world_cam, confidence)
                rows.append((float(loss), float(details["translation_m"].mean()),
                             float(details["rotation_rad"].mean())))
            if rows:
                per_drive.append(np.mean(rows, axis=0))
    model.train()
    if not per_drive:
        raise DcslamError(f"no validation drive has {frames_per_window} frames for the pose loss")
    mean = np.mean(per_drive, axis=0)
    return {"pose": float(mean[0]), "pose_translation_m": float(mean[1]), "pose_rotation_rad": float(mean[2])}
