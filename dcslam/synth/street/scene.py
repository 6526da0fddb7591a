"""Procedural street scenes: oriented boxes, vertical cylinders and ellipsoids placed along a path on a terrain.

A street is a sequence of zones along the ego path: *urban* (sidewalks with curbs, façades of varied height with
recessed ground floors and varied setbacks, parked cars, poles, street trees), *residential* (houses set back
behind hedges, many trees and bushes, some parked cars) and *open* (grass verges, a few far trees and poles: few
features, the hard case for odometry). A few cars drive along the road in either direction.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from dcslam.geometry.rotations import rotation_from_rpy
from dcslam.synth.shapes import BOX, CYLINDER, ELLIPSOID, Shape  # noqa: F401 (street builders use all three)
from dcslam.synth.street.trajectory import Drive

# materials: index → (name, LiDAR reflectance); colours are per object
ASPHALT, GRASS, SIDEWALK, FACADE, GLASS, CAR, TIRE, BARK, FOLIAGE, METAL, HEDGE, ROOF = range(12)
REFLECTANCE = np.array([0.15, 0.3, 0.35, 0.4, 0.05, 0.5, 0.05, 0.25, 0.3, 0.6, 0.3, 0.3], dtype=np.float32)

LANE_WIDTH_M = 3.5


@dataclass(frozen=True)
class MovingCar:
    """A car driving along the path: arc length ``s0 + direction · speed · t`` at ``lateral`` metres to the left."""

    s0: float
    speed: float
    direction: int
    lateral: float
    parts: tuple  # shapes in the car's own frame (x forward, y left, z up, origin on the ground)


@dataclass
class Scene:
    """The static shapes of a drive, the moving cars, the road's lateral extent and the zone of each path sample."""

    drive: Drive
    shapes: list[Shape]
    movers: list[MovingCar]
    road_right_m: float  # road edge to the right of the ego path (negative)
    road_left_m: float
    sun: np.ndarray = field(default_factory=lambda: np.array([0.4, -0.3, 0.87]))

    def __post_init__(self):
        self.centers = np.array([s.center for s in self.shapes]).reshape(-1, 3)
        self.radii = np.array([s.radius for s in self.shapes])

    def shapes_at(self, t: float, position: np.ndarray, max_range_m: float) -> list[Shape]:
        """Static shapes whose bounding sphere comes within ``max_range_m`` of ``position`` (3,), plus the moving
        cars at time ``t``."""
        near = np.linalg.norm(self.centers - position, axis=1) - self.radii < max_range_m
        shapes = [self.shapes[i] for i in np.flatnonzero(near)]
        path, terrain = self.drive.path, self.drive.terrain
        for car in self.movers:
            s = car.s0 + car.direction * car.speed * t
            xy, heading = path.place(s, car.lateral)
            if np.linalg.norm(xy - position[:2]) > max_range_m + 5:
                continue
            yaw = heading + (0.0 if car.direction > 0 else np.pi)
            z = terrain.height(xy[0], xy[1])
            R = rotation_from_rpy([0.0], [0.0], [yaw])[0]
            origin = np.array([xy[0], xy[1], z])
            shapes += [Shape(p.kind, R @ p.R_world_obj, origin + R @ p.center, p.half, p.material, p.color)
                       for p in car.parts]
        return shapes


