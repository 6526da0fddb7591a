"""The synthetic indoor generator: the ICL-NUIM files it writes, its room and camera path, and that depth, poses
and the negative-fy intrinsics agree."""
import json

import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.io import tum_rgbd as tr
from dcslam.io.tum import read_tum
from dcslam.io.tum_sequence import index_sequence
from dcslam.synth import indoor
from dcslam.synth.raycast import CameraGrid


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    root = tmp_path_factory.mktemp("tum")
    ticks = []
    result = indoor.generate_indoor(root, sequences=2, frames=3, seed=4, scale=0.1, on_frame=lambda: ticks.append(1))
    return root, result, ticks


def test_files_in_the_icl_nuim_layout(written):
    root, result, ticks = written
    assert result.paths == (root / "living_room_traj0_frei_png", root / "living_room_traj1_frei_png")
    assert len(ticks) == 6 and not [p for p in root.iterdir() if p.name.startswith(".")]
    seq = result.paths[1]
    assert sorted(p.name for p in seq.iterdir()) == ["associations.txt", "depth", "intrinsics.txt",
                                                     "livingRoom1.gt.freiburg", "rgb"]
    assert (seq / "associations.txt").read_text().splitlines() == [f"{k} depth/{k}.png {k} rgb/{k}.png"
                                                                    for k in range(3)]
    times, T = read_tum(seq / "livingRoom1.gt.freiburg")
    assert times.tolist() == [0, 1, 2] and np.allclose(np.linalg.det(T[:, :3, :3]), 1.0)
    K = tr.read_intrinsics(seq / "intrinsics.txt")
    assert K[1, 1] < 0 and np.allclose(K, indoor.camera_K(0.1)[0], atol=1e-6, rtol=0)
    rgb, depth = tr.read_rgb_png(seq / "rgb" / "0.png"), tr.read_depth_png(seq / "depth" / "0.png")
    assert rgb.shape == (48, 64, 3) and depth.shape == (48, 64) and 0.3 < depth.min() and depth.max() < 10
    assert result.sequences[0].trajectory == result.paths[0] / "livingRoom0.gt.freiburg"
    assert json.loads((root / "synth_indoor.json").read_text())["settings"]["seed"] == 4
    assert len(index_sequence(seq)) == 3


def test_deterministic_and_refuses_to_overwrite(written, tmp_path):
    root, _, _ = written
    again = indoor.generate_indoor(tmp_path, sequences=1, frames=2, seed=4, scale=0.1)
    for kind in ("rgb", "depth"):
        assert (again.paths[0] / kind / "1.png").read_bytes() == (root / "living_room_traj0_frei_png" / kind /
                                                                  "1.png").read_bytes()
    with pytest.raises(DcslamError, match="living_room_traj0_frei_png exists; pass --force"):
        indoor.generate_indoor(tmp_path, sequences=1, frames=1, scale=0.1)
    forced = indoor.generate_indoor(tmp_path, sequences=1, frames=1, seed=5, scale=0.1, force=True)
    assert sorted(p.name for p in (forced.paths[0] / "rgb").iterdir()) == ["0.png"]


@pytest.mark.parametrize("kwargs, match", [({"sequences": 0}, "sequences"), ({"frames": 0}, "frames"),
                                           ({"scale": 0.01}, "scale"), ({"scale": 5}, "scale")])
def test_bad_arguments(tmp_path, kwargs, match):
    with pytest.raises(DcslamError, match=match):
        indoor.generate_indoor(tmp_path / "out", **kwargs)
    assert not (tmp_path / "out").exists()


def test_depth_agrees_with_poses_only_through_the_negative_fy():
    """Frame 0's depth moved into frame 6 with the true poses lands on frame 6's depth, with ICL-NUIM's fy < 0."""
    rng = np.random.default_rng([1, 0, 7])
    room = indoor.build_room(rng)
    T = indoor.handheld_trajectory(room, 7, rng)
    K, width, height = indoor.camera_K(0.25)
    grid = CameraGrid(K, width, height)
    look = indoor.Look(np.array([0.6, 0.45, 0.3], np.float32), False)
    d0, d6 = (indoor.render(room, look, grid, T[k], rng)[0] for k in (0, 6))

    def reprojection_error(K_used):
        v, u = np.mgrid[0:height, 0:width]
        z = d0.ravel()
        p = np.stack([(u.ravel() - K_used[0, 2]) / K_used[0, 0] * z, (v.ravel() - K_used[1, 2]) / K_used[1, 1] * z,
                      z], 1)
        T_6_0 = np.linalg.inv(T[6]) @ T[0]
        q = p @ T_6_0[:3, :3].T + T_6_0[:3, 3]
        uu = np.rint(K_used[0, 0] * q[:, 0] / q[:, 2] + K_used[0, 2]).astype(int)
        vv = np.rint(K_used[1, 1] * q[:, 1] / q[:, 2] + K_used[1, 2]).astype(int)
        inside = (uu >= 0) & (uu < width) & (vv >= 0) & (vv < height)
        return np.median(np.abs(d6[vv[inside], uu[inside]] - q[inside, 2]))

    flipped = K.copy()
    flipped[1, 1] *= -1
    assert reprojection_error(K) < 0.01 and reprojection_error(flipped) > 3 * reprojection_error(K)


def test_room_and_handheld_path():
    rng = np.random.default_rng([3, 0, 7])
    room = indoor.build_room(rng)
    assert 5.5 <= room.size_x <= 7.5 and 4.8 <= room.size_y <= 6.0 and len(room.shapes) > 40
    inside = [s for s in room.shapes if s.material not in (indoor.WALL, indoor.CEILING)]
    for shape in inside:  # furniture stays in the room
        corners = shape.corners()
        assert corners[:, :2].min() > -1e-6 and corners[:, 0].max() < room.size_x + 1e-6
        assert corners[:, 1].max() < room.size_y + 1e-6 and corners[:, 2].min() > -1e-6
    T = indoor.handheld_trajectory(room, 300, rng)
    step = np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1)
    R = T[:, :3, :3]
    turn = np.degrees(np.arccos(np.clip((np.einsum("nij,nij->n", R[:-1], R[1:]) - 1) / 2, -1, 1)))
    assert 0.003 < step.min() and step.max() < 0.04 and turn.max() < 1.2
    assert np.allclose(np.linalg.det(R), 1.0) and np.allclose(R @ np.swapaxes(R, 1, 2), np.eye(3), atol=1e-12)
    xy = T[:, :2, 3]
    assert xy.min() > 1.3 and (xy[:, 0].max() < room.size_x - 1.3) and (xy[:, 1].max() < room.size_y - 1.3)
    assert 1.0 < T[:, 2, 3].min() and T[:, 2, 3].max() < 1.7
    assert np.all(R[:, 2, 1] > 0.9)  # the camera's y axis points up (world z)


def test_camera_K_scales_icl_intrinsics():
    K, width, height = indoor.camera_K(1.0)
    assert (width, height) == (640, 480) and np.array_equal(K, tr.ICL_K)
    K, width, height = indoor.camera_K(0.5)
    assert (width, height) == (320, 240) and K[1, 1] == -240.0 and K[0, 2] == 159.5 and K[1, 2] == 119.5
