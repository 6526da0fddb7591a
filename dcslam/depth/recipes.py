"""The training recipes' names, decoded in this one place (no torch: the command line imports it).

A recipe is a loss (``mse`` with a ``sparse`` or ``dense`` mask, or ``chamfer`` over maps of ``map_frames`` frames).
"""
from __future__ import annotations

LOSSES = ("mse", "chamfer")
MASKS = ("sparse", "dense")
LR_SCHEDULES = ("constant", "cosine")


def map_frames_of(loss: str, map_frames: int) -> int:
    """Frames per chamfer map of a recipe: ``map_frames`` for chamfer, 1 otherwise (MSE validates 1-frame maps)."""
    return map_frames if loss == "chamfer" else 1


def selection_key(loss: str) -> str:
    """The validation metric that picks a run's best checkpoint: its own loss (``chamfer`` or ``mse``)."""
    return "chamfer" if loss == "chamfer" else "mse"


def run_name(loss: str, mask: str, map_frames: int) -> str:
    """The default run name of a recipe: ``mse-<mask>`` or ``chamfer-<map frames>``."""
    return f"{loss}-{mask}" if loss == "mse" else f"{loss}-{map_frames}"


def recipe_label(settings: dict) -> str:
    """The thesis's name of a training recipe from a run's settings (``loss``, ``mask``, ``map_frames``)."""
    loss = settings.get("loss")
    if loss == "chamfer":
        return "chamfer single-frame" if int(settings.get("map_frames", 1)) <= 1 else "chamfer multi-frame"
    if loss == "mse":
        return f"MSE {settings.get('mask', 'dense')} mask"
    return f"{loss} (unknown recipe)"
