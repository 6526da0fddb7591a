"""KITTI raw calibration: the three text files of a recording date, worked out once into an immutable record.

Files under ``raw/<date>/`` (``key: values`` lines; ``calib_time`` is text, every other value is numbers):

- ``calib_cam_to_cam.txt``: ``S_rect_02`` (width height of rectified images), ``R_rect_00`` (3x3 rectifying
  rotation of camera 0), ``P_rect_02`` (3x4 projection of rectified camera 2), and the same for the other cameras;
- ``calib_velo_to_cam.txt``: ``R`` (3x3), ``T`` (3,): ``T_cam0_velo``, Velodyne → unrectified camera 0;
- ``calib_imu_to_velo.txt``: ``R``, ``T``: ``T_velo_imu``, IMU/GPS (OXTS) → Velodyne.

Camera 2 (left colour) through the chain ``T_cam2_velo = T(P_rect_02) · R_rect_00 · T_cam0_velo`` where
``T(P_rect_02)`` translates by the camera-2 offset ``t = K⁻¹ · P_rect_02[:, 3]``, taken exactly. pykitti instead
uses ``(P[0, 3] / P[0, 0], 0, 0)``: for 2011_09_26 that is (62.17, 0, 0) mm against our (59.85, -0.36, 2.75) mm, so
its camera-2 poses sit 3.6 mm from ours. With the exact offset, ``K · T_cam2_velo`` equals
``P_rect_02 · R_rect_00 · T_cam0_velo``, so projecting a point through the record agrees with KITTI's projection.
"""
from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.io.atomic import atomic_output

CALIB_FILES = ("calib_cam_to_cam.txt", "calib_velo_to_cam.txt", "calib_imu_to_velo.txt")


def read_calib_file(path: Path | str) -> dict[str, np.ndarray | str]:
    """A KITTI calibration text file → ``{key: float64 array}`` (``calib_time`` stays text).

    Fails with the file and line number on a line without ``key:`` or with values that are not numbers.
    """
    path = Path(path)
    if not path.exists():
        raise DcslamError(f"calibration file {path} not found (expected KITTI raw layout raw/<date>/{path.name})")
    values: dict[str, np.ndarray | str] = {}
    for number, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
        if not line.strip():
            continue
        key, colon, rest = line.partition(":")
        key = key.strip()
        if not colon or not key:
            raise DcslamError(f"{path}:{number}: expected 'key: values', got {line.strip()[:60]!r}")
        if key == "calib_time":
            values[key] = rest.strip()
            continue
        try:
            values[key] = np.array([float(v) for v in rest.split()], dtype=np.float64)
        except ValueError:
            raise DcslamError(f"{path}:{number}: {key} has values that are not numbers") from None
    return values


def _entry(values: dict, key: str, size: int, path: Path) -> np.ndarray:
    if key not in values:
        raise DcslamError(f"{path}: missing entry {key!r}")
    value = values[key]
    if not isinstance(value, np.ndarray) or value.size != size:
        got = value.size if isinstance(value, np.ndarray) else "text"
        raise DcslamError(f"{path}: {key} has {got} values, expected {size}")
    return value


