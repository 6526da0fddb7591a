"""The real KITTI 2011-09-26 calibration that synthetic drives are rendered with (package data, verbatim files).

The chain is the one KITTI's devkit and pykitti use: ``T_cam2_velo = T(P_rect_02) · R_rect_00 · T_cam0_velo`` where
``T(P_rect_02)`` is the pure translation ``K⁻¹ · P_rect_02[:, 3]``, and ``T_cam2_imu = T_cam2_velo · T_velo_imu``.
"""
from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError

DATE = "2011_09_26"
CALIB_DIR = Path(__file__).parent / f"calib_{DATE}"
CALIB_FILES = ("calib_cam_to_cam.txt", "calib_velo_to_cam.txt", "calib_imu_to_velo.txt")


def _read_numbers(path: Path) -> dict[str, np.ndarray]:
    values = {}
    for line in path.read_text().splitlines():
        key, _, rest = line.partition(":")
        try:
            values[key.strip()] = np.array([float(x) for x in rest.split()], dtype=np.float64)
        except ValueError:
            continue  # calib_time and other text entries
    return values


def _rigid(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = np.asarray(R).reshape(3, 3)
    T[:3, 3] = np.asarray(t).reshape(3)
    return T


@dataclass(frozen=True)
class SensorRig:
    """Camera 2 (rectified), Velodyne and IMU of the KITTI car.

    ``K_cam2`` (3, 3); ``T_cam2_velo``, ``T_velo_imu``, ``T_cam2_imu`` (4, 4) map points in the second frame to the
    first; ``width`` × ``height`` is the rectified image size.
    """

    K_cam2: np.ndarray
    T_cam2_velo: np.ndarray
    T_velo_imu: np.ndarray
    width: int
    height: int

    @property
    def T_cam2_imu(self) -> np.ndarray:
        return self.T_cam2_velo @ self.T_velo_imu


def load_rig(calib_dir: Path | str = CALIB_DIR) -> SensorRig:
    """Read the three KITTI calibration files of ``calib_dir`` into a :class:`SensorRig`."""
    calib_dir = Path(calib_dir)
    try:
        cam = _read_numbers(calib_dir / "calib_cam_to_cam.txt")
        velo = _read_numbers(calib_dir / "calib_velo_to_cam.txt")
        imu = _read_numbers(calib_dir / "calib_imu_to_velo.txt")
        P2 = cam["P_rect_02"].reshape(3, 4)
        K = P2[:, :3].copy()
        T_cam2_rect0 = _rigid(np.eye(3), np.linalg.solve(K, P2[:, 3]))
        T_rect0_cam0 = _rigid(cam["R_rect_00"], np.zeros(3))
        T_cam0_velo = _rigid(velo["R"], velo["T"])
        T_velo_imu = _rigid(imu["R"], imu["T"])
        width, height = (int(round(v)) for v in cam["S_rect_02"])
    except (OSError, KeyError, ValueError) as error:
        raise DcslamError(f"cannot read the KITTI calibration in {calib_dir}: {error}") from None
    return SensorRig(K_cam2=K, T_cam2_velo=T_cam2_rect0 @ T_rect0_cam0 @ T_cam0_velo, T_velo_imu=T_velo_imu,
                     width=width, height=height)


def copy_calibration(date_dir: Path, force: bool) -> None:
    """Copy the three real calibration files into ``date_dir`` (``raw/2011_09_26``).

    Files already there with the same bytes are left alone; different ones are an error unless ``force``.
    """
    date_dir.mkdir(parents=True, exist_ok=True)
    for name in CALIB_FILES:
        source, target = CALIB_DIR / name, date_dir / name
        if target.exists():
            if target.read_bytes() == source.read_bytes():
                continue
            if not force:
                raise DcslamError(f"{target} exists and differs from the real {DATE} calibration; "
                                  f"pass --force to replace it")
        tmp = target.with_name(f".{name}.tmp")
        shutil.copyfile(source, tmp)
        tmp.replace(target)
