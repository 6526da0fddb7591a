"""KITTI OXTS (GPS/IMU) packets and the poses made from them.

An OXTS packet is one text line of 30 space-separated numbers (KITTI ``oxts/dataformat.txt``):
``lat lon alt roll pitch yaw vn ve vf vl vu ax ay az af al au wx wy wz wf wl wu pos_accuracy vel_accuracy navstat
numsats posmode velmode orimode``; one file ``oxts/data/<frame:010d>.txt`` per frame.

Poses as in KITTI's devkit and pykitti: a Mercator projection whose scale ``cos(lat₀)`` comes from the first
packet's latitude, earth radius 6378137 m, ``R = Rz(yaw) · Ry(pitch) · Rx(roll)``, and the world origin at the first
packet's position (``T_world_imu``: IMU → world, world x east, y north, z up). Camera-2 poses then follow from the
calibration chain, ``T_world_cam2 = T_world_imu · inv(T_cam2_imu)``, re-based so the first camera pose is the
identity.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.geometry.rotations import rotation_from_rpy
from dcslam.io.kitti_calib import Calibration

EARTH_RADIUS_M = 6378137.0


@dataclass(frozen=True)
class OxtsPacket:
    """One OXTS packet: angles in radians, positions in degrees / metres, velocities in m/s, rates in rad/s."""

    lat: float
    lon: float
    alt: float
    roll: float
    pitch: float
    yaw: float
    vn: float
    ve: float
    vf: float
    vl: float
    vu: float
    ax: float
    ay: float
    az: float
    af: float
    al: float
    au: float
    wx: float
    wy: float
    wz: float
    wf: float
    wl: float
    wu: float
    pos_accuracy: float
    vel_accuracy: float
    navstat: int
    numsats: int
    posmode: int
    velmode: int
    orimode: int

    @classmethod
    def from_values(cls, values) -> "OxtsPacket":
        """30 numbers in the order of :data:`OXTS_FIELDS` → a packet (the last five rounded to integers)."""
        return cls(**{name: (int(round(x)) if name in _INT_FIELDS else float(x))
                      for name, x in zip(OXTS_FIELDS, values)})

    def to_line(self) -> str:
        """The packet as one KITTI text line (floats with 15 significant digits, the last five as integers)."""
        return " ".join(str(int(v)) if isinstance(v, int) else f"{v:.15g}" for v in self.values())

    def values(self) -> tuple:
        return tuple(getattr(self, f.name) for f in fields(self))


OXTS_FIELDS = tuple(f.name for f in fields(OxtsPacket))
_INT_FIELDS = ("navstat", "numsats", "posmode", "velmode", "orimode")


def parse_oxts_line(line: str, where: str = "OXTS packet") -> OxtsPacket:
    """One text line of 30 numbers → :class:`OxtsPacket`; ``where`` names the file in error messages."""
    parts = line.split()
    if len(parts) != len(OXTS_FIELDS):
        raise DcslamError(f"{where}: {len(parts)} fields, expected {len(OXTS_FIELDS)} "
                          f"({' '.join(OXTS_FIELDS[:6])} ...)")
    try:
        numbers = [float(p) for p in parts]
    except ValueError:
        raise DcslamError(f"{where}: values that are not numbers") from None
    if not np.all(np.isfinite(numbers)):
        raise DcslamError(f"{where}: non-finite values")
    return OxtsPacket.from_values(numbers)


def read_oxts(path: Path | str) -> OxtsPacket:
    """One ``oxts/data/<frame>.txt`` file (one line of 30 numbers) → :class:`OxtsPacket`."""
    path = Path(path)
    if not path.exists():
        raise DcslamError(f"OXTS file {path} not found")
    lines = [line for line in path.read_text(errors="replace").splitlines() if line.strip()]
    if len(lines) != 1:
        raise DcslamError(f"{path}: {len(lines)} non-empty lines, expected one OXTS packet")
    return parse_oxts_line(lines[0], str(path))


def write_oxts(path: Path | str, packet: OxtsPacket) -> None:
    """Write one packet as a KITTI ``oxts/data/<frame>.txt`` file."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text(packet.to_line() + "\n")


