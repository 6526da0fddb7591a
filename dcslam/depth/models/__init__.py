"""Model registry: build a network by architecture name, save it with its hyperparameters, rebuild it from the file.

A model file is a plain ``torch.save`` of ``{"format": "dcslam.model/1", "arch": str, "hparams": dict,
"state_dict": dict, "meta": dict}`` holding only tensors, numbers, strings, lists and dicts, so it loads with
``torch.load(weights_only=True)`` (no pickled code is ever executed).
"""
from __future__ import annotations

from pathlib import Path

from dcslam.errors import DcslamError
from dcslam.io.atomic import atomic_output

MODEL_FORMAT = "dcslam.model/1"
IP_BASIC_NAMES = ("ip-basic-fast", "ip-basic-multiscale")


def _registry() -> dict:
    from dcslam.depth.models.dncnn import DnCNN
    from dcslam.depth.models.sparse_conv import SparseConvNet

    return {SparseConvNet.ARCH: SparseConvNet, DnCNN.ARCH: DnCNN}


def architectures() -> tuple[str, ...]:
    """Names of the trainable architectures."""
    return tuple(_registry())


def build_model(arch: str, **hparams):
    """A fresh network of architecture ``arch`` (``sparse-conv`` or ``dncnn``)."""
    registry = _registry()
    if arch not in registry:
        raise DcslamError(f"unknown model {arch!r}; expected one of {', '.join(registry)}")
    try:
        return registry[arch](**hparams)
    except TypeError as exc:
        raise DcslamError(f"bad hyperparameters for {arch}: {exc}") from None


def model_record(model, meta: dict | None = None) -> dict:
    """The dictionary written to a model file (tensors moved to the CPU)."""
    return {"format": MODEL_FORMAT, "arch": model.ARCH, "hparams": dict(model.hparams),
            "state_dict": {k: v.detach().cpu() for k, v in model.state_dict().items()}, "meta": dict(meta or {})}


def save_model(path: Path | str, model, meta: dict | None = None, force: bool = True) -> Path:
    """Write ``model`` with its architecture name and hyperparameters, atomically."""
    import torch

    with atomic_output(path, force=force) as tmp:
        torch.save(model_record(model, meta), tmp)
    return Path(path)


def model_from_record(record: dict, source: str = "model record"):
    if not isinstance(record, dict) or record.get("format") != MODEL_FORMAT:
        raise DcslamError(f"{source}: not a dcslam model file (expected format {MODEL_FORMAT})")
    model = build_model(record["arch"], **record["hparams"])
    try:
        model.load_state_dict(record["state_dict"])
    except RuntimeError as exc:
        raise DcslamError(f"{source}: weights do not fit {record['arch']} {record['hparams']}: {exc}") from None
    return model


def load_model(path: Path | str, device: str = "cpu"):
    """Rebuild a model from its file alone (safe load, ``weights_only=True``); returns it in eval mode on ``device``."""
    import pickle

    import torch

    path = Path(path)
    if not path.exists():
        raise DcslamError(f"model file {path} not found; run `dcslam train` first")
    try:
        record = torch.load(path, map_location="cpu", weights_only=True)
    except (RuntimeError, pickle.UnpicklingError, EOFError, ValueError) as exc:
        raise DcslamError(f"{path}: not a readable model file ({str(exc).splitlines()[0]})") from None
    model = model_from_record(record, str(path))
    return model.to(device).eval(), record.get("meta", {})
