"""The training recipes' names, decoded in this one place (no torch: the command line imports it).

A recipe is a loss (``mse`` with a ``sparse`` or ``dense`` mask, ``chamfer`` over maps of ``map_frames`` frames, or
``pose``: the relative-pose error of dcslam's differentiable ICP over windows of frames), for ``pose``
the run it was fine-tuned from (``init``), if any, and the geometry terms added to its loss (``normal_weight``,
``plane_weight``, ``edge_weight`` > 0).
"""
from __future__ import annotations

LOSSES = ("mse", "chamfer", "pose")
MASKS = ("sparse", "dense")
POSE_WEIGHTS = ("confidence", "none")  # per-pixel ICP weights of the pose loss: the network's confidence, or none
#: The geometry terms a training loss may add (docs/training.md, "Geometry losses"), each weighted by the setting
#: ``<term>_weight``: surface-normal angle, point-to-plane distance, mixed depths at depth edges.
GEOMETRY_TERMS = ("normal", "plane", "edge")
#: Distances of the chamfer loss: point to point (the thesis's), or point to plane along the ground-truth map's normals.
CHAMFER_DISTANCES = ("point", "plane")


def geometry_terms(settings: dict) -> tuple[str, ...]:
    """The geometry terms a run's settings weigh in (weight > 0), in :data:`GEOMETRY_TERMS` order."""
    return tuple(t for t in GEOMETRY_TERMS if float(settings.get(f"{t}_weight", 0) or 0) > 0)


def check_pose_options(config) -> None:
    """The pose loss's options of a training configuration (``pose_frames``, the weights, ...); raises
    :class:`dcslam.errors.DcslamError` naming the option."""
    from dcslam.errors import DcslamError

    if config.pose_frames < 2:
        raise DcslamError(f"--pose-frames must be >= 2 (a window of consecutive frames), got {config.pose_frames}")
    for name in ("pose_weight", "mse_weight", "chamfer_weight", "pose_translation_weight", "pose_rotation_weight",
                 "pose_source_voxel"):
        if not 0 <= getattr(config, name) < float("inf"):
            raise DcslamError(f"--{name.replace('_', '-')} must be a number >= 0, got {getattr(config, name)}")
    if config.pose_weights not in POSE_WEIGHTS:
        raise DcslamError(f"unknown --pose-weights {config.pose_weights!r}; expected one of {', '.join(POSE_WEIGHTS)}")
    for name in ("pose_iterations", "pose_grad_iterations", "pose_max_sources"):
        if getattr(config, name) < (1 if name == "pose_iterations" else 0):
            raise DcslamError(f"--{name.replace('_', '-')} must be >= {1 if name == 'pose_iterations' else 0}, "
                              f"got {getattr(config, name)}")
LR_SCHEDULES = ("constant", "cosine")


def map_frames_of(loss: str, map_frames: int) -> int:
    """Frames per chamfer map of a recipe: ``map_frames`` for chamfer, 1 otherwise (MSE validates 1-frame maps)."""
    return map_frames if loss == "chamfer" else 1


def selection_key(loss: str) -> str:
    """The validation metric that picks a run's best checkpoint: its own loss (``chamfer``, ``mse`` or ``pose``)."""
    return loss if loss in ("chamfer", "pose") else "mse"


def run_name(loss: str, mask: str, map_frames: int, init: str | None = None, chamfer_distance: str = "point") -> str:
    """The default run name of a recipe: ``mse-<mask>``, ``chamfer-<map frames>`` (``chamfer-p2plane-<map frames>``
    with the point-to-plane distance), ``pose`` or ``pose-from-<init run>``."""
    if loss == "pose":
        return f"pose-from-{init}" if init else "pose"
    if loss == "chamfer":
        return f"chamfer-p2plane-{map_frames}" if chamfer_distance == "plane" else f"chamfer-{map_frames}"
    return f"{loss}-{mask}"


def init_run(settings: dict) -> str:
    """The name of the run a run was fine-tuned from (its ``init`` model file's folder), "" if none."""
    from pathlib import PurePath

    init = settings.get("init") or ""
    return PurePath(init).parent.name if init else ""


def recipe_label(settings: dict) -> str:
    """The thesis's name of a training recipe from a run's settings (``loss``, ``mask``, ``map_frames``), followed
    by the geometry terms it adds, if any: ``MSE dense mask + normal/plane``."""
    terms = geometry_terms(settings)
    return _loss_label(settings) + (" + " + "/".join(terms) if terms else "")


def _loss_label(settings: dict) -> str:
    loss = settings.get("loss")
    if loss == "chamfer":
        label = "chamfer single-frame" if int(settings.get("map_frames", 1)) <= 1 else "chamfer multi-frame"
        return label + (", point-to-plane" if settings.get("chamfer_distance", "point") == "plane" else "")
    if loss == "mse":
        return f"MSE {settings.get('mask', 'dense')} mask"
    if loss == "pose":
        init = init_run(settings)
        return f"pose, fine-tuned from {init}" if init else "pose from scratch"
    return f"{loss} (unknown recipe)"