def write_oxts_dataformat(path: Path | str) -> None:
    """Write KITTI's ``oxts/dataformat.txt`` (the field list, verbatim as in the raw recordings)."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text(OXTS_DATAFORMAT)


def mercator_xyz(lat: np.ndarray, lon: np.ndarray, alt: np.ndarray, scale: float) -> np.ndarray:
    """Latitudes, longitudes (N,) in degrees and altitudes (N,) in metres → (N, 3) Mercator x east, y north, z up."""
    lat, lon, alt = (np.asarray(a, dtype=np.float64) for a in (lat, lon, alt))
    x = scale * EARTH_RADIUS_M * np.deg2rad(lon)
    y = scale * EARTH_RADIUS_M * np.log(np.tan(np.deg2rad(90.0 + lat) / 2.0))
    return np.stack([x, y, alt], -1)


def mercator_to_lat_lon_alt(xyz: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The inverse of :func:`mercator_xyz`: (N, 3) Mercator x east, y north, z up → latitudes, longitudes (N,) in
    degrees and altitudes (N,) in metres."""
    xyz = np.asarray(xyz, dtype=np.float64)
    lon = np.rad2deg(xyz[:, 0] / (scale * EARTH_RADIUS_M))
    lat = np.rad2deg(2 * np.arctan(np.exp(xyz[:, 1] / (scale * EARTH_RADIUS_M)))) - 90.0
    return lat, lon, xyz[:, 2]


def oxts_to_T_world_imu(packets: list[OxtsPacket]) -> np.ndarray:
    """OXTS packets → (N, 4, 4) float64 ``T_world_imu``; world origin at the first packet, Mercator scale
    ``cos(lat₀)`` from the first latitude (as KITTI's devkit and pykitti)."""
    if not packets:
        raise DcslamError("no OXTS packets to turn into poses")
    lat = np.array([p.lat for p in packets])
    lon = np.array([p.lon for p in packets])
    alt = np.array([p.alt for p in packets])
    xyz = mercator_xyz(lat, lon, alt, scale=float(np.cos(np.deg2rad(lat[0]))))
    T = np.tile(np.eye(4), (len(packets), 1, 1))
    T[:, :3, :3] = rotation_from_rpy([p.roll for p in packets], [p.pitch for p in packets], [p.yaw for p in packets])
    T[:, :3, 3] = xyz - xyz[0]
    return T


def camera_poses(T_world_imu: np.ndarray, calib: Calibration) -> np.ndarray:
    """(N, 4, 4) IMU poses → (N, 4, 4) poses ``T_world_cam2`` of rectified camera 2, re-based so that the first
    one is the identity (world = camera 2 at the first given pose).

    KITTI's calibration rotations are orthonormal only to about 1e-7 (seven printed digits), so the camera
    rotations are projected onto SO(3) (nearest rotation, by SVD); this moves them by about 1e-7.
    """
    T_world_imu = np.asarray(T_world_imu, dtype=np.float64)
    if T_world_imu.ndim != 3 or T_world_imu.shape[1:] != (4, 4) or len(T_world_imu) == 0:
        raise DcslamError(f"IMU poses have shape {T_world_imu.shape}, expected (N, 4, 4) with N >= 1")
    T_world_cam2 = rebase(T_world_imu @ np.linalg.inv(calib.T_cam2_imu))
    U, _, Vt = np.linalg.svd(T_world_cam2[:, :3, :3])
    T_world_cam2[:, :3, :3] = U @ Vt  # det(U Vt) = +1: the rotations are 1e-7 from proper ones
    return T_world_cam2


def rebase(T_world_cam: np.ndarray, index: int = 0) -> np.ndarray:
    """(N, 4, 4) poses → the same trajectory in the frame of pose ``index`` (which becomes the identity)."""
    T_world_cam = np.asarray(T_world_cam, dtype=np.float64)
    T_first_world = np.linalg.inv(T_world_cam[index])
    out = T_first_world @ T_world_cam
    out[:, 3, :] = (0.0, 0.0, 0.0, 1.0)
    out[index] = np.eye(4)
    return out


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
