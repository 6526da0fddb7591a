"""The ``--device`` option as a torch device: one place for every stage that runs torch (train, predict, slam,
demo-icl), so that a GPU asked for on a machine without one fails the same way before any work."""
from __future__ import annotations


def resolve_device(device: str):
    """The ``torch.device`` of ``device``: ``auto`` → the first GPU if there is one, else the CPU; ``cpu``,
    ``cuda`` or ``cuda:N`` as given. An unknown name, or a GPU on a machine without one, is a DcslamError."""
    import torch

    from dcslam.errors import DcslamError

    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        resolved = torch.device(device)
    except RuntimeError:
        raise DcslamError(f"unknown device {device!r}; expected auto, cpu or cuda") from None
    if resolved.type == "cuda" and not torch.cuda.is_available():
        raise DcslamError("--device cuda, but no GPU is available")
    return resolved
