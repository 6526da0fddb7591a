"""The street's centre path, the terrain, the car's true motion, and the OXTS packets that describe it.

World frame: x east, y north, z up (the frame of KITTI's Mercator/ENU poses), metres. The ego path is a smooth
curve of bounded curvature; the terrain is a gentle height field (slopes of a few per cent); the car follows the
path at 5.5–13.5 m/s with the Velodyne exactly 1.73 m above the ground, its pitch and roll following the terrain
plus a small suspension wobble.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dcslam.geometry.rotations import rotation_from_rpy, rpy_from_rotation

EARTH_RADIUS_M = 6378137.0
GRAVITY = 9.81
LIDAR_HEIGHT_M = 1.73


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

    def around(self, x0: float, y0: float, dx: np.ndarray, dy: np.ndarray):
        """Height and gradient (h, dh/dx, dh/dy), each (n,) float32, at offsets dx, dy (n,) float32 from the point
        (x0, y0): float32 arithmetic around a float64 origin, for speed on many rays."""
        phase = (self.phase + self.wave @ np.array([x0, y0])).astype(np.float32)
        arg = dx[:, None] * self.wave[:, 0].astype(np.float32) + dy[:, None] * self.wave[:, 1].astype(np.float32)
        arg += phase
        amplitude = self.amplitude.astype(np.float32)
        c = np.cos(arg) * amplitude
        return (np.sin(arg) @ amplitude, c @ self.wave[:, 0].astype(np.float32),
                c @ self.wave[:, 1].astype(np.float32))

    def gradient(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(dh/dx, dh/dy) at points x, y (...)."""
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        c = np.cos(x[..., None] * self.wave[:, 0] + y[..., None] * self.wave[:, 1] + self.phase) * self.amplitude
        return c @ self.wave[:, 0], c @ self.wave[:, 1]


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
        T[:, :3, :3] = rotation_from_rpy(roll, pitch, yaw)  # the Velodyne axes follow the car body (x fwd, y left, z up)
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
    mx0 = scale * EARTH_RADIUS_M * np.deg2rad(lon0_deg)
    my0 = scale * EARTH_RADIUS_M * np.log(np.tan(np.deg2rad(90.0 + lat0_deg) / 2))
    mx = mx0 + (p[:, 0] - p[0, 0])
    my = my0 + (p[:, 1] - p[0, 1])
    lon = np.rad2deg(mx / (scale * EARTH_RADIUS_M))
    lat = np.rad2deg(2 * np.arctan(np.exp(my / (scale * EARTH_RADIUS_M)))) - 90.0
    alt = alt0_m + (p[:, 2] - p[0, 2])
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


def format_oxts(packet: np.ndarray) -> str:
    """One packet (30,) → a KITTI OXTS text line (15 significant digits, the last five fields as integers)."""
    return " ".join([f"{v:.15g}" for v in packet[:25]] + [str(int(round(v))) for v in packet[25:]])


OXTS_DATAFORMAT = """lat:   latitude of the oxts-unit (deg)
lon:   longitude of the oxts-unit (deg)
alt:   altitude of the oxts-unit (m)
roll:  roll angle (rad),    0 = level, positive = left side up,      range: -pi   .. +pi
pitch: pitch angle (rad),   0 = level, positive = front down,        range: -pi/2 .. +pi/2
yaw:   heading (rad),       0 = east,  positive = counter clockwise, range: -pi   .. +pi
vn:    velocity towards north (m/s)
ve:    velocity towards east (m/s)
vf:    forward velocity, i.e. parallel to earth-surface (m/s)
vl:    leftward velocity, i.e. parallel to earth-surface (m/s)
vu:    upward velocity, i.e. perpendicular to earth-surface (m/s)
ax:    acceleration in x, i.e. in direction of vehicle front (m/s^2)
ay:    acceleration in y, i.e. in direction of vehicle left (m/s^2)
ay:    acceleration in z, i.e. in direction of vehicle top (m/s^2)
af:    forward acceleration (m/s^2)
al:    leftward acceleration (m/s^2)
au:    upward acceleration (m/s^2)
wx:    angular rate around x (rad/s)
wy:    angular rate around y (rad/s)
wz:    angular rate around z (rad/s)
wf:    angular rate around forward axis (rad/s)
wl:    angular rate around leftward axis (rad/s)
wu:    angular rate around upward axis (rad/s)
pos_accuracy:  velocity accuracy (north/east in m)
vel_accuracy:  velocity accuracy (north/east in m/s)
navstat:       navigation status (see navstat_to_string)
numsats:       number of satellites tracked by primary GPS receiver
posmode:       position mode of primary GPS receiver (see gps_mode_to_string)
velmode:       velocity mode of primary GPS receiver (see gps_mode_to_string)
orimode:       orientation mode of primary GPS receiver (see gps_mode_to_string)
"""
