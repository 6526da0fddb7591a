"""Procedural street layout: what the scene holds and where."""
import numpy as np
import pytest

from dcslam.synth.street.generate import make_drive, street_calibration
from dcslam.synth.street.scene import CAR, FACADE, FOLIAGE, METAL, SIDEWALK  # noqa: F401


@pytest.fixture(scope="module")
def truth():
    return make_drive(2, 0, 60, street_calibration())[0]


def test_street_has_the_kinds_of_objects_of_kitti_streets(truth):
    materials = {s.material for s in truth.scene.shapes}
    assert {FACADE, SIDEWALK, CAR, METAL, FOLIAGE} <= materials
    assert len(truth.scene.movers) >= 2


def test_nothing_static_stands_in_the_driving_lanes(truth):
    path = truth.scene.drive.path
    tree_s = path.s
    for shape in truth.scene.shapes:
        i = np.argmin(np.linalg.norm(path.xy - shape.center[:2], axis=1))
        h = path.heading[i]
        lateral = -np.sin(h) * (shape.center[0] - path.xy[i, 0]) + np.cos(h) * (shape.center[1] - path.xy[i, 1])
        left = np.array([-np.sin(h), np.cos(h)])
        extent = np.sum(np.abs(left @ shape.R_world_obj[:2, :]) * shape.half)  # half-width across the road
        if tree_s[0] + 5 < path.s[i] < tree_s[-1] - 5:
            assert lateral + extent < -1.75 + 1e-6 or lateral - extent > 5.25 - 1e-6, (shape, lateral)


def test_moving_cars_move(truth):
    scene = truth.scene
    position = np.zeros(3)
    static = len(scene.shapes_at(0.0, position, 1e6)) - 6 * len(scene.movers)
    a = scene.shapes_at(0.0, position, 1e6)[static:]
    b = scene.shapes_at(1.0, position, 1e6)[static:]
    speeds = [np.linalg.norm(x.center - y.center) for x, y in zip(a[::6], b[::6])]
    assert len(speeds) == len(scene.movers) and min(speeds) > 5.0
