"""Synthetic indoor sequences in the ICL-NUIM TUM-compatible layout (``dcslam synth --indoor``).

Per sequence ``i`` under ``out_root``::

    living_room_traj<i>_frei_png/rgb/<k>.png          640 x 480 colour (times ``scale``)
    living_room_traj<i>_frei_png/depth/<k>.png        16-bit z-depth, metres = value / 5000, 0 = none
    living_room_traj<i>_frei_png/associations.txt     "k depth/k.png k rgb/k.png"
    living_room_traj<i>_frei_png/livingRoom<i>.gt.freiburg   T_world_cam of every frame (timestamps = k)
    living_room_traj<i>_frei_png/intrinsics.txt       "fx fy cx cy" (ICL-NUIM's, fy = -480, scaled with ``scale``)
    synth_indoor.json                                 the settings

Files are written through :class:`dcslam.io.tum_rgbd.IclWriter`. The room is :mod:`~dcslam.synth.indoor.room`'s,
the camera and its path :mod:`~dcslam.synth.indoor.camera`'s, the images :mod:`~dcslam.synth.indoor.render`'s.
"""
from __future__ import annotations

import contextlib
import os
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.io.atomic import write_json_atomic
from dcslam.io.tum_rgbd import IclWriter
from dcslam.synth.indoor.camera import camera_K, handheld_trajectory
from dcslam.synth.indoor.render import Look, render
from dcslam.synth.indoor.room import build_room
from dcslam.synth.raycast import CameraGrid


def sequence_name(index: int) -> str:
    """``living_room_traj<index>_frei_png``, ICL-NUIM's folder name."""
    return f"living_room_traj{index}_frei_png"


def trajectory_name(index: int) -> str:
    """``livingRoom<index>.gt.freiburg``, ICL-NUIM's trajectory file name."""
    return f"livingRoom{index}.gt.freiburg"


@dataclass(frozen=True)
class IndoorSequence:
    """One written sequence: its folder, trajectory file, frame count, fraction of pixels with depth, seconds."""

    name: str
    path: Path
    trajectory: Path
    frames: int
    depth_density: float
    seconds: float


@dataclass(frozen=True)
class IndoorResult:
    """What :func:`generate_indoor` wrote: one :class:`IndoorSequence` per sequence, and the settings file."""

    sequences: tuple[IndoorSequence, ...]
    config_path: Path

    @property
    def paths(self) -> tuple[Path, ...]:
        """The sequence folders, in order."""
        return tuple(s.path for s in self.sequences)


def _occupied(path: Path) -> bool:
    return path.exists() and (not path.is_dir() or any(path.iterdir()))


def write_sequence(folder: Path, index: int, frames: int, seed: int, scale: float = 1.0,
                   on_frame: Callable[[], None] | None = None) -> IndoorSequence:
    """Render and write sequence ``index`` of ``seed`` (``frames`` frames) into ``folder``."""
    started = time.perf_counter()
    rng = np.random.default_rng([seed, index, 7])
    room = build_room(rng)
    look = Look(floor_tint=np.clip(np.array([0.62, 0.45, 0.3]) * rng.uniform(0.8, 1.2, 3), 0, 1).astype(np.float32),
                 planks_along_x=bool(rng.random() < 0.5))
    T_world_cam = handheld_trajectory(room, frames, rng)
    K, width, height = camera_K(scale)
    grid = CameraGrid(K, width, height)
    writer = IclWriter(folder, trajectory_name(index), K)
    density = []
    for k in range(frames):
        depth, rgb = render(room, look, grid, T_world_cam[k], rng)
        writer.append(rgb, depth, T_world_cam[k])
        density.append(float(np.mean(depth > 0)))
        if on_frame is not None:
            on_frame()
    writer.close()
    return IndoorSequence(sequence_name(index), folder, folder / trajectory_name(index), frames,
                          float(np.mean(density)), time.perf_counter() - started)


def generate_indoor(out_root: Path | str, sequences: int = 1, frames: int = 60, seed: int = 0, force: bool = False,
                    on_frame: Callable[[], None] | None = None, scale: float = 1.0) -> IndoorResult:
    """Write ``sequences`` synthetic indoor sequences of ``frames`` frames under ``out_root`` (ICL-NUIM layout).

    Sequence ``i`` is ``living_room_traj<i>_frei_png`` and follows from (``seed``, ``i``) alone. ``scale`` resizes
    the 640 x 480 images (and the intrinsics; ``intrinsics.txt`` records them). Refuses (:class:`DcslamError`) to
    replace a sequence folder that exists and is not empty unless ``force``; each sequence is written into a hidden
    temporary folder and renamed when complete. ``on_frame`` is called after each frame (progress).
    """
    from dcslam.workspace import stage_config

    if sequences < 1:
        raise DcslamError(f"sequences must be at least 1, got {sequences}")
    if frames < 1:
        raise DcslamError(f"frames must be at least 1, got {frames}")
    if not 0 < scale <= 4:
        raise DcslamError(f"scale must be in (0, 4], got {scale}")
    camera_K(scale)
    out_root = Path(out_root)
    names = [sequence_name(i) for i in range(sequences)]
    if not force:
        foreign = [p for p in sorted(out_root.iterdir()) if not p.name.startswith(".")
                   and p.name != "synth_indoor.json" and not p.match("living_room_traj*_frei_png")] \
            if out_root.is_dir() else []
        if foreign:  # the sequences of a real dataset beside generated ones would be read as one dataset
            raise DcslamError(f"{out_root} holds data dcslam synth did not write ({', '.join(map(str, foreign[:3]))}"
                              f"{f' and {len(foreign) - 3} more' if len(foreign) > 3 else ''}); choose another "
                              "--out, or pass --force to write the sequences beside it")
        taken = [out_root / name for name in names if _occupied(out_root / name)]
        if taken:
            raise DcslamError(f"{taken[0]} exists; pass --force to replace it")
    out_root.mkdir(parents=True, exist_ok=True)
    written = []
    for index, name in enumerate(names):
        tmp = out_root / f".{name}.tmp-{os.getpid()}"
        try:
            shutil.rmtree(tmp, ignore_errors=True)
            tmp.mkdir(parents=True)
            report = write_sequence(tmp, index, frames, seed, scale, on_frame)
            final = out_root / name
            if final.exists():
                shutil.rmtree(final)
            os.replace(tmp, final)
            written.append(IndoorSequence(name, final, final / report.trajectory.name, report.frames,
                                          report.depth_density, report.seconds))
        finally:
            with contextlib.suppress(FileNotFoundError):
                shutil.rmtree(tmp)
    config = write_json_atomic(out_root / "synth_indoor.json", stage_config("synth --indoor", {
        "out": out_root, "sequences": sequences, "frames": frames, "seed": seed, "scale": scale,
        "camera": "ICL-NUIM (fy < 0)", "depth_scale": 5000}))
    return IndoorResult(tuple(written), config)
