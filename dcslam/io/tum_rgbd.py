"""TUM RGB-D and ICL-NUIM sequences (images + timestamps + ground truth): readers and writers.

Trajectory files (``groundtruth.txt``, ``*.gt.freiburg``: ``timestamp tx ty tz qx qy qz qw``) are read and written
by :mod:`dcslam.io.tum`; this module handles the rest of a sequence folder.

**TUM RGB-D** (``rgbd_dataset_freiburg1_xyz/`` …)::

    rgb.txt, depth.txt     "timestamp relative/path.png" per line, "#" comments, timestamps increasing
    rgb/*.png              8-bit colour
    depth/*.png            16-bit, metres = value / 5000, 0 = no measurement (z-depth, registered to rgb)
    groundtruth.txt        TUM trajectory of the colour camera (100 Hz motion capture)

Colour and depth frames are paired as TUM's ``associate.py`` pairs them: every pair closer than ``max_difference``
(0.02 s) is a candidate, candidates are taken in order of increasing difference, and each image is used at most
once. Default intrinsics: TUM's ROS default ``fx = fy = 525, cx = 319.5, cy = 239.5`` (TUM's per-camera
calibrations differ by a few per cent; pass your own with ``intrinsics``).

**ICL-NUIM, TUM-compatible form** (``living_room_traj0_frei_png/`` …)::

    associations.txt       "t depth/N.png t rgb/N.png" per line (t = the frame number N)
    rgb/N.png, depth/N.png 640 x 480; depth 16-bit, metres = value / 5000
    livingRoom0.gt.freiburg   TUM trajectory, timestamps = frame numbers (frame 0 has no pose in the download);
                              in the folder, or in its parent folder as the separate download puts it

Default intrinsics: ``fx = 481.2, fy = -480.0, cx = 319.5, cy = 239.5``. **The negative fy is real.** ICL-NUIM was
rendered by POV-Ray, whose camera frame is x right, **y up**, z forward, so image rows grow as y falls:
``v = fy · y / z + cy`` with ``fy < 0``. Back-projected with that negative fy, the depth images agree with the
``.gt.freiburg`` poses (proper rotations, det +1). Such a frame (x right, y up, z forward) is left-handed when read
as a physical camera, so the reconstruction is the room's mirror image; geometry does not care. dcslam keeps
``K`` with its negative ``fy`` everywhere (drive files included): back-projection, projection, normals (oriented
towards the camera by the sign of ``n · p``, not by the pixel grid's handedness), surfel radii (``|f|``) and ICP
are written for either sign. Flipping the sign of fy alone would mirror every frame against its pose.

Also read (a dcslam extension, written by ``dcslam synth --indoor``): ``intrinsics.txt`` in a sequence folder, one
line ``fx fy cx cy``; it is used when no intrinsics are given.

Sequence folders are indexed (paired, checked, given poses) by :mod:`dcslam.io.tum_sequence`.
"""
from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.io import png
from dcslam.io.atomic import atomic_output

DEPTH_SCALE = 5000.0  # 16-bit depth PNG: metres = value / 5000, 0 = no value
MAX_DIFFERENCE_S = 0.02
MAX_POSE_GAP_S = 0.1
WIDTH, HEIGHT = 640, 480
TUM_K = np.array([[525.0, 0.0, 319.5], [0.0, 525.0, 239.5], [0.0, 0.0, 1.0]])
"""TUM RGB-D's ROS default intrinsics (640 x 480)."""
ICL_K = np.array([[481.2, 0.0, 319.5], [0.0, -480.0, 239.5], [0.0, 0.0, 1.0]])
"""ICL-NUIM's intrinsics (640 x 480); fy < 0: the camera's y axis points up (see the module docstring)."""

TUM, ICL = "tum-rgbd", "icl-nuim"
LIST_FORMAT = "'timestamp relative/path.png' per line, '#' comments"
ASSOCIATION_FORMAT = "'timestamp depth/N.png timestamp rgb/N.png' per line"
INTRINSICS_FILE = "intrinsics.txt"


