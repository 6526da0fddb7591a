"""Running a depth completer over drives and writing one prediction layer per drive.

A completer maps one sparse depth map (H, W) float32 metres to a dense one of the same shape: IP-Basic directly,
or a trained network through :class:`NetworkCompleter` (which applies the down-scaling the run was trained with and
brings the prediction back to full resolution).
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dcslam.depth.data import check_view, downscale_depth
from dcslam.depth.models import ALIASES, CLASSICAL, IP_BASIC_NAMES, build_classical, classical_name
from dcslam.errors import DcslamError
from dcslam.eval.depth import MIN_DEPTH_M


class NetworkCompleter:
    """A trained network as a completer. ``scale`` is the run's training scale (1/integer)."""

    def __init__(self, model, device, scale: float = 1.0, name: str = "network"):
        self.model, self.device, self.name = model, device, name
        self.factor = check_view(scale, 0)

    def __call__(self, sparse_m: np.ndarray) -> np.ndarray:
        """(H, W) float32 metres → (H, W) float32 metres (finite; 0 = none, else ≥ :data:`MIN_DEPTH_M`).

        Outputs below 0.1 m become holes: no depth sensor here measures that near, and a network that outputs them
        (a chamfer-trained one settles on ~0.2 mm where no LiDAR reaches) is saying nothing.
        """
        import cv2
        import torch

        if sparse_m.ndim != 2:
            raise DcslamError(f"sparse depth has shape {sparse_m.shape}, expected (H, W)")
        h, w = sparse_m.shape
        small = downscale_depth(np.asarray(sparse_m, np.float32), self.factor)
        with torch.no_grad():
            x = torch.from_numpy(small)[None, None].to(self.device)
            pred = self.model(x, (x > 0).to(x.dtype))[0, 0].float().cpu().numpy()
        pred = np.nan_to_num(pred, nan=0.0, posinf=0.0, neginf=0.0)
        pred[pred < MIN_DEPTH_M] = 0
        if pred.shape != (h, w):
            pred = cv2.resize(pred, (w, h), interpolation=cv2.INTER_NEAREST)
        return pred.astype(np.float32)


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


def run_predictor(run_dir: Path | str, device) -> Predictor:
    """The best model of a training run (``runs/<run>/model.pt``), with the run's scale."""
    from dcslam.depth.models import load_model

    run_dir = Path(run_dir)
    model, meta = load_model(run_dir / "model.pt", device=str(device))
    scale = float(meta.get("scale", 1.0))
    config = {"run": run_dir.name, "model_file": str(run_dir / "model.pt"), "arch": model.ARCH,
              "hparams": model.hparams, "scale": scale, "checkpoint": {k: meta[k] for k in ("epoch", "step") if k in meta}}
    config_path = run_dir / "config.json"
    if config_path.exists():
        config["train_settings"] = json.loads(config_path.read_text()).get("settings", {})
    return Predictor(NetworkCompleter(model, device, scale, run_dir.name), run_dir.name, config)


def predict_drive(predictor: Predictor, drive_path: Path | str, out_path: Path | str, force: bool = False,
                  progress: bool = True) -> Path:
    """Complete every frame's sparse depth of a drive and write the layer ``out_path`` atomically.

    The layer holds ``depth`` (N, H, W) float32 metres, the same frames as the drive.
    """
    from dcslam.io.drive import DriveFile, Layer, write_layer
    from dcslam.progress import track

    out_path = Path(out_path)
    if out_path.exists() and not force:
        raise DcslamError(f"{out_path} exists; pass --force to overwrite it")
    with DriveFile(drive_path) as drive:
        n, h, w = drive.shape
        depth = np.zeros((n, h, w), np.float32)
        frames = range(n)
        for i in (track(frames, f"predict {drive.name}") if progress else frames):
            depth[i] = predictor.completer(drive.depth("sparse", i))
        layer = Layer(depth=depth, drive=drive.path.name, made_by=predictor.made_by,
                      config={**predictor.config, "drive_file": str(drive.path)})
    return write_layer(out_path, layer, force=force)
