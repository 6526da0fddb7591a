"""Completer registry: learned networks and classical completers by name; model files save and rebuild networks.

:data:`ARCHITECTURES` maps a trainable architecture's name to its class, :data:`CLASSICAL` a classical completer's
name (IP-Basic's variants) to its factory; both as ``"module:attribute"`` strings, imported only when built, so
the names are known without importing torch. Adding a completer is one module plus one line here.

A model file is a plain ``torch.save`` of ``{"format": "dcslam.model/1", "arch": str, "hparams": dict,
"state_dict": dict, "meta": dict}`` holding only tensors, numbers, strings, lists and dicts, so it loads with
``torch.load(weights_only=True)`` (no pickled code is ever executed).
"""
from __future__ import annotations

from pathlib import Path

from dcslam import plugins as _plugins
from dcslam.errors import DcslamError
from dcslam.io.atomic import atomic_output

MODEL_FORMAT = "dcslam.model/1"
ARCHITECTURES = {  # trainable network name → "module:class" (the class takes its hyperparameters as keywords)
    "sparse-conv": "dcslam.depth.models.sparse_conv:SparseConvNet",
    "dncnn": "dcslam.depth.models.dncnn:DnCNN",
    "nconv": "dcslam.depth.models.nconv:NConvCNN",
    "nconv-guided": "dcslam.depth.models.nconv:GuidedNConvCNN",
}
CLASSICAL = {  # completer that needs no training → "module:factory" (called with no argument)
    "ip-basic-fast": "dcslam.depth.models.ip_basic:fast",
    "ip-basic-multiscale": "dcslam.depth.models.ip_basic:multiscale",
    "scanline": "dcslam.depth.models.scanline:scanline",
    "planefit": "dcslam.depth.models.planefit:planefit",
}
ALIASES = {"ip-basic": "ip-basic-fast"}  # other names of registered completers
IP_BASIC_NAMES = tuple(name for name in CLASSICAL if name.startswith("ip-basic"))
# installed packages' completers (entry points of dcslam.completers, dcslam/plugins.py): names only, imported when built
_FROM_PACKAGES = _plugins.targets(_plugins.COMPLETERS, {**ARCHITECTURES, **CLASSICAL, **ALIASES})
CLASSICAL.update(_FROM_PACKAGES)


def _load(target: str):
    import importlib

    module, _, attribute = target.partition(":")
    return getattr(importlib.import_module(module), attribute)


def _registry() -> dict:
    return {name: _load(target) for name, target in ARCHITECTURES.items()}


def architectures() -> tuple[str, ...]:
    """Names of the trainable architectures."""
    return tuple(ARCHITECTURES)


def is_guided(arch: str) -> bool:
    """Whether architecture ``arch`` also takes the colour image (``model(sparse, mask, rgb)``)."""
    return arch in ARCHITECTURES and bool(getattr(_load(ARCHITECTURES[arch]), "GUIDED", False))


def classical_name(name: str) -> str | None:
    """The registered name of classical completer ``name`` (aliases resolved), or None if it is not one."""
    name = ALIASES.get(name, name)
    return name if name in CLASSICAL else None


def build_classical(name: str):
    """A classical completer by name (``ip-basic`` = ``ip-basic-fast``): ``(H, W)`` sparse metres → dense."""
    registered = classical_name(name)
    if registered is None:
        raise DcslamError(f"unknown completer {name!r}; expected one of {', '.join([*CLASSICAL, *ALIASES])}")
    if registered not in _FROM_PACKAGES:
        return _load(CLASSICAL[registered])()
    # a plugin's failure is its package's, reported in one line; dcslam's own completers keep their tracebacks
    factory = _plugins.load(_plugins.COMPLETERS, registered, CLASSICAL[registered])
    if not callable(factory):
        raise _plugins.refuse(_plugins.COMPLETERS, registered, f"is a {type(factory).__name__}, not a factory")
    try:
        completer = factory()
    except Exception as exc:
        raise _plugins.refuse(_plugins.COMPLETERS, registered, f"failed to build ({_plugins.reason(exc)})") from None
    if not callable(completer):
        raise _plugins.refuse(_plugins.COMPLETERS, registered, f"built a {type(completer).__name__}, not a "
                              "completer (a callable from (H, W) sparse metres to dense)")
    return completer


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
    return save_torch(path, model_record(model, meta), force)


def save_torch(path: Path | str, obj, force: bool = True) -> Path:
    """``torch.save`` of ``obj`` to ``path``, atomically. The bytes are made in memory and written by Python, so a
    full disk or a read-only filesystem is one :class:`DcslamError` line naming ``path`` and the reason (torch's
    own writer reports it as "unexpected pos ...", without the reason)."""
    import io

    import torch

    buffer = io.BytesIO()
    torch.save(obj, buffer)
    with atomic_output(path, force=force) as tmp:
        with open(tmp, "wb") as f:
            f.write(buffer.getbuffer())
    return Path(path)


def model_from_record(record: dict, source: str = "model record"):
    if not isinstance(record, dict) or record.get("format") != MODEL_FORMAT:
        raise DcslamError(f"{source}: not a dcslam model file (expected format {MODEL_FORMAT})")
    missing = [k for k in ("arch", "hparams", "state_dict") if k not in record]
    if missing or not isinstance(record["hparams"], dict):
        raise DcslamError(f"{source}: model file without {', '.join(missing) or 'a table of hparams'}; retrain the "
                          "run (`dcslam train --force`)")
    try:
        model = build_model(record["arch"], **record["hparams"])
    except TypeError as exc:  # hyperparameters the architecture does not take
        raise DcslamError(f"{source}: hparams {record['hparams']} do not fit {record['arch']} ({exc})") from None
    try:
        model.load_state_dict(record["state_dict"])
    except (RuntimeError, TypeError, AttributeError) as exc:
        # torch lists every mismatch on its own line: the first one says enough, on the one line of an error
        details = [line.strip() for line in str(exc).splitlines() if line.strip()]
        first = details[1] if len(details) > 1 else (details[0] if details else type(exc).__name__)
        more = f" (and {len(details) - 2} more)" if len(details) > 2 else ""
        raise DcslamError(f"{source}: weights do not fit {record['arch']} {record['hparams']}: {first}{more}; "
                          "retrain the run (`dcslam train --force`) or pass the model it was trained as") from None
    return model


def read_torch_file(path: Path, what: str, fix: str):
    """``torch.load(path, weights_only=True)``; a truncated, empty or malicious file is a :class:`DcslamError`
    naming ``path`` (``what`` it should be, and ``fix``: what to do), never a traceback."""
    import torch

    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises RuntimeError, OSError, IndexError, UnpicklingError... on broken files
        reason = (str(exc).strip().splitlines() or [type(exc).__name__])[0].split(". ")[0]
        raise DcslamError(f"{path}: not a readable {what} ({reason}); {fix}") from None


def load_model(path: Path | str, device: str = "cpu"):
    """Rebuild a model from its file alone (safe load, ``weights_only=True``); returns it in eval mode on ``device``."""
    path = Path(path)
    if not path.exists():
        raise DcslamError(f"model file {path} not found; run `dcslam train` first")
    record = read_torch_file(path, "model file", "retrain it with `dcslam train --force`")
    model = model_from_record(record, str(path))
    return model.to(device).eval(), record.get("meta", {})
