"""Builders of tiny TUM RGB-D and ICL-NUIM sequence folders for the io tests."""
import numpy as np

from dcslam.io import tum_rgbd as tr
from dcslam.geometry.rotations import quaternion_to_rotation
from dcslam.io.tum import read_tum, write_tum

H, W = 6, 8


def pose(t: float) -> np.ndarray:
    """A smooth known motion: constant velocity, constant rate about a fixed axis."""
    T = np.eye(4)
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    angle = 0.4 * t
    T[:3, :3] = quaternion_to_rotation(np.append(axis * np.sin(angle / 2), np.cos(angle / 2)))
    T[:3, 3] = [0.2 * t, -0.1 * t, 1.0 + 0.05 * t]
    return T


def write_tum_sequence(root, rgb_times, depth_times, gt_times, size=(H, W)):
    """A TUM RGB-D folder: rgb.txt, depth.txt, groundtruth.txt and tiny images."""
    root.mkdir(parents=True)
    names = {"rgb": [], "depth": []}
    rng = np.random.default_rng(0)
    for kind, times in (("rgb", rgb_times), ("depth", depth_times)):
        for t in times:
            name = f"{kind}/{t:.6f}.png"
            names[kind].append(name)
            if kind == "rgb":
                tr.write_rgb_png(root / name, rng.integers(0, 255, (*size, 3), dtype=np.uint8))
            else:
                tr.write_depth_png(root / name, rng.uniform(0.5, 4.0, size))
        tr.write_list(root / f"{kind}.txt", np.array(times), names[kind], f"{kind} images")
    write_tum(root / "groundtruth.txt", np.array(gt_times), np.stack([pose(t) for t in gt_times]))
    return root


def write_icl_sequence(root, frames=4, gt_from=0, K=None, size=(H, W)):
    """An ICL-NUIM folder through :class:`IclWriter` (poses of :func:`pose` at t = frame number)."""
    writer = tr.IclWriter(root, "livingRoom0.gt.freiburg", K)
    rng = np.random.default_rng(1)
    for k in range(frames):
        writer.append(rng.integers(0, 255, (*size, 3), dtype=np.uint8), rng.uniform(0.5, 4.0, size), pose(k))
    writer.close()
    if gt_from:  # as the real download: no pose for the first frame(s)
        times, T = read_tum(root / "livingRoom0.gt.freiburg")
        write_tum(root / "livingRoom0.gt.freiburg", times[gt_from:], T[gt_from:], force=True)
    return root
