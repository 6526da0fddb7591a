"""Indexing a TUM RGB-D or ICL-NUIM sequence folder: pairing its images, checking its files, giving each frame a pose.

The file formats (lists, associations, 16-bit depth PNGs, intrinsics) are read and written by
:mod:`dcslam.io.tum_rgbd`; trajectories by :mod:`dcslam.io.tum`.

A frame's pose is the ground truth at the frame's **depth** timestamp (SLAM uses the depth): linearly interpolated
(translation lerp, rotation slerp) between the two ground-truth poses around it when they are at most
``max_pose_gap`` (0.1 s) apart, else the nearest pose when it is within ``max_difference`` (0.02 s), else the frame
has no pose and is dropped (ICL-NUIM's frame 0, stretches where motion capture lost the camera). Interpolation
rather than nearest: with TUM's 100 Hz ground truth the nearest pose can be 5 ms off the frame's time, a few
millimetres at hand-held speeds.
"""
from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.geometry.rotations import quaternion_to_rotation, rotation_to_quaternion, slerp
from dcslam.io.tum_rgbd import (DEPTH_SCALE, HEIGHT, ICL, ICL_K, INTRINSICS_FILE, MAX_DIFFERENCE_S, MAX_POSE_GAP_S, TUM,
                                TUM_K, WIDTH, associate, format_time, read_associations, read_depth_png,
                                read_intrinsics, read_list, read_rgb_png)


# ------------------------------------------------------------------------------------------------ poses
def interpolate_poses(times: np.ndarray, gt_times: np.ndarray, T_gt: np.ndarray,
                      max_difference: float = MAX_DIFFERENCE_S,
                      max_pose_gap: float = MAX_POSE_GAP_S) -> tuple[np.ndarray, np.ndarray]:
    """Ground-truth poses at ``times`` (N,) from poses T_gt (M, 4, 4) at increasing ``gt_times`` (M,).

    Between two poses at most ``max_pose_gap`` apart: interpolated (lerp, slerp); otherwise the nearest pose if
    within ``max_difference``; otherwise none. Returns (T (N, 4, 4) float64, found (N,) bool).
    """
    times = np.asarray(times, dtype=np.float64)
    gt_times = np.asarray(gt_times, dtype=np.float64)
    T = np.tile(np.eye(4), (len(times), 1, 1))
    found = np.zeros(len(times), dtype=bool)
    if len(gt_times) == 0:
        return T, found
    q_gt = rotation_to_quaternion(T_gt[:, :3, :3])
    right = np.clip(np.searchsorted(gt_times, times, side="left"), 0, len(gt_times) - 1)
    left = np.clip(right - 1, 0, len(gt_times) - 1)
    for k, t in enumerate(times):
        i, j = left[k], right[k]
        nearest = i if abs(gt_times[i] - t) <= abs(gt_times[j] - t) else j
        if gt_times[i] <= t <= gt_times[j] and i != j and gt_times[j] - gt_times[i] <= max_pose_gap:
            w = (t - gt_times[i]) / (gt_times[j] - gt_times[i])
            T[k, :3, 3] = (1 - w) * T_gt[i, :3, 3] + w * T_gt[j, :3, 3]
            T[k, :3, :3] = quaternion_to_rotation(slerp(q_gt[i], q_gt[j], w))
            found[k] = True
        elif abs(gt_times[nearest] - t) <= max_difference:
            T[k] = T_gt[nearest]
            found[k] = True
    return T, found


# ------------------------------------------------------------------------------------------------ sequences
@dataclass(frozen=True)
class Sequence:
    """One indexed sequence whose files have been checked: frame k is ``rgb_paths[k]`` + ``depth_paths[k]`` at
    ``timestamps[k]`` (the depth image's) with pose ``T_world_cam[k]`` (4, 4) from the ground truth, as recorded
    (not re-based). ``frame_ids`` (N,) number the frames in the full association (before any frame was dropped or
    skipped); ``notes`` say what was dropped and why.
    """

    root: Path
    name: str
    format: str
    K: np.ndarray
    groundtruth: Path
    rgb_paths: tuple[Path, ...]
    depth_paths: tuple[Path, ...]
    timestamps: np.ndarray
    T_world_cam: np.ndarray
    frame_ids: np.ndarray
    depth_scale: float = DEPTH_SCALE
    notes: tuple[str, ...] = ()

    def __len__(self) -> int:
        return len(self.timestamps)

    def select(self, index: np.ndarray) -> "Sequence":
        index = np.asarray(index, dtype=np.int64)
        return replace(self, rgb_paths=tuple(self.rgb_paths[i] for i in index),
                       depth_paths=tuple(self.depth_paths[i] for i in index), timestamps=self.timestamps[index],
                       T_world_cam=self.T_world_cam[index], frame_ids=self.frame_ids[index])

    def subsample(self, stride: int = 1, max_frames: int | None = None) -> "Sequence":
        """Every ``stride``-th frame, then at most ``max_frames`` of them."""
        if stride < 1:
            raise DcslamError(f"stride is {stride}, expected at least 1")
        index = np.arange(0, len(self), stride)
        return self.select(index[:max_frames] if max_frames is not None else index)

    def frames(self) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """Yield (rgb (H, W, 3) uint8, depth (H, W) float32 metres) of every frame, checking sizes."""
        for rgb_path, depth_path in zip(self.rgb_paths, self.depth_paths):
            rgb, depth = read_rgb_png(rgb_path), read_depth_png(depth_path, self.depth_scale)
            if rgb.shape[:2] != depth.shape:
                raise DcslamError(f"{rgb_path} is {rgb.shape[1]}x{rgb.shape[0]} but {depth_path} is "
                                  f"{depth.shape[1]}x{depth.shape[0]}")
            yield rgb, depth


