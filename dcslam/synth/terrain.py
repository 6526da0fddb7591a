"""The ground both generators stand on: a gentle height field of a few sinusoids (flat for the indoor floor)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Terrain:
    """Ground height ``h(x, y) = Σ a_i sin(k_i · (x, y) + φ_i)``: (K,) amplitudes, (K, 2) wave vectors, (K,) phases."""

    amplitude: np.ndarray
    wave: np.ndarray
    phase: np.ndarray

    @classmethod
    def random(cls, rng: np.random.Generator) -> "Terrain":
        wavelength = rng.uniform(180.0, 420.0, 3)
        direction = rng.uniform(0, 2 * np.pi, 3)
        wave = (2 * np.pi / wavelength)[:, None] * np.stack([np.cos(direction), np.sin(direction)], -1)
        slope = rng.uniform(0.006, 0.018, 3)  # per-wave maximum slope; the sum stays below ~4 %
        return cls(amplitude=slope / np.linalg.norm(wave, axis=1), wave=wave, phase=rng.uniform(0, 2 * np.pi, 3))

    def height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Heights (...) at points x, y (...)."""
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        arg = x[..., None] * self.wave[:, 0] + y[..., None] * self.wave[:, 1] + self.phase
        return np.sin(arg) @ self.amplitude

    def _args_around(self, x0: float, y0: float, dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
        """The sinusoids' arguments (n, K) float32 at offsets dx, dy (n,) float32 from the point (x0, y0)."""
        phase = (self.phase + self.wave @ np.array([x0, y0])).astype(np.float32)
        arg = dx[:, None] * self.wave[:, 0].astype(np.float32) + dy[:, None] * self.wave[:, 1].astype(np.float32)
        arg += phase
        return arg

    def around(self, x0: float, y0: float, dx: np.ndarray, dy: np.ndarray):
        """Height and gradient (h, dh/dx, dh/dy), each (n,) float32, at offsets dx, dy (n,) float32 from the point
        (x0, y0): float32 arithmetic around a float64 origin, for speed on many rays."""
        arg = self._args_around(x0, y0, dx, dy)
        amplitude = self.amplitude.astype(np.float32)
        c = np.cos(arg) * amplitude
        return (np.sin(arg) @ amplitude, c @ self.wave[:, 0].astype(np.float32),
                c @ self.wave[:, 1].astype(np.float32))

    def height_around(self, x0: float, y0: float, dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
        """The height of :meth:`around` alone (the same numbers), without the cosines of its gradient."""
        return np.sin(self._args_around(x0, y0, dx, dy)) @ self.amplitude.astype(np.float32)

    def gradient(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(dh/dx, dh/dy) at points x, y (...)."""
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        c = np.cos(x[..., None] * self.wave[:, 0] + y[..., None] * self.wave[:, 1] + self.phase) * self.amplitude
        return c @ self.wave[:, 0], c @ self.wave[:, 1]