def _car_parts(rng: np.random.Generator) -> tuple:
    length, width = rng.uniform(3.9, 4.8), rng.uniform(1.7, 1.9)
    color = rng.choice(np.array([[0.7, 0.1, 0.1], [0.1, 0.2, 0.6], [0.8, 0.8, 0.8], [0.15, 0.15, 0.15],
                                 [0.5, 0.5, 0.55], [0.9, 0.9, 0.85], [0.2, 0.4, 0.2]]))
    R_level = np.eye(3)
    body = Shape(BOX, R_level, np.array([0.0, 0.0, 0.75]), np.array([length / 2, width / 2, 0.4]), CAR, color)
    cabin = Shape(BOX, R_level, np.array([-0.2, 0.0, 1.35]), np.array([length * 0.3, width / 2 - 0.08, 0.25]), GLASS,
                  color * 0.5)
    R_wheel = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])  # local z (cylinder axis) → car y
    wheels = tuple(Shape(CYLINDER, R_wheel, np.array([sx * (length / 2 - 0.75), sy * (width / 2 - 0.1), 0.33]),
                         np.array([0.33, 0.33, 0.11]), TIRE, np.array([0.08, 0.08, 0.08]))
                   for sx in (-1, 1) for sy in (-1, 1))
    return (body, cabin) + wheels


class _Builder:
    def __init__(self, drive: Drive, rng: np.random.Generator):
        self.drive, self.rng, self.shapes = drive, rng, []

    def frame(self, s: float, lateral: float, yaw_offset: float = 0.0):
        xy, heading = self.drive.path.place(s, lateral)
        return xy, heading + yaw_offset, float(self.drive.terrain.height(xy[0], xy[1]))

    def box(self, s, lateral, along, across, bottom, height, material, color, sunk=0.0, pitch=0.0, z0=None):
        """A box centred at path coordinates (s, lateral), sides ``along`` × ``across`` metres, from ``bottom``
        metres above the ground (``sunk`` metres more below) to ``bottom + height``."""
        xy, yaw, z = self.frame(s, lateral)
        z = z if z0 is None else z0
        R = rotation_from_rpy([0.0], [pitch], [yaw])[0]
        zc = z + bottom + (height - sunk) / 2
        self.shapes.append(Shape(BOX, R, np.array([xy[0], xy[1], zc]),
                                 np.array([along / 2, across / 2, (height + sunk) / 2]), material, np.asarray(color)))

    def cylinder(self, s, lateral, radius, bottom, height, material, color):
        xy, _, z = self.frame(s, lateral)
        self.shapes.append(Shape(CYLINDER, np.eye(3), np.array([xy[0], xy[1], z + bottom + height / 2 - 0.25]),
                                 np.array([radius, radius, height / 2 + 0.25]), material, np.asarray(color)))

    def ellipsoid(self, s, lateral, radii, center_height, material, color):
        xy, yaw, z = self.frame(s, lateral)
        R = rotation_from_rpy([0.0], [0.0], [yaw])[0]
        self.shapes.append(Shape(ELLIPSOID, R, np.array([xy[0], xy[1], z + center_height]), np.asarray(radii, float),
                                 material, np.asarray(color)))

    def tree(self, s, lateral):
        rng = self.rng
        trunk_h, crown = rng.uniform(1.8, 3.2), rng.uniform(1.4, 3.0)
        # crowns stay out of the driving lanes (lateral −1.75 … 5.25 m)
        clearance = lateral - 1.5 * LANE_WIDTH_M if lateral > 0 else -LANE_WIDTH_M / 2 - lateral
        crown = float(np.clip(crown, 0.8, max(clearance - 0.1, 0.8)))
        self.cylinder(s, lateral, rng.uniform(0.12, 0.3), 0.0, trunk_h + crown * 0.5, BARK, [0.35, 0.25, 0.15])
        green = np.array([0.18, 0.38, 0.12]) * rng.uniform(0.7, 1.3)
        self.ellipsoid(s, lateral, [crown, crown, crown * rng.uniform(0.8, 1.3)], trunk_h + crown, FOLIAGE, green)

    def pole(self, s, lateral):
        height = self.rng.uniform(4.0, 8.0)
        self.cylinder(s, lateral, self.rng.uniform(0.06, 0.12), 0.0, height, METAL, [0.55, 0.55, 0.58])
        if self.rng.random() < 0.4:  # a sign
            self.box(s, lateral, 0.05, 0.7, height - 1.5, 0.6, METAL, self.rng.choice(
                np.array([[0.1, 0.3, 0.7], [0.8, 0.1, 0.1], [0.9, 0.8, 0.1]])))

    def parked_car(self, s, lateral):
        xy, yaw, z = self.frame(s, lateral, yaw_offset=self.rng.normal(0, 0.03))
        R = rotation_from_rpy([0.0], [0.0], [yaw])[0]
        origin = np.array([xy[0], xy[1], z])
        for p in _car_parts(self.rng):
            self.shapes.append(Shape(p.kind, R @ p.R_world_obj, origin + R @ p.center, p.half, p.material, p.color))

    def facade_block(self, s, length, side, front, kind):
        """A building: 1–3 boxes side by side at varied setbacks, a recessed ground floor, sometimes a roof box."""
        rng = self.rng
        height = rng.uniform(6.0, 18.0) if kind == "urban" else rng.uniform(4.5, 8.0)
        depth = rng.uniform(8.0, 14.0)
        color = np.array([[0.75, 0.7, 0.6], [0.6, 0.35, 0.25], [0.85, 0.85, 0.8], [0.55, 0.55, 0.5],
                          [0.8, 0.65, 0.45], [0.65, 0.7, 0.75]])[rng.integers(6)] * rng.uniform(0.8, 1.1)
        parts = rng.integers(1, 4)
        cuts = np.sort(rng.uniform(0.2, 0.8, parts - 1)) * length
        edges = np.concatenate([[0.0], cuts, [length]])
        for a, b in zip(edges[:-1], edges[1:]):
            setback = front + (rng.uniform(0.0, 1.8) if parts > 1 else 0.0)
            h = height + rng.uniform(-2.0, 2.0) * (parts > 1)
            mid, along = s + (a + b) / 2, b - a - 0.05
            ground_floor = rng.uniform(2.8, 3.6)
            recess = rng.uniform(0.6, 1.6) if rng.random() < 0.6 else 0.0
            self.box(mid, side * (setback + recess + depth / 2), along, depth, 0.0, ground_floor, FACADE,
                     color * 0.85, sunk=1.0)
            self.box(mid, side * (setback + depth / 2), along, depth, ground_floor, h - ground_floor, FACADE, color)
            if rng.random() < 0.5:
                self.box(mid, side * (setback + depth / 2 + 0.5), along - 0.6, depth - 1.0, h, rng.uniform(1.0, 3.0),
                         ROOF, np.array([0.45, 0.25, 0.2]))