def is_sequence(folder: Path | str) -> bool:
    """A folder with ``associations.txt``, or with both ``rgb.txt`` and ``depth.txt``."""
    folder = Path(folder)
    return (folder / "associations.txt").is_file() or ((folder / "rgb.txt").is_file()
                                                       and (folder / "depth.txt").is_file())


def find_sequences(src: Path | str) -> list[Path]:
    """``src`` itself if it is a sequence folder, else its sequence sub-folders sorted by name."""
    src = Path(src)
    if not src.is_dir():
        raise DcslamError(f"{src} is not a folder; expected a TUM RGB-D / ICL-NUIM sequence folder or a folder of "
                          f"them (run `dcslam synth --indoor` to generate one)")
    if is_sequence(src):
        return [src]
    found = sorted(p for p in src.iterdir() if p.is_dir() and not p.name.startswith(".") and is_sequence(p))
    if not found:
        raise DcslamError(f"no TUM RGB-D or ICL-NUIM sequence in {src} (a sequence folder holds associations.txt, "
                          f"or rgb.txt and depth.txt); run `dcslam synth --indoor` to generate one")
    return found


_ICL_NAME = re.compile(r"^(?P<room>living_room_|office_room_)?traj(?P<number>\d+)n?_frei_png$")
_ICL_STEMS = {"living_room_": ("livingRoom",), "office_room_": ("traj",), None: ("traj", "livingRoom")}


def find_groundtruth(folder: Path | str) -> Path:
    """A sequence's trajectory: ``groundtruth.txt`` in the folder, else its one ``*.gt.freiburg``, else the
    ICL-NUIM name in the parent folder (``living_room_traj2[n]_frei_png`` → ``livingRoom2.gt.freiburg``; the office
    sequences ``traj2[n]_frei_png`` → ``traj2.gt.freiburg``), where the separate download puts it."""
    folder = Path(folder)
    if (folder / "groundtruth.txt").is_file():
        return folder / "groundtruth.txt"
    match = _ICL_NAME.match(folder.name)
    expected = [f"{stem}{match['number']}.gt.freiburg" for stem in _ICL_STEMS[match["room"]]] if match else []
    inside = sorted(folder.glob("*.gt.freiburg"))
    if len(inside) > 1:
        named = [p for p in inside if p.name in expected]
        if len(named) != 1:
            raise DcslamError(f"{folder}: {len(inside)} *.gt.freiburg files ({', '.join(p.name for p in inside)}); "
                              f"keep one, or name the trajectory groundtruth.txt")
        return named[0]
    if inside:
        return inside[0]
    for name in expected:
        if (folder.parent / name).is_file():
            return folder.parent / name
    looked = [str(folder / "groundtruth.txt"), str(folder / "*.gt.freiburg")] + [str(folder.parent / n)
                                                                                for n in expected]
    raise DcslamError(f"{folder}: no ground-truth trajectory (looked for {', '.join(looked)})")


