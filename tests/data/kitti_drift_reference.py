"""Makes ``kitti_drift_reference.json``: the KITTI odometry drift of a perturbed copy of sequence 04, computed by an
independent implementation, KISS-ICP's C++ port of the devkit's ``calcSequenceErrors`` (``kiss_icp.metrics``).

Run once (kiss-icp is not a dcslam dependency; its wheel works without its own dependencies for this call)::

    pip install --no-deps --target /tmp/kisslib kiss-icp==1.3.0
    PYTHONPATH=/tmp/kisslib:. python tests/data/kitti_drift_reference.py

The test (tests/eval/test_trajectory_drift.py) imports :func:`perturb` from here and needs no kiss-icp.
"""
import json
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
POSES_04 = HERE / "kitti-sample" / "odometry" / "poses" / "04.txt"


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def perturb(T_world_cam: np.ndarray) -> np.ndarray:
    """A deterministic estimate from a ground truth (N, 4, 4): every relative motion is stretched by 1.5 %, shifted
    sideways by a few cm and turned by up to 0.002 rad about a slowly changing axis (no random numbers)."""
    T = np.asarray(T_world_cam, dtype=np.float64)
    out = [T[0].copy()]
    for i in range(1, len(T)):
        rel = np.linalg.inv(T[i - 1]) @ T[i]
        noise = np.eye(4)
        noise[:3, :3] = _rotation(np.array([np.sin(0.1 * i), 1.0, np.cos(0.07 * i)]), 0.002 * np.sin(0.05 * i))
        rel = rel.copy()
        rel[:3, 3] = 1.015 * rel[:3, 3] + np.array([0.02 * np.cos(0.3 * i), 0.005, 0.0])
        out.append(out[-1] @ rel @ noise)
    return np.stack(out)


def main() -> None:
    from kiss_icp.metrics import sequence_error

    from dcslam.io.kitti_poses import read_kitti_poses

    gt = read_kitti_poses(POSES_04)
    est = perturb(gt)
    t_rel, r_rel = sequence_error(list(gt), list(est))
    reference = {
        "source": "kiss_icp.metrics.sequence_error (kiss-icp 1.3.0), a C++ port of the KITTI odometry devkit's "
                  "calcSequenceErrors; made by tests/data/kitti_drift_reference.py",
        "ground_truth": "kitti-sample/odometry/poses/04.txt",
        "estimate": "perturb(ground truth) in tests/data/kitti_drift_reference.py",
        "t_rel_percent": float(t_rel),
        "kiss_icp_r_rel_deg_per_m": float(r_rel),
        "note": "KISS-ICP converts rad/m to deg/m with 180 / 3.14 (not pi) and returns 32-bit floats: "
                "r_rel in deg/100 m = kiss_icp_r_rel_deg_per_m * 3.14 / pi * 100",
    }
    (HERE / "kitti_drift_reference.json").write_text(json.dumps(reference, indent=2) + "\n")
    print(json.dumps(reference, indent=2))


if __name__ == "__main__":
    main()
