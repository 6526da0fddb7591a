"""SLAM with ICL-NUIM's negative fy: a tiny synthetic indoor sequence (``dcslam.synth.indoor``, fy < 0) is tracked
as well as the same room and path seen by an ordinary y-down camera, and flipping the sign of fy breaks it."""
import math

import numpy as np
import pytest
import torch

from dcslam.geometry.se3 import pose_error
from dcslam.slam.frame import prepare_frame
from dcslam.slam.fusion import PointFusion, surfel_radius
from dcslam.slam.odometry import ICPOdometry
from dcslam.slam.pipeline import SLAM
from dcslam.synth import indoor
from dcslam.synth.raycast import CameraGrid

FRAMES, SCALE = 12, 0.25
Y_DOWN = np.diag([-1.0, -1.0, 1.0])  # ICL camera (x, y up, z) -> ordinary camera (x right, y down, z): a rotation


@pytest.fixture(scope="module")
def sequence():
    rng = np.random.default_rng([0, 0, 7])
    room = indoor.build_room(rng)
    T = indoor.handheld_trajectory(room, FRAMES, rng)
    K, width, height = indoor.camera_K(SCALE)
    look = indoor.Look(np.array([0.6, 0.45, 0.3], np.float32), True)

    def render(K_, T_):
        return [indoor.render(room, look, CameraGrid(K_, width, height), t, rng)[0] for t in T_]

    K_down = K.copy()
    K_down[1, 1] *= -1
    K_down[0, 2] = width - 1 - K[0, 2]
    T_down = T.copy()
    T_down[:, :3, :3] = T[:, :3, :3] @ Y_DOWN
    return {"up": (render(K, T), K, T), "down": (render(K_down, T_down), K_down, T_down)}


def track(depths, K, T):
    slam = SLAM(ICPOdometry(), PointFusion())
    for depth in depths:
        slam.step(torch.from_numpy(depth)[None, None], torch.tensor(K, dtype=torch.float32))
    truth = torch.from_numpy(np.linalg.inv(T[0]) @ T)
    dt, dr = pose_error(truth, slam.trajectory().double())
    return float(dt.max()), math.degrees(float(dr.max())), slam


def test_camera_is_y_up_and_images_are_mirrors(sequence):
    (up, K, _), (down, _, _) = sequence["up"], sequence["down"]
    assert K[1, 1] < 0
    np.testing.assert_allclose(up[3], down[3][:, ::-1], atol=1e-4)  # one view, mirrored left to right


def test_tracks_with_negative_fy(sequence):
    dt_up, dr_up, slam = track(*sequence["up"])
    dt_down, dr_down, _ = track(*sequence["down"])
    assert not slam.rejected
    assert dt_up < 0.02 and dr_up < 1.0                      # 12 frames, 11 cm of path, 160 x 120 pixels
    assert dt_up < dt_down + 0.005 and dr_up < dr_down + 0.25  # as well as an ordinary camera
    flipped = sequence["up"][1].copy()
    flipped[1, 1] *= -1                                      # the sign dropped: every frame mirrored
    dt_wrong, dr_wrong, _ = track(sequence["up"][0], flipped, sequence["up"][2])
    assert dt_wrong > 2 * dt_up and dr_wrong > 2.0


def test_surfel_radius_and_map_normals_with_negative_fy(sequence):
    depths, K, _ = sequence["up"]
    frame = prepare_frame(torch.from_numpy(depths[0])[None, None].double(), torch.from_numpy(K))
    mirror = K.copy()
    mirror[1, 1] *= -1
    other = prepare_frame(torch.from_numpy(depths[0])[None, None].double(), torch.from_numpy(mirror))
    v, n = frame.vertex[frame.valid], frame.normal[frame.valid]
    radius = surfel_radius(frame, v, n)
    assert bool((radius > 0).all()) and float(radius.max()) < 0.5  # with fx + fy ~ 0 it would be metres
    torch.testing.assert_close(radius, surfel_radius(other, other.vertex[other.valid], other.normal[other.valid]))
    assert bool(((n * v).sum(1) < 0).all())  # normals face the camera