def index_sequence(folder: Path | str, *, intrinsics: np.ndarray | None = None, groundtruth: Path | str | None = None,
                   max_difference: float = MAX_DIFFERENCE_S, max_pose_gap: float = MAX_POSE_GAP_S,
                   depth_scale: float = DEPTH_SCALE) -> Sequence:
    """Index a TUM RGB-D or ICL-NUIM sequence folder and check it: association, files present, ground truth.

    ``associations.txt`` is used when present (ICL-NUIM), else ``rgb.txt`` + ``depth.txt`` are associated by
    timestamp. Intrinsics: ``intrinsics`` (3, 3), else ``intrinsics.txt`` in the folder, else the format's default
    (:data:`ICL_K` with an association file, :data:`TUM_K` otherwise). Frames without a ground-truth pose are
    dropped (noted). Raises :class:`DcslamError` on malformed lines, unsorted timestamps, a missing image or
    trajectory, or no frame left.
    """
    from dcslam.io.tum import read_tum

    folder = Path(folder)
    if not folder.is_dir():
        raise DcslamError(f"sequence folder {folder} not found")
    notes: list[str] = []
    fmt, depth_t, depth_n, rgb_n = _associated_images(folder, max_difference, notes)
    rgb_paths = tuple(folder / n for n in rgb_n)
    depth_paths = tuple(folder / n for n in depth_n)
    for paths, listed in ((depth_paths, "depth.txt"), (rgb_paths, "rgb.txt")):
        for path in paths:
            if not path.is_file():
                raise DcslamError(f"{path} not found (listed in "
                                  f"{folder / ('associations.txt' if fmt == ICL else listed)})")

    if groundtruth is None:
        groundtruth = find_groundtruth(folder)
    gt_times, T_gt = read_tum(groundtruth)
    T, found = interpolate_poses(depth_t, gt_times, T_gt, max_difference, max_pose_gap)
    if not found.all():
        missing = np.flatnonzero(~found)
        shown = ", ".join(format_time(depth_t[i]) for i in missing[:5]) + (" ..." if len(missing) > 5 else "")
        notes.append(f"{len(missing)} frame(s) without a ground-truth pose in {Path(groundtruth).name}, dropped "
                     f"(timestamps {shown})")
    if not found.any():
        raise DcslamError(f"{folder}: no frame has a ground-truth pose in {groundtruth} (timestamps "
                          f"{format_time(depth_t[0])}..{format_time(depth_t[-1])} vs "
                          f"{format_time(gt_times[0])}..{format_time(gt_times[-1])})")

    K = _sequence_intrinsics(folder, fmt, intrinsics)
    keep = np.flatnonzero(found)
    sequence = Sequence(root=folder, name=folder.name, format=fmt, K=K, groundtruth=Path(groundtruth),
                        rgb_paths=rgb_paths, depth_paths=depth_paths, timestamps=depth_t, T_world_cam=T,
                        frame_ids=np.arange(len(depth_t), dtype=np.int64), depth_scale=depth_scale,
                        notes=tuple(notes))
    return sequence.select(keep)


def _associated_images(folder: Path, max_difference: float, notes: list[str]):
    """(format, depth timestamps (N,), depth image names, colour image names) of a sequence folder: its
    ``associations.txt`` (ICL-NUIM), else ``rgb.txt`` and ``depth.txt`` associated by timestamp (TUM; depth images
    without a colour image are skipped and noted). No pair at all is a DcslamError."""
    if (folder / "associations.txt").is_file():
        fmt = ICL
        depth_t, depth_n, _, rgb_n = read_associations(folder / "associations.txt")
    elif (folder / "rgb.txt").is_file() and (folder / "depth.txt").is_file():
        fmt = TUM
        rgb_t, rgb_all = read_list(folder / "rgb.txt")
        depth_all_t, depth_all = read_list(folder / "depth.txt")
        i_rgb, i_depth = associate(rgb_t, depth_all_t, max_difference)
        if len(i_rgb) < len(depth_all_t):
            notes.append(f"{len(depth_all_t) - len(i_rgb)} of {len(depth_all_t)} depth images have no colour image "
                         f"within {max_difference} s, skipped")
        depth_t = depth_all_t[i_depth]
        depth_n = [depth_all[j] for j in i_depth]
        rgb_n = [rgb_all[i] for i in i_rgb]
    else:
        raise DcslamError(f"{folder}: no associations.txt, nor rgb.txt and depth.txt; not a TUM RGB-D or ICL-NUIM "
                          f"sequence")
    if len(depth_t) == 0:
        raise DcslamError(f"{folder}: no colour and depth images within {max_difference} s of each other")
    return fmt, depth_t, depth_n, rgb_n


def _sequence_intrinsics(folder: Path, fmt: str, intrinsics: np.ndarray | None) -> np.ndarray:
    """K (3, 3): ``intrinsics`` if given, else the folder's ``intrinsics.txt``, else the format's default."""
    if intrinsics is not None:
        K = np.asarray(intrinsics, dtype=np.float64)
        if K.shape != (3, 3):
            raise DcslamError(f"intrinsics have shape {K.shape}, expected (3, 3)")
        return K
    if (folder / INTRINSICS_FILE).is_file():
        return read_intrinsics(folder / INTRINSICS_FILE)
    return ICL_K.copy() if fmt == ICL else TUM_K.copy()


def check_image_size(sequence: Sequence, width: int, height: int, intrinsics_given: bool) -> None:
    """Fail when a format's default intrinsics (for 640 x 480) meet images of another size."""
    if intrinsics_given or (sequence.root / INTRINSICS_FILE).is_file():
        return
    if (width, height) != (WIDTH, HEIGHT):
        raise DcslamError(f"{sequence.root}: images are {width}x{height} but the default {sequence.format} "
                          f"intrinsics are for {WIDTH}x{HEIGHT}; pass intrinsics (--intrinsics fx,fy,cx,cy)")
