"""The indoor camera: ICL-NUIM's intrinsics (``fy < 0``, y axis up) and a smooth hand-held path over the room."""
from __future__ import annotations

import numpy as np

from dcslam.errors import DcslamError
from dcslam.geometry.rotations import look_rotation
from dcslam.io.tum_rgbd import HEIGHT, ICL_K, WIDTH
from dcslam.synth.indoor.room import Room


def camera_K(scale: float = 1.0) -> tuple[np.ndarray, int, int]:
    """ICL-NUIM's intrinsics for images ``scale`` times 640 x 480 → (K (3, 3), width, height)."""
    width, height = int(round(WIDTH * scale)), int(round(HEIGHT * scale))
    if width < 16 or height < 12:
        raise DcslamError(f"--scale {scale} gives {width}x{height} images; use at least 0.025")
    sx, sy = width / WIDTH, height / HEIGHT
    K = ICL_K.copy()
    K[0, 0] *= sx
    K[1, 1] *= sy
    K[0, 2] = (K[0, 2] + 0.5) * sx - 0.5
    K[1, 2] = (K[1, 2] + 0.5) * sy - 0.5
    return K, width, height


def handheld_trajectory(room: Room, frames: int, rng: np.random.Generator) -> np.ndarray:
    """A smooth hand-held path over the middle of the room: T_world_cam (N, 4, 4) float64.

    Position: slow sinusoids (periods of 250-450 frames, longer in big rooms so that no axis moves more than 2 cm per
    frame) over the free middle of the room (at least 1.6 m from the walls, where the furniture stands) at
    1.15-1.55 m height, plus about a millimetre of hand shake: at most 3 cm per frame. Heading: a slow turn (0.2-0.5
    degrees per frame) plus a swing; the camera looks 8-20 degrees down and rolls up to 3 degrees.
    """
    k = np.arange(frames, dtype=np.float64)
    centre = np.array([room.size_x / 2, room.size_y / 2, 1.35])
    amplitude = np.array([max(room.size_x / 2 - 1.6, 0.2), max(room.size_y / 2 - 1.6, 0.2), 0.2])
    period = np.maximum(rng.uniform(250.0, 450.0, 3), 2 * np.pi * amplitude / 0.02)  # at most 2 cm/frame per axis
    phase = rng.uniform(0, 2 * np.pi, 3)
    position = centre + amplitude * np.sin(2 * np.pi * k[:, None] / period + phase)
    shake = rng.normal(0, 1.0, (3, 3))  # three slow-ish sinusoids per axis, ~1 mm
    for j, p in enumerate((9.0, 13.0, 21.0)):
        position += 0.001 * shake[j] * np.sin(2 * np.pi * k[:, None] / p + phase[j])
    turn = np.deg2rad(rng.uniform(0.2, 0.5)) * rng.choice([-1.0, 1.0])
    yaw = rng.uniform(-np.pi, np.pi) + turn * k + 0.25 * np.sin(2 * np.pi * k / rng.uniform(180, 320)
                                                                 + rng.uniform(0, 2 * np.pi))
    pitch = -np.deg2rad(14.0) + np.deg2rad(6.0) * np.sin(2 * np.pi * k / rng.uniform(120, 240) + rng.uniform(0, 6))
    roll = np.deg2rad(3.0) * np.sin(2 * np.pi * k / rng.uniform(100, 200) + rng.uniform(0, 6))
    forward = np.stack([np.cos(pitch) * np.cos(yaw), np.cos(pitch) * np.sin(yaw), np.sin(pitch)], axis=1)
    T = np.tile(np.eye(4), (frames, 1, 1))
    T[:, :3, :3] = look_rotation(forward, roll)
    T[:, :3, 3] = position
    return T
