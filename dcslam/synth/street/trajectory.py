"""The street's centre path, the car's true motion on the terrain, and the OXTS packets that describe it.

World frame: x east, y north, z up (the frame of KITTI's Mercator/ENU poses), metres. The ego path is a smooth
curve of bounded curvature; the terrain is a gentle height field (slopes of a few per cent); the car follows the
path at 5.5–13.5 m/s with the Velodyne exactly 1.73 m above the ground, its pitch and roll following the terrain
plus a small suspension wobble.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dcslam.geometry.rotations import rotation_from_rpy, rpy_from_rotation
from dcslam.io.kitti_oxts import mercator_to_lat_lon_alt, mercator_xyz
from dcslam.synth.terrain import Terrain

GRAVITY = 9.81
LIDAR_HEIGHT_M = 1.73


@dataclass(frozen=True)
class Path:
    """The ego lane's centre line sampled every ``step`` metres of arc length: s (M,), xy (M, 2), heading (M,)."""

    s: np.ndarray
    xy: np.ndarray
    heading: np.ndarray

    @classmethod
    def random(cls, rng: np.random.Generator, s_min: float, s_max: float, step: float = 0.1) -> "Path":
        s = np.arange(s_min, s_max + step, step)
        wavelength = rng.uniform(150.0, 600.0, 3)
        curvature = (rng.uniform(-1, 1, 3) / rng.uniform(120.0, 300.0, 3)) * 0.6  # |κ| ≲ 1/70 m⁻¹
        phase = rng.uniform(0, 2 * np.pi, 3)
        # heading = ∫ κ(s) ds with κ(s) = Σ c_i sin(2π s / λ_i + φ_i), analytically
        k = 2 * np.pi / wavelength
        heading = rng.uniform(-np.pi, np.pi) + np.sum(
            -(curvature / k) * (np.cos(k * s[:, None] + phase) - np.cos(phase)), axis=1)
        dx, dy = np.cos(heading), np.sin(heading)
        x = np.concatenate([[0.0], np.cumsum((dx[1:] + dx[:-1]) * 0.5 * step)])
        y = np.concatenate([[0.0], np.cumsum((dy[1:] + dy[:-1]) * 0.5 * step)])
        i0 = int(np.argmin(np.abs(s)))
        xy = np.stack([x - x[i0], y - y[i0]], -1)
        return cls(s=s, xy=xy, heading=heading)

    def at(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Arc lengths (...) → points (..., 2) and headings (...)."""
        s = np.asarray(s, dtype=np.float64)
        x = np.interp(s, self.s, self.xy[:, 0])
        y = np.interp(s, self.s, self.xy[:, 1])
        return np.stack([x, y], -1), np.interp(s, self.s, self.heading)

    def place(self, s, lateral) -> tuple[np.ndarray, np.ndarray]:
        """Path coordinates (arc length, metres to the left) (...) → world points (..., 2) and headings (...)."""
        xy, heading = self.at(s)
        left = np.stack([-np.sin(heading), np.cos(heading)], -1)
        return xy + np.asarray(lateral, dtype=np.float64)[..., None] * left, heading


@dataclass(frozen=True)
class Motion:
    """The car's speed profile ``v(t) = v0 + a sin(ω t + φ) − a sin φ`` and small attitude wobbles."""

    v0: float
    a: float
    omega: float
    phi: float
    wobble: np.ndarray  # (3, 3): amplitude, angular frequency, phase for roll, pitch, yaw

    @classmethod
    def random(cls, rng: np.random.Generator) -> "Motion":
        v0 = rng.uniform(7.0, 11.5)
        a = rng.uniform(0.3, 1.8)
        wobble = np.stack([rng.uniform(0.001, 0.004, 3), rng.uniform(1.0, 4.0, 3), rng.uniform(0, 2 * np.pi, 3)], -1)
        return cls(v0=v0, a=a, omega=rng.uniform(0.15, 0.5), phi=rng.uniform(0, 2 * np.pi), wobble=wobble)

    def arc_length(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)
        return (self.v0 - self.a * np.sin(self.phi)) * t \
            - (self.a / self.omega) * (np.cos(self.omega * t + self.phi) - np.cos(self.phi))

    def speed(self, t: np.ndarray) -> np.ndarray:
        return self.v0 + self.a * np.sin(self.omega * np.asarray(t) + self.phi) - self.a * np.sin(self.phi)


@dataclass(frozen=True)
class Drive:
    """Everything that moves in a drive: the terrain, the path and the car's speed profile."""

    terrain: Terrain
    path: Path
    motion: Motion

    def T_world_velo(self, t: np.ndarray) -> np.ndarray:
        """Times (N,) in seconds → (N, 4, 4) true Velodyne poses: 1.73 m above the ground, on the path."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        s = self.motion.arc_length(t)
        xy, heading = self.path.at(s)
        gx, gy = self.terrain.gradient(xy[:, 0], xy[:, 1])
        forward = np.stack([np.cos(heading), np.sin(heading)], -1)
        left = np.stack([-np.sin(heading), np.cos(heading)], -1)
        w = self.motion.wobble
        wob = w[:, :1] * np.sin(w[:, 1:2] * t + w[:, 2:3])  # (3, N)
        roll = np.arctan(gx * left[:, 0] + gy * left[:, 1]) + wob[0]
        pitch = -np.arctan(gx * forward[:, 0] + gy * forward[:, 1]) + wob[1]
        yaw = heading + wob[2]
        T = np.tile(np.eye(4), (len(t), 1, 1))
        T[:, :3, :3] = rotation_from_rpy(roll, pitch, yaw)  # Velodyne axes follow the car body (x fwd, y left, z up)
        T[:, :3, 3] = np.concatenate([xy, (self.terrain.height(xy[:, 0], xy[:, 1]) + LIDAR_HEIGHT_M)[:, None]], 1)
        return T


def oxts_packets(T_world_imu_of, times: np.ndarray, lat0_deg: float, lon0_deg: float, alt0_m: float,
                 rng: np.random.Generator) -> np.ndarray:
    """The OXTS packets (N, 30) of a car whose IMU pose at time t is ``T_world_imu_of(t)`` ((N,) → (N, 4, 4)).

    The first packet sits at ``lat0_deg, lon0_deg, alt0_m``; later ones are offset by the world displacement through
    KITTI's Mercator projection with the first latitude's scale, so that KITTI's reader recovers the poses exactly.
    Velocities, accelerations (specific force, gravity included) and angular rates are central differences of the
    true motion.
    """
    times = np.asarray(times, dtype=np.float64)
    h = 1e-3
    T = T_world_imu_of(times)
    Tp, Tm = T_world_imu_of(times + h), T_world_imu_of(times - h)
    R, p = T[:, :3, :3], T[:, :3, 3]
    roll, pitch, yaw = rpy_from_rotation(R)
    velocity = (Tp[:, :3, 3] - Tm[:, :3, 3]) / (2 * h)
    accel = (Tp[:, :3, 3] - 2 * p + Tm[:, :3, 3]) / h ** 2 + np.array([0.0, 0.0, GRAVITY])
    dR = (Tp[:, :3, :3] - Tm[:, :3, :3]) / (2 * h)
    W = np.transpose(R, (0, 2, 1)) @ dR  # body-frame skew matrix of the angular rate
    omega_body = np.stack([W[:, 2, 1] - W[:, 1, 2], W[:, 0, 2] - W[:, 2, 0], W[:, 1, 0] - W[:, 0, 1]], -1) / 2
    omega_world = np.einsum("nij,nj->ni", R, omega_body)
    c, s = np.cos(yaw), np.sin(yaw)
    f_h = np.stack([c, s, np.zeros_like(c)], -1)  # forward and left, parallel to the earth's surface
    l_h = np.stack([-s, c, np.zeros_like(c)], -1)
    a_body = np.einsum("nji,nj->ni", R, accel)

    scale = np.cos(np.deg2rad(lat0_deg))
    origin = mercator_xyz([lat0_deg], [lon0_deg], [alt0_m], scale)[0]
    lat, lon, alt = mercator_to_lat_lon_alt(origin + (p - p[0]), scale)
    n = len(times)
    return np.stack([
        lat, lon, alt, roll, pitch, yaw,
        velocity[:, 1], velocity[:, 0], np.sum(velocity * f_h, 1), np.sum(velocity * l_h, 1), velocity[:, 2],
        a_body[:, 0], a_body[:, 1], a_body[:, 2], np.sum(accel * f_h, 1), np.sum(accel * l_h, 1), accel[:, 2],
        omega_body[:, 0], omega_body[:, 1], omega_body[:, 2],
        np.sum(omega_world * f_h, 1), np.sum(omega_world * l_h, 1), omega_world[:, 2],
        rng.uniform(0.02, 0.4, n), rng.uniform(0.01, 0.03, n),
        np.full(n, 4), np.full(n, 8), np.full(n, 6), np.full(n, 6), np.full(n, 6),
    ], -1)
