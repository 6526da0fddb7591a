"""The training objective and the validation pass of a training run (docs/training.md): :class:`Objective`, the
loss of a configuration (masked MSE, map chamfer or the pose loss, plus geometry terms), and :func:`validate`, the
depth metrics of the validation drives. The training loop (:mod:`dcslam.depth.train`) and its validation hook
(:class:`dcslam.depth.hooks.Validation`) use both.
"""
from __future__ import annotations

import math

import numpy as np
import torch

from dcslam.depth.config import TrainConfig
from dcslam.depth.data import DriveFrames, frame_windows
from dcslam.depth.forward import run_model
from dcslam.depth.losses import GeometryTerms, MaskedMSE, batch_depth_errors, confidence_loss
from dcslam.depth.maps import MapChamfer
from dcslam.depth.train_pose import pose_loss_of
from dcslam.errors import DcslamError


class Objective:
    """The training loss of a configuration: ``objective(pred, batch)`` → scalar; :attr:`parts` holds the terms of
    the last call (pose loss: ``pose``, its mean ``pose_translation_m`` and ``pose_rotation_rad`` per step, and
    ``mse`` / ``chamfer`` when weighted in; with geometry terms (``normal_weight``, ``plane_weight``,
    ``edge_weight``): those of them weighted in, ``normal`` / ``plane`` / ``edge``, beside the loss's own term,
    ``mse`` or ``chamfer``, which they are added to)."""

    def __init__(self, config: TrainConfig, map_builder=None):
        self.loss = config.loss
        self.mse = MaskedMSE(config.mask, config.l1_weight)
        self.chamfer = MapChamfer(config.map_frames, map_builder, config.chamfer_distance)
        self.pose = pose_loss_of(config) if config.loss == "pose" else None
        self.geometry = GeometryTerms(config.normal_weight, config.plane_weight, config.edge_weight)
        self.weights = {"pose": config.pose_weight, "mse": config.mse_weight, "chamfer": config.chamfer_weight}
        self.confidence_weight = config.confidence_weight
        self.pose_weights = config.pose_weights
        self.parts: dict = {}

    def __call__(self, pred, batch, confidence=None):
        """``confidence`` (B, 1, h, w) or None: the network's, for the confidence loss (``confidence_weight``) and
        as the pose loss's per-pixel ICP weights (``pose_weights`` confidence)."""
        geometry = self.geometry(pred, batch.dense, batch.K)
        if self.confidence_weight > 0:
            if confidence is None:
                raise DcslamError("--confidence-weight needs a network that gives a confidence (sparse-conv "
                                  "--correct-fill trained with it, nconv, nconv-guided)")
            geometry = {**geometry, "confidence": confidence_loss(confidence, pred, batch.dense)}
        if self.loss in ("mse", "chamfer"):
            own = self.mse(pred, batch.sparse, batch.dense) if self.loss == "mse" else \
                self.chamfer(pred, batch.dense, batch.K, batch.T_world_cam)
            if geometry:
                self.parts = {k: float(v.detach()) for k, v in {self.loss: own, **geometry}.items()}
            return own + self._weighted(geometry)
        weights = confidence if self.pose_weights == "confidence" else None
        pose, details = self.pose(pred, batch.K, batch.T_world_cam, weights)
        terms = {"pose": pose}
        if self.weights["mse"] > 0:
            terms["mse"] = self.mse(pred, batch.sparse, batch.dense)
        if self.weights["chamfer"] > 0:
            terms["chamfer"] = self.chamfer(pred, batch.dense, batch.K, batch.T_world_cam)
        self.parts = {**{k: float(v.detach()) for k, v in {**terms, **geometry}.items()},
                      "pose_translation_m": float(details["translation_m"].mean()),
                      "pose_rotation_rad": float(details["rotation_rad"].mean()), "pose_rejected": details["rejected"]}
        return sum(self.weights[k] * v for k, v in terms.items()) + self._weighted(geometry)

    def _weighted(self, terms: dict):
        """The geometry terms weighted (:meth:`GeometryTerms.weighted`) plus the confidence term's share."""
        rest = {k: v for k, v in terms.items() if k != "confidence"}
        total = self.geometry.weighted(rest)
        return total + self.confidence_weight * terms["confidence"] if "confidence" in terms else total


def validate(model, drives: list[DriveFrames], map_frames: int, device, map_builder=None,
             geometry: GeometryTerms | None = None) -> dict:
    """The validation pass: no back-propagation, metrics per drive averaged over the drives.

    Returns ``{"chamfer": m², "mse": m², "mae_mm": mm, "rmse_mm": mm}``, and the mean over the windows of each of the
    ``geometry`` terms (``normal``, ``plane``, ``edge``) weighted in; chamfer uses maps of ``map_frames`` frames.
    """
    chamfer = MapChamfer(map_frames, map_builder)
    geometry = geometry or GeometryTerms()
    per_drive = []
    model.eval()
    with torch.no_grad():
        for frames in drives:
            sq, ab, n, chamfers, terms = 0.0, 0.0, 0, [], {t: [] for t in geometry.weights}
            for window in frame_windows(len(frames), map_frames):
                batch = frames.load(window).to(device)
                pred = run_model(model, batch)
                chamfers.append(float(chamfer(pred, batch.dense, batch.K, batch.T_world_cam)))
                for term, value in geometry(pred, batch.dense, batch.K).items():
                    terms[term].append(float(value))
                e = batch_depth_errors(pred, batch.dense)
                if e["pixels"]:
                    sq += e["mse"] * e["pixels"]
                    ab += e["mae_mm"] * e["pixels"]
                    n += e["pixels"]
            if n == 0:
                raise DcslamError(f"validation drive {frames.name} has no ground-truth depth")
            mse = sq / n
            per_drive.append({"chamfer": float(np.mean(chamfers)), "mse": mse, "mae_mm": ab / n,
                              "rmse_mm": math.sqrt(mse) * 1000.0, **{t: float(np.mean(v)) for t, v in terms.items()}})
    model.train()
    return {key: float(np.mean([d[key] for d in per_drive]))
            for key in ("chamfer", "mse", "mae_mm", "rmse_mm", *geometry.weights)}
