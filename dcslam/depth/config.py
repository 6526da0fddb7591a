"""The settings of the depth package's two training loops, declared once and checked once.

:class:`TrainSettings` holds every setting of a training run (:func:`dcslam.depth.train.train_loop`) and
:class:`DenoiseSettings` those of the denoising experiment (:mod:`dcslam.depth.denoise`) that a user chooses. Each
field carries its help text (and choices, option name) in its metadata, so that ``dcslam train`` and ``dcslam
demo-icl``, whose configurations extend these classes, take option names, defaults and help from here; each class
checks its values in ``__post_init__``, the one place they are checked. :class:`TrainConfig` and
:class:`DenoiseConfig` add what a run is given besides (drives, the model to start from, fixed constants).

No torch here: the command line imports this module to list the options.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from dcslam.depth.models import ARCHITECTURES
from dcslam.depth.recipes import (CHAMFER_DISTANCES, GEOMETRY_TERMS, LOSSES, LR_SCHEDULES, MASKS, POSE_WEIGHTS,
                                  check_pose_options, map_frames_of)
from dcslam.errors import DcslamError
from dcslam.settings import option

MODELS = tuple(ARCHITECTURES)
WARMUP_FRACTION = 0.1  # the denoiser's learning rate rises linearly over this fraction of its steps


def flag(name: str) -> str:
    """The option of setting ``name``: ``map_frames`` → ``--map-frames``."""
    return "--" + name.replace("_", "-")


def check_kind(kind: str) -> str:
    """``kind`` if it names depth held in drive files (``sparse``, ``sparse@16``, ``dense``, ``exact``)."""
    from dcslam.io.drive import check_input_kind

    return check_input_kind(kind)


def check_choice(config, name: str, choices) -> None:
    if getattr(config, name) not in choices:
        raise DcslamError(f"unknown {flag(name)} {getattr(config, name)!r}; expected one of {', '.join(choices)}")


def check_at_least_one(config, *names: str) -> None:
    for name in names:
        if getattr(config, name) < 1:
            raise DcslamError(f"{flag(name)} must be >= 1, got {getattr(config, name)}")


def device_option():
    """The ``--device`` option of both training loops (read by :func:`dcslam.device.resolve_device`)."""
    return option("auto", help="auto (a GPU if there is one), cpu or cuda.")


def check_view(scale: float, crop: int) -> None:
    from dcslam.depth.data import check_view as check  # (torch: imported only when a configuration is made)

    check(scale, crop)


@dataclass(frozen=True)
class TrainSettings:
    """What a training run is asked to do: loss, network, optimiser, frames, inputs (no paths)."""

    loss: str = option("mse", choices=LOSSES, help="mse, chamfer or pose (relative-pose error of differentiable "
                                                   "ICP over --pose-frames windows).")
    mask: str = option("dense", choices=MASKS, help="MSE mask: dense (pixels with ground truth) or sparse (pixels "
                                                    "with sparse input and ground truth).")
    map_frames: int = option(1, help="Frames per chamfer map: 1, or windows of up to N frames (the thesis: 8; its "
                                     "code: 7).")
    chamfer_distance: str = option("point", choices=CHAMFER_DISTANCES,
                                   help="Chamfer distance (the chamfer loss and the pose loss's chamfer term): point "
                                        "(squared point-to-point, the thesis's) or plane (squared point-to-plane "
                                        "along the ground-truth map's normals).")
    model: str = option("sparse-conv", choices=MODELS, help=f"Network: {' or '.join(MODELS)}.")
    epochs: int = option(1, help="Passes over the training drives.")
    lr: float = option(1e-3, help="AdamW learning rate.")
    weight_decay: float = option(0.01, help="AdamW weight decay.")
    max_frames: int = option(200, help="At most this many frames per drive.")
    stride: int = option(1, help="Use every N-th frame.")
    scale: float = option(1.0, help="Image scale, 1/integer (1, 0.5, 0.25).")
    crop: int = option(0, help="Keep only the bottom N rows (0 = whole image).")
    batch_size: int = option(1, help="Frames per step (MSE and 1-frame chamfer).")
    seed: int = option(0, help="Random seed.")
    device: str = device_option()
    input: str = option("sparse", validate=check_kind, metavar="KIND",
                        help="Depth fed to the network: sparse (the drive's own), sparse@<beams> (written by "
                             "prepare-kitti --beams), dense or exact.")
    input_mix: list[str] = option(default_factory=list, validate=check_kind, metavar="KIND",
                                  help="Density augmentation (repeatable): each frame's input drawn in turn from "
                                       "these kinds, e.g. --input-mix sparse --input-mix sparse@32 --input-mix "
                                       "sparse@16 --input-mix sparse@8 (one model for every beam count); replaces "
                                       "--input.")
    target: str = option("dense", validate=check_kind, metavar="KIND",
                         help="Depth the loss compares with: dense (annotated) or exact (generated drives only).")
    l1_weight: float = option(0.0, help="MSE loss plus this weight times the mean absolute error (metres) over the "
                                        "same pixels (0 = MSE alone, the thesis's).")
    normal_weight: float = option(0.0, help="Add this weight times the mean of 1 - cos(angle) between the "
                                            "predicted and the --target surface normals (0 = off).")
    plane_weight: float = option(0.0, help="Add this weight times the mean squared distance (m²) of the predicted "
                                           "points from the --target surface, point-to-plane (0 = off).")
    edge_weight: float = option(0.0, help="Add this weight times the mean squared distance (m²) of the predicted "
                                          "points near --target depth edges from the nearer side (0 = off).")
    confidence_weight: float = option(0.0, help="Add this weight times the binary cross-entropy between the "
                                                "network's confidence and whether each pixel lies within "
                                                "PointFusion's association gate of the --target depth (max(0.1 m, "
                                                "2 percent of the depth)): a confidence that says which pixels it "
                                                "placed. sparse-conv --correct-fill (its head's gate; its "
                                                "predictions then leave empty the pixels of confidence below 0.5) "
                                                "and nconv networks (0 = off).")
    lr_schedule: str = option("constant", choices=LR_SCHEDULES, help="constant, or cosine: from --lr down to 0 over "
                                                                     "all the run's steps.")
    pose_frames: int = option(4, help="Pose loss: frames per window (the first at its true pose, the others "
                                      "tracked by ICP).")
    pose_weight: float = option(1.0, help="Pose loss: weight of the pose term.")
    mse_weight: float = option(0.0, help="Pose loss: weight of an added MSE term (with --mask).")
    chamfer_weight: float = option(0.0, help="Pose loss: weight of an added chamfer term (with --map-frames).")
    pose_translation_weight: float = option(1.0, help="Pose loss: weight of the translation error (per metre).")
    pose_rotation_weight: float = option(1.0, help="Pose loss: weight of the rotation error (per radian).")
    pose_iterations: int = option(10, help="Pose loss: LM iterations per ICP gate stage.")
    pose_grad_iterations: int = option(0, help="Pose loss: back-propagate through only the last N LM iterations "
                                               "of each stage (0 = all).")
    pose_max_sources: int = option(0, help="Pose loss: align at most N random valid pixels per frame (0 = all).")
    pose_source_voxel: float = option(0.2, help="Pose loss: ICP keeps one source point per voxel of this size, "
                                                "metres (0 = every point).")
    pose_weights: str = option("confidence", choices=POSE_WEIGHTS, help="Pose loss: per-pixel ICP weights: "
                               "confidence (the network's, for nconv models; others have none) or none.")

    def __post_init__(self) -> None:
        for name, choices in (("loss", LOSSES), ("mask", MASKS), ("model", MODELS), ("lr_schedule", LR_SCHEDULES),
                              ("chamfer_distance", CHAMFER_DISTANCES)):
            check_choice(self, name, choices)
        check_at_least_one(self, "map_frames", "epochs", "max_frames", "stride", "batch_size")
        if not 0 < self.lr < float("inf"):
            raise DcslamError(f"--lr must be a positive number, got {self.lr}")
        for name in ("weight_decay", "l1_weight", "confidence_weight",
                     *(f"{term}_weight" for term in GEOMETRY_TERMS)):
            if not 0 <= getattr(self, name) < float("inf"):
                raise DcslamError(f"{flag(name)} must be a non-negative number, got {getattr(self, name)}")
        check_view(self.scale, self.crop)
        for kind in (self.input, self.target, *self.input_mix):
            check_kind(kind)
        check_pose_options(self)

    @property
    def chunk(self) -> int:
        """Frames per optimisation step: one pose window, one multi-frame map window, else one batch."""
        if self.loss == "pose":
            return self.pose_frames
        frames = map_frames_of(self.loss, self.map_frames)
        return frames if frames > 1 else self.batch_size


@dataclass(frozen=True)
class TrainConfig(TrainSettings):
    """A training run: its settings, the network's hyperparameters and what it trains on (written to
    ``config.json`` as its ``settings``, ``init_model`` under the key ``init``)."""

    model_hparams: dict = field(default_factory=dict)
    train_drives: list[Path] = field(default_factory=list)
    val_drives: list[Path] = field(default_factory=list)
    init_model: Path | None = None  # the model file the network starts from (fine-tuning); None: a new network


@dataclass(frozen=True)
class DenoiseSettings:
    """What the denoising experiment is asked to do: noise, optimiser, network, frames."""

    sigma_m: float = option(0.05, flags=("--sigma",), key="sigma",
                            help="Standard deviation of the Gaussian depth noise, metres.")
    steps: int = option(200, help="Training steps (AdamW).")
    lr: float = option(1e-3, help=f"AdamW learning rate (after a linear warm-up over {WARMUP_FRACTION * 100:g} % of "
                                  "the steps).")
    batch_size: int = option(4, help="Frames per step (single-frame maps).")
    patch: int = option(64, help="Train on random patch × patch windows (0 = whole images).")
    map_frames: int = option(1, help="Frames per chamfer map (1: one map per frame).")
    scale: float = option(0.25, help="Image scale, 1/integer (0.25: 640 × 480 → 160 × 120).")
    features: int = option(32, help="DnCNN feature channels.")
    layers: int = option(8, help="DnCNN layers.")
    seed: int = option(0, help="Seed of the generated rooms, the noise and training.")
    device: str = device_option()

    def __post_init__(self) -> None:
        check_view(self.scale, 0)
        check_at_least_one(self, "steps", "batch_size", "features", "layers", "map_frames")
        if not self.sigma_m > 0:
            raise DcslamError(f"--sigma must be > 0 m, got {self.sigma_m}")
        if self.patch < 0:
            raise DcslamError(f"--patch must be >= 0 (0 = whole images), got {self.patch}")
        if not 0 < self.lr < float("inf"):
            raise DcslamError(f"--lr must be a positive number, got {self.lr}")


@dataclass(frozen=True)
class DenoiseConfig(DenoiseSettings):
    """The denoising experiment: its settings, fixed constants and its drives (written to ``results.json``)."""

    warmup_fraction: float = WARMUP_FRACTION
    weight_decay: float = 0.01
    depth_scale_m: float = 4.0
    map_voxel_m: float = 0.0
    max_frames: int = 200
    stride: int = 1
    heldout_fraction: float = 0.25
    examples: int = 3
    train_drives: list[Path] = field(default_factory=list)
    test_drives: list[Path] = field(default_factory=list)

    def __post_init__(self) -> None:
        super().__post_init__()
        check_at_least_one(self, "max_frames", "stride")
        if self.map_voxel_m < 0 or self.depth_scale_m <= 0:
            raise DcslamError("the map voxel size must be >= 0, the depth scale > 0")
        if not 0 <= self.warmup_fraction < 1:
            raise DcslamError(f"the warm-up fraction must be in [0, 1), got {self.warmup_fraction}")
        if not 0 < self.heldout_fraction < 1:
            raise DcslamError(f"the held-out fraction must be in (0, 1), got {self.heldout_fraction}")
