"""Depth completers as predictors: a trained network or a registered classical completer, with its provenance.
(Running one over drives and writing layers is :mod:`dcslam.stages.predict`.)

A completer maps one sparse depth map (H, W) float32 metres to a dense one of the same shape: IP-Basic directly,
or a trained network through :class:`NetworkCompleter` (which applies the down-scaling the run was trained with and
brings the prediction back to full resolution).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dcslam.depth.data import check_view, downscale_depth
from dcslam.depth.models import ALIASES, CLASSICAL, IP_BASIC_NAMES, build_classical, classical_name
from dcslam.errors import DcslamError
from dcslam.constants import MIN_DEPTH_M


class NetworkCompleter:
    """A trained network as a completer. ``scale`` is the run's training scale (1/integer)."""

    def __init__(self, model, device, scale: float = 1.0, name: str = "network"):
        self.model, self.device, self.name = model, device, name
        self.factor = check_view(scale, 0)

    @property
    def has_confidence(self) -> bool:
        """Whether the network says how sure it is (:func:`dcslam.depth.forward.gives_confidence`: nconv, a
        sparse-conv trained with a confidence loss)."""
        from dcslam.depth.forward import gives_confidence

        return gives_confidence(self.model)

    def __call__(self, sparse_m: np.ndarray) -> np.ndarray:
        """(H, W) float32 metres → (H, W) float32 metres (finite; 0 = none, else ≥ :data:`MIN_DEPTH_M`).

        Outputs below 0.1 m become holes: no depth sensor here measures that near, and a network that outputs them
        (a chamfer-trained one settles on ~0.2 mm where no LiDAR reaches) is saying nothing.
        """
        return self.complete(sparse_m)[0]

    @property
    def guided(self) -> bool:
        """Whether the network also takes the colour image (give ``rgb`` to :meth:`complete`)."""
        return bool(getattr(self.model, "GUIDED", False))

    def complete(self, sparse_m: np.ndarray, rgb: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """Like :meth:`__call__`, with the network's confidence (H, W) float32 in [0, 1] (0 at holes), or None
        for a network without one; a network with an ``empty_below`` confidence leaves the pixels below it empty.
        ``rgb`` (H, W, 3) uint8 is required by guided networks."""
        import cv2
        import torch

        from dcslam.depth.data import downscale_rgb

        if sparse_m.ndim != 2:
            raise DcslamError(f"sparse depth has shape {sparse_m.shape}, expected (H, W)")
        h, w = sparse_m.shape
        small = downscale_depth(np.asarray(sparse_m, np.float32), self.factor)
        # inference_mode, not no_grad: no version counters or views tracked (faster, less memory); the outputs
        # leave as NumPy arrays, so no inference tensor reaches autograd
        with torch.inference_mode():
            x = torch.from_numpy(small)[None, None].to(self.device)
            mask = (x > 0).to(x.dtype)
            extra = ()
            if self.guided:
                if rgb is None or np.shape(rgb) != (h, w, 3):
                    raise DcslamError(f"{self.name} is guided: it needs the (H, W, 3) colour image of the frame")
                extra = (torch.from_numpy(np.ascontiguousarray(downscale_rgb(rgb, self.factor).transpose(2, 0, 1)))
                         [None].to(self.device, x.dtype),)
            if self.has_confidence:
                pred, confidence = (t[0, 0].float().cpu().numpy()
                                    for t in self.model.forward_with_confidence(x, mask, *extra))
            else:
                pred, confidence = self.model(x, mask)[0, 0].float().cpu().numpy(), None
        pred = np.nan_to_num(pred, nan=0.0, posinf=0.0, neginf=0.0)
        pred[pred < MIN_DEPTH_M] = 0
        empty_below = getattr(self.model, "empty_below", None)
        if confidence is not None and empty_below is not None:  # what it says it cannot place stays empty
            pred[~(confidence >= empty_below)] = 0
        if confidence is not None:
            confidence = np.clip(np.nan_to_num(confidence, nan=0.0), 0, 1)
            confidence[pred == 0] = 0
        if pred.shape != (h, w):
            pred = cv2.resize(pred, (w, h), interpolation=cv2.INTER_NEAREST)
            if confidence is not None:
                confidence = cv2.resize(confidence, (w, h), interpolation=cv2.INTER_NEAREST)
        return pred.astype(np.float32), None if confidence is None else confidence.astype(np.float32)


@dataclass
class Predictor:
    """A completer with its provenance: ``made_by`` names the layer's maker, ``config`` is recorded in the layer."""

    completer: object
    made_by: str
    config: dict


def classical_predictor(name: str) -> Predictor:
    """A registered classical completer (:data:`dcslam.depth.models.CLASSICAL`; aliases such as ``ip-basic``
    resolve to their registered name, which is the layer's ``made_by`` and folder name)."""
    from dataclasses import asdict, is_dataclass

    registered = classical_name(name)
    if registered is None:
        raise DcslamError(f"unknown completer {name!r}; expected one of {', '.join([*CLASSICAL, *ALIASES])}")
    completer = build_classical(registered)
    config = asdict(completer) if is_dataclass(completer) else {}
    return Predictor(completer, registered, {"model": registered, **config})


def ip_basic_predictor(name: str) -> Predictor:
    """``ip-basic-fast`` or ``ip-basic-multiscale`` (``ip-basic`` = fast)."""
    if classical_name(name) not in IP_BASIC_NAMES:
        raise DcslamError(f"unknown IP-Basic variant {name!r}; expected one of {', '.join(IP_BASIC_NAMES)}")
    return classical_predictor(name)