def transform(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Rotation (3, 3) and translation (3,) → homogeneous (4, 4) float64."""
    T = np.eye(4)
    T[:3, :3] = np.reshape(R, (3, 3))
    T[:3, 3] = np.reshape(t, 3)
    return T


def _frozen(array: np.ndarray) -> np.ndarray:
    array = np.array(array, dtype=np.float64)
    array.flags.writeable = False
    return array


@dataclass(frozen=True, eq=False)
class Calibration:
    """Calibration of one KITTI recording date (arrays are float64 and read-only).

    Attributes:
        P_rect_02: (3, 4) projection of rectified camera 2 (``K_cam2 · [I | t]``).
        R_rect_00: (4, 4) rectifying rotation of camera 0 (unrectified camera 0 → rectified frame).
        T_cam0_velo: (4, 4) Velodyne → unrectified camera 0.
        T_velo_imu: (4, 4) IMU (OXTS) → Velodyne.
        size_rect_02: (width, height) of rectified camera-2 images in pixels (``S_rect_02``).
    """

    P_rect_02: np.ndarray
    R_rect_00: np.ndarray
    T_cam0_velo: np.ndarray
    T_velo_imu: np.ndarray
    size_rect_02: tuple[int, int]

    def __post_init__(self):
        for name, shape in (("P_rect_02", (3, 4)), ("R_rect_00", (4, 4)), ("T_cam0_velo", (4, 4)),
                            ("T_velo_imu", (4, 4))):
            value = np.asarray(getattr(self, name))
            if value.shape != shape:
                raise DcslamError(f"calibration {name} has shape {value.shape}, expected {shape}")
            object.__setattr__(self, name, _frozen(value))

    @property
    def K_cam2(self) -> np.ndarray:
        """(3, 3) intrinsics of rectified camera 2."""
        return np.array(self.P_rect_02[:, :3])

    @property
    def T_cam2_rect0(self) -> np.ndarray:
        """(4, 4) rectified camera 0 → rectified camera 2: a translation by ``K⁻¹ · P_rect_02[:, 3]``."""
        return transform(np.eye(3), np.linalg.solve(self.K_cam2, self.P_rect_02[:, 3]))

    @property
    def T_cam2_velo(self) -> np.ndarray:
        """(4, 4) Velodyne → rectified camera 2."""
        return self.T_cam2_rect0 @ self.R_rect_00 @ self.T_cam0_velo

    @property
    def T_cam2_imu(self) -> np.ndarray:
        """(4, 4) IMU (OXTS) → rectified camera 2."""
        return self.T_cam2_velo @ self.T_velo_imu

    @property
    def image_size(self) -> tuple[int, int]:
        """(height, width) of rectified camera-2 images."""
        width, height = self.size_rect_02
        return height, width


def read_calibration(date_dir: Path | str) -> Calibration:
    """Read the three calibration files of a date folder (``raw/<date>/``) into a :class:`Calibration`."""
    date_dir = Path(date_dir)
    paths = [date_dir / name for name in CALIB_FILES]
    cam, velo, imu = (read_calib_file(p) for p in paths)
    size = _entry(cam, "S_rect_02", 2, paths[0])
    R_rect_00 = np.eye(4)
    R_rect_00[:3, :3] = _entry(cam, "R_rect_00", 9, paths[0]).reshape(3, 3)
    for R, path in ((_entry(velo, "R", 9, paths[1]), paths[1]), (_entry(imu, "R", 9, paths[2]), paths[2])):
        R = R.reshape(3, 3)
        if np.abs(R @ R.T - np.eye(3)).max() > 1e-4 or np.linalg.det(R) < 0:
            raise DcslamError(f"{path}: R is not a rotation matrix")
    for values, path in zip((cam, velo, imu), paths):
        for key, value in values.items():
            if isinstance(value, np.ndarray) and not np.isfinite(value).all():
                raise DcslamError(f"{path}: {key} holds non-finite values; restore the calibration file")
    R_rect = R_rect_00[:3, :3]
    if np.abs(R_rect @ R_rect.T - np.eye(3)).max() > 1e-4 or np.linalg.det(R_rect) < 0:
        raise DcslamError(f"{paths[0]}: R_rect_00 is not a rotation matrix")
    P_rect_02 = _entry(cam, "P_rect_02", 12, paths[0]).reshape(3, 4)
    from dcslam.io.validate import check_intrinsics

    check_intrinsics(P_rect_02[:, :3], f"{paths[0]}: P_rect_02")
    return Calibration(
        P_rect_02=P_rect_02,
        R_rect_00=R_rect_00,
        T_cam0_velo=transform(velo["R"], _entry(velo, "T", 3, paths[1])),
        T_velo_imu=transform(imu["R"], _entry(imu, "T", 3, paths[2])),
        size_rect_02=(int(round(size[0])), int(round(size[1]))),
    )


def copy_calibration(source_dir: Path | str, date_dir: Path | str, force: bool) -> None:
    """Copy the three calibration files of ``source_dir`` into ``date_dir`` (``raw/<date>``), each atomically.

    Files already there with the same bytes are left alone; different ones are an error unless ``force``.
    """
    source_dir, date_dir = Path(source_dir), Path(date_dir)
    for name in CALIB_FILES:
        source, target = source_dir / name, date_dir / name
        if not source.exists():
            raise DcslamError(f"calibration file {source} not found (expected KITTI raw layout raw/<date>/{name})")
        if target.exists() and target.read_bytes() == source.read_bytes():
            continue
        if target.exists() and not force:
            raise DcslamError(f"{target} exists and differs from {source}; pass --force to replace it")
        with atomic_output(target, force=True) as tmp:
            shutil.copyfile(source, tmp)


def project_velodyne(points: np.ndarray, calib: Calibration, image_size: tuple[int, int] | None = None,
                     min_depth_m: float = 0.1) -> np.ndarray:
    """Project a Velodyne scan into rectified camera 2 as a sparse depth image, keeping the nearest point per pixel.

    A point lands on pixel ``(round(v), round(u))`` where ``(u, v)`` is its projection (pixel centres at integer
    coordinates, as in KITTI's ``P_rect``); its depth is the z coordinate in camera 2 (metres).

    Args:
        points: (N, 3) or (N, 4) Velodyne points (x, y, z[, reflectance]) in metres, Velodyne frame.
        calib: the date's calibration.
        image_size: (H, W); default ``calib.image_size``.
        min_depth_m: points closer than this (or behind the camera) are dropped.

    Returns:
        (H, W) float32 depth in metres, 0 where no point projects.
    """
    points = np.asarray(points)
    if points.ndim != 2 or points.shape[1] not in (3, 4):
        raise DcslamError(f"points have shape {points.shape}, expected (N, 3) or (N, 4)")
    height, width = image_size or calib.image_size
    xyz = points[:, :3].astype(np.float64)
    T = calib.T_cam2_velo
    p_cam = xyz @ T[:3, :3].T + T[:3, 3]
    z = p_cam[:, 2]
    keep = z > min_depth_m
    p_cam, z = p_cam[keep], z[keep]
    uv = p_cam @ calib.K_cam2.T
    u = np.rint(uv[:, 0] / z).astype(np.int64)
    v = np.rint(uv[:, 1] / z).astype(np.int64)
    inside = (u >= 0) & (u < width) & (v >= 0) & (v < height)
    u, v, z = u[inside], v[inside], z[inside]
    depth = np.full(height * width, np.inf)
    np.minimum.at(depth, v * width + u, z)
    depth[~np.isfinite(depth)] = 0.0
    return depth.reshape(height, width).astype(np.float32)