def build_scene(drive: Drive, rng: np.random.Generator, s_min: float, s_max: float) -> Scene:
    """Lay out the street along the path from arc length ``s_min`` to ``s_max``.

    Cars driving ahead of the ego car in its lane are faster than the ego car ever is, so they never collide.
    """
    b = _Builder(drive, rng)
    park_right, park_left = rng.choice([0.4, 2.3]), rng.choice([0.4, 2.3])
    right = -(LANE_WIDTH_M / 2 + park_right)
    left = LANE_WIDTH_M * 1.5 + park_left
    s = s_min
    while s < s_max:
        zone = rng.choice(["urban", "residential", "open"], p=[0.5, 0.3, 0.2])
        end = min(s + rng.uniform(40.0, 120.0), s_max)
        for side, edge, park in ((-1, -right, park_right), (1, left, park_left)):
            _fill_side(b, zone, s, end, side, edge, park)
        s = end
    movers = []
    for _ in range(rng.integers(2, 6)):
        direction = int(rng.choice([-1, 1]))
        lateral = LANE_WIDTH_M if direction < 0 else rng.choice([0.0, LANE_WIDTH_M])
        s0 = rng.uniform(s_min + 20, s_max - 20) if direction < 0 else rng.uniform(15.0, 80.0)
        speed = rng.uniform(6.0, 14.0)
        if direction > 0 and lateral == 0.0:
            speed = drive.motion.v0 + 2 * drive.motion.a + rng.uniform(0.5, 3.0)
        movers.append(MovingCar(s0, speed, direction, float(lateral), _car_parts(rng)))
    return Scene(drive=drive, shapes=b.shapes, movers=movers, road_right_m=right, road_left_m=left,
                 sun=np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), 0.8]))