# ------------------------------------------------------------------------------------------------ intrinsics
def make_K(fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    """(3, 3) float64 intrinsics; fy may be negative (ICL-NUIM), neither focal length may be zero."""
    if not all(np.isfinite([fx, fy, cx, cy])) or fx == 0 or fy == 0:
        raise DcslamError(f"intrinsics fx={fx}, fy={fy}, cx={cx}, cy={cy}: expected finite values, fx and fy != 0")
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def parse_intrinsics(text: str, source: str = "intrinsics") -> np.ndarray:
    """``"fx,fy,cx,cy"`` (commas and/or spaces) → (3, 3) K."""
    fields = text.replace(",", " ").split()
    try:
        values = [float(f) for f in fields]
    except ValueError:
        values = []
    if len(values) != 4:
        raise DcslamError(f"{source}: {text.strip()!r} is not four numbers 'fx,fy,cx,cy'")
    return make_K(*values)


def write_intrinsics(path: Path | str, K: np.ndarray, force: bool = True) -> Path:
    """``intrinsics.txt``: one line ``fx fy cx cy`` (a dcslam extension of the layouts)."""
    K = np.asarray(K, dtype=np.float64)
    with atomic_output(path, force=force) as tmp:
        tmp.write_text("# fx fy cx cy (pixels; fy < 0: camera y axis up, as ICL-NUIM)\n"
                       f"{K[0, 0]:.6f} {K[1, 1]:.6f} {K[0, 2]:.6f} {K[1, 2]:.6f}\n")
    return Path(path)


def read_intrinsics(path: Path | str) -> np.ndarray:
    path = Path(path)
    lines = [ln for ln in path.read_text().splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if len(lines) != 1:
        raise DcslamError(f"{path}: expected one line 'fx fy cx cy', found {len(lines)}")
    return parse_intrinsics(lines[0], str(path))


# ------------------------------------------------------------------------------------------------ lists
def _data_lines(path: Path) -> Iterator[tuple[int, list[str]]]:
    if not path.exists():
        raise DcslamError(f"{path} not found")
    for number, line in enumerate(path.read_text().splitlines(), 1):
        line = line.strip()
        if line and not line.startswith("#"):
            yield number, line.split()


def _timestamp(path: Path, number: int, text: str, fmt: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise DcslamError(f"{path}:{number}: timestamp {text!r} is not a number ({fmt})") from None
    if not np.isfinite(value):
        raise DcslamError(f"{path}:{number}: timestamp {text!r} is not finite ({fmt})")
    return value


def _check_increasing(path: Path, numbers: list[int], times: list[float]) -> None:
    for k in range(1, len(times)):
        if times[k] <= times[k - 1]:
            raise DcslamError(f"{path}:{numbers[k]}: timestamp {times[k]!r} is not after the previous one "
                              f"({times[k - 1]!r}); timestamps must be strictly increasing")


def read_list(path: Path | str) -> tuple[np.ndarray, list[str]]:
    """A TUM ``rgb.txt`` / ``depth.txt`` → (timestamps (N,) float64 s, relative paths [N])."""
    path = Path(path)
    numbers, times, names = [], [], []
    for number, fields in _data_lines(path):
        if len(fields) != 2:
            raise DcslamError(f"{path}:{number}: {len(fields)} fields, expected 2 ({LIST_FORMAT})")
        times.append(_timestamp(path, number, fields[0], LIST_FORMAT))
        names.append(fields[1])
        numbers.append(number)
    if not times:
        raise DcslamError(f"{path}: no entries ({LIST_FORMAT})")
    _check_increasing(path, numbers, times)
    return np.array(times), names


def write_list(path: Path | str, timestamps: np.ndarray, names: list[str], what: str = "images",
               force: bool = True) -> Path:
    """Write a TUM ``rgb.txt`` / ``depth.txt`` (timestamps (N,) increasing, relative paths [N]), atomically."""
    timestamps = np.asarray(timestamps, dtype=np.float64)
    if timestamps.shape != (len(names),):
        raise DcslamError(f"{len(names)} names but timestamps of shape {timestamps.shape}")
    if np.any(np.diff(timestamps) <= 0):
        raise DcslamError(f"{path}: timestamps must be strictly increasing")
    lines = [f"# {what}", "# timestamp filename"]
    lines += [f"{format_time(t)} {name}" for t, name in zip(timestamps, names)]
    with atomic_output(path, force=force) as tmp:
        tmp.write_text("\n".join(lines) + "\n")
    return Path(path)


def format_time(t: float) -> str:
    """A timestamp as these files write it: a whole number as an integer (ICL-NUIM's frame numbers), else 6 decimals."""
    return str(int(t)) if float(t).is_integer() and abs(t) < 1e9 else f"{t:.6f}"


def _is(name: str, folder: str) -> bool:
    return Path(name).parts[:1] == (folder,)


def read_associations(path: Path | str) -> tuple[np.ndarray, list[str], np.ndarray, list[str]]:
    """An association file → (depth timestamps (N,), depth paths [N], rgb timestamps (N,), rgb paths [N]).

    ICL-NUIM's order is ``t depth/N.png t rgb/N.png``; a line whose first path lies under ``rgb/`` (or whose second
    lies under ``depth/``) is read the other way round, as TUM's ``associate.py rgb.txt depth.txt`` writes it.
    Depth timestamps must be strictly increasing.
    """
    path = Path(path)
    numbers, depth_t, depth_n, rgb_t, rgb_n = [], [], [], [], []
    for number, fields in _data_lines(path):
        if len(fields) != 4:
            raise DcslamError(f"{path}:{number}: {len(fields)} fields, expected 4 ({ASSOCIATION_FORMAT})")
        a, b = (_timestamp(path, number, fields[i], ASSOCIATION_FORMAT) for i in (0, 2))
        if _is(fields[1], "rgb") or _is(fields[3], "depth"):
            a, b, fields = b, a, [fields[2], fields[3], fields[0], fields[1]]
        depth_t.append(a)
        depth_n.append(fields[1])
        rgb_t.append(b)
        rgb_n.append(fields[3])
        numbers.append(number)
    if not numbers:
        raise DcslamError(f"{path}: no entries ({ASSOCIATION_FORMAT})")
    _check_increasing(path, numbers, depth_t)
    return np.array(depth_t), depth_n, np.array(rgb_t), rgb_n


def write_associations(path: Path | str, depth_timestamps: np.ndarray, depth_names: list[str],
                       rgb_timestamps: np.ndarray, rgb_names: list[str], force: bool = True) -> Path:
    """Write an ICL-NUIM ``associations.txt`` (``t depth/N.png t rgb/N.png``), atomically."""
    depth_timestamps = np.asarray(depth_timestamps, dtype=np.float64)
    rgb_timestamps = np.asarray(rgb_timestamps, dtype=np.float64)
    n = len(depth_names)
    if depth_timestamps.shape != (n,) or rgb_timestamps.shape != (n,) or len(rgb_names) != n:
        raise DcslamError("associations: depth and rgb timestamps and names must all have the same length")
    if np.any(np.diff(depth_timestamps) <= 0):
        raise DcslamError(f"{path}: depth timestamps must be strictly increasing")
    lines = [f"{format_time(td)} {nd} {format_time(tr)} {nr}"
             for td, nd, tr, nr in zip(depth_timestamps, depth_names, rgb_timestamps, rgb_names)]
    with atomic_output(path, force=force) as tmp:
        tmp.write_text("\n".join(lines) + "\n")
    return Path(path)


def associate(a: np.ndarray, b: np.ndarray, max_difference: float = MAX_DIFFERENCE_S) -> tuple[np.ndarray, np.ndarray]:
    """TUM's ``associate.py``: one-to-one pairs of timestamps a (N,) and b (M,) closer than ``max_difference``,
    chosen greedily by increasing difference → (index into a (P,), index into b (P,)), sorted by a."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    order_b = np.argsort(b, kind="stable")
    sorted_b = b[order_b]
    lo = np.searchsorted(sorted_b, a - max_difference, side="left")
    hi = np.searchsorted(sorted_b, a + max_difference, side="right")
    ia = np.repeat(np.arange(len(a)), hi - lo)
    ib = order_b[np.concatenate([np.arange(s, e) for s, e in zip(lo, hi)] or [np.zeros(0, np.int64)]).astype(np.int64)]
    diff = np.abs(a[ia] - b[ib])
    keep = diff < max_difference
    ia, ib, diff = ia[keep], ib[keep], diff[keep]
    used_a, used_b = np.zeros(len(a), bool), np.zeros(len(b), bool)
    pairs = []
    for k in np.argsort(diff, kind="stable"):
        i, j = ia[k], ib[k]
        if not used_a[i] and not used_b[j]:
            used_a[i] = used_b[j] = True
            pairs.append((i, j))
    pairs.sort()
    out = np.array(pairs, dtype=np.int64).reshape(-1, 2)
    return out[:, 0], out[:, 1]


# ------------------------------------------------------------------------------------------------ images
def read_depth_png(path: Path | str, scale: float = DEPTH_SCALE) -> np.ndarray:
    """A 16-bit depth PNG → (H, W) float32 metres (value / ``scale``, 0 = no value); see :mod:`dcslam.io.png`."""
    return png.read_depth_png(path, scale)


def write_depth_png(path: Path | str, depth_m: np.ndarray, scale: float = DEPTH_SCALE) -> Path:
    """(H, W) metres → 16-bit PNG, value = round(scale · metres); see :mod:`dcslam.io.png`."""
    return png.write_depth_png(path, depth_m, scale)


def read_rgb_png(path: Path | str) -> np.ndarray:
    """An 8-bit colour (or grey) image → (H, W, 3) uint8 RGB; see :mod:`dcslam.io.png`."""
    return png.read_rgb_png(path)


def write_rgb_png(path: Path | str, rgb: np.ndarray) -> Path:
    """(H, W, 3) uint8 RGB → PNG (fast compression, as sequences are large); see :mod:`dcslam.io.png`."""
    return png.write_rgb_png(path, rgb, compression=1)


# ------------------------------------------------------------------------------------------------ writing
class IclWriter:
    """Write a sequence in the ICL-NUIM TUM-compatible layout, frame by frame, into ``folder``::

        rgb/<i>.png, depth/<i>.png, associations.txt ("i depth/i.png i rgb/i.png"), <trajectory name>, and
        intrinsics.txt when ``K`` is given

    Frame timestamps are the frame numbers, as in ICL-NUIM. The text files are written by :meth:`close`.
    """

    def __init__(self, folder: Path | str, trajectory_name: str, K: np.ndarray | None = None,
                 depth_scale: float = DEPTH_SCALE):
        self.folder, self.trajectory_name, self.K, self.depth_scale = Path(folder), trajectory_name, K, depth_scale
        self.times: list[float] = []
        self.poses: list[np.ndarray] = []

    def append(self, rgb: np.ndarray, depth_m: np.ndarray, T_world_cam: np.ndarray) -> None:
        """rgb (H, W, 3) uint8, depth_m (H, W) metres, T_world_cam (4, 4)."""
        i = len(self.times)
        if np.asarray(rgb).shape[:2] != np.asarray(depth_m).shape:
            raise DcslamError(f"frame {i}: rgb {np.asarray(rgb).shape} and depth {np.asarray(depth_m).shape} differ")
        write_rgb_png(self.folder / "rgb" / f"{i}.png", rgb)
        write_depth_png(self.folder / "depth" / f"{i}.png", depth_m, self.depth_scale)
        self.times.append(float(i))
        self.poses.append(np.asarray(T_world_cam, dtype=np.float64))

    def close(self) -> Path:
        from dcslam.io.tum import write_tum

        n = len(self.times)
        if n == 0:
            raise DcslamError(f"{self.folder}: no frames to write")
        names = [str(i) for i in range(n)]
        write_associations(self.folder / "associations.txt", self.times, [f"depth/{k}.png" for k in names],
                           self.times, [f"rgb/{k}.png" for k in names])
        write_tum(self.folder / self.trajectory_name, np.array(self.times), np.stack(self.poses), force=True)
        if self.K is not None:
            write_intrinsics(self.folder / INTRINSICS_FILE, self.K)
        return self.folder