def _fill_side(b: _Builder, zone: str, s0: float, s1: float, side: int, edge: float, park: float) -> None:
    rng = b.rng
    sidewalk = rng.uniform(2.0, 4.0) if zone != "open" else 0.0
    if sidewalk:  # raised 15 cm behind a curb, in 5 m segments pitched with the terrain
        for s in np.arange(s0, s1, 5.0):
            xy, heading = b.drive.path.place(s + 2.5, side * (edge + sidewalk / 2))
            gx, gy = b.drive.terrain.gradient(xy[0], xy[1])
            pitch = -np.arctan(gx * np.cos(heading) + gy * np.sin(heading))
            b.box(s + 2.5, side * (edge + sidewalk / 2), 5.1, sidewalk, 0.0, 0.15, SIDEWALK, [0.6, 0.6, 0.58],
                  sunk=0.4, pitch=pitch)
    back = edge + sidewalk
    if park > 1.0 and zone != "open":
        for s in np.arange(s0 + 3.0, s1 - 3.0, 6.0):
            if rng.random() < (0.6 if zone == "urban" else 0.35):
                b.parked_car(s + rng.normal(0, 0.3), side * (edge - 1.1))
    if zone == "urban":
        s = s0
        while s < s1 - 6.0:
            length = min(rng.uniform(8.0, 25.0), s1 - s)
            b.facade_block(s, length, side, back + rng.uniform(0.3, 5.0), "urban")
            s += length + (rng.uniform(2.0, 8.0) if rng.random() < 0.3 else 0.0)
        for s in np.arange(s0 + rng.uniform(0, 30), s1, rng.uniform(25.0, 40.0)):
            b.pole(s, side * (edge + 0.5))
        for s in np.arange(s0 + rng.uniform(0, 20), s1, rng.uniform(12.0, 30.0)):
            if sidewalk > 2.5 and rng.random() < 0.6:
                b.tree(s, side * (edge + sidewalk - 0.9))
    elif zone == "residential":
        s = s0
        while s < s1 - 8.0:
            length = rng.uniform(9.0, 16.0)
            setback = back + rng.uniform(4.0, 10.0)
            if rng.random() < 0.8:
                b.facade_block(s, min(length, s1 - s), side, setback, "residential")
            if rng.random() < 0.6:  # a hedge along the front garden
                b.box(s + length / 2, side * (back + 0.6), length - 0.8, rng.uniform(0.6, 1.0), 0.0,
                      rng.uniform(0.9, 1.7), HEDGE, np.array([0.15, 0.3, 0.1]) * rng.uniform(0.8, 1.2))
            for _ in range(rng.integers(0, 3)):
                r = rng.uniform(0.5, 1.2)
                b.ellipsoid(s + rng.uniform(0, length), side * (back + rng.uniform(1.5, 4.0)), [r, r, r * 0.7],
                            r * 0.5, FOLIAGE, np.array([0.2, 0.35, 0.12]) * rng.uniform(0.8, 1.2))
            s += length + rng.uniform(1.0, 5.0)
        for s in np.arange(s0 + rng.uniform(0, 10), s1, rng.uniform(7.0, 14.0)):
            b.tree(s, side * (back + rng.uniform(1.0, 3.5)))
        for s in np.arange(s0 + rng.uniform(0, 30), s1, rng.uniform(30.0, 45.0)):
            b.pole(s, side * (edge + 0.4))
    else:  # open: grass, a few poles and far trees
        for s in np.arange(s0 + rng.uniform(0, 40), s1, rng.uniform(40.0, 60.0)):
            b.pole(s, side * (edge + 1.0))
        for _ in range(rng.integers(0, 4)):
            b.tree(rng.uniform(s0, s1), side * (edge + rng.uniform(8.0, 35.0)))
