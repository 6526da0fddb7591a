"""The room of the indoor generator: walls, floor and ceiling, furniture along the walls (bookshelves with rows of
books, sideboards with doors and things on top, sofas with cushions, tables with chairs, plants), pictures, a door
and a window on the walls, a rug and a low table in the middle, and a ceiling lamp. Shapes are the generators'
shared solids (:class:`~dcslam.synth.shapes.Shape`)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dcslam.synth.shapes import BOX, CYLINDER, ELLIPSOID, Shape

# materials (indices into the albedo rules of :func:`albedo`)
WALL, CEILING, WOOD, FABRIC, PAINTED, BOOKS, PICTURE, PLANT, METAL, RUG, GLASS, FLOOR = range(12)


@dataclass(frozen=True)
class Room:
    """An axis-aligned room ``[0, size_x] x [0, size_y] x [0, height]`` metres (z up, the floor at z = 0), its
    shapes, and the ceiling lamp's position (3,)."""

    size_x: float
    size_y: float
    height: float
    shapes: list[Shape]
    lamp: np.ndarray


class _WallFrame:
    """Coordinates along wall ``w`` (0: y = 0, 1: x = size_x, 2: y = size_y, 3: x = 0, counter-clockwise):
    ``s`` metres along it, ``t`` metres out from it into the room, ``z`` up."""

    def __init__(self, room_x: float, room_y: float, wall: int):
        origins = [(0.0, 0.0), (room_x, 0.0), (room_x, room_y), (0.0, room_y)]
        along = [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)]
        self.origin = np.array([*origins[wall], 0.0])
        self.a = np.array([*along[wall], 0.0])
        self.n = np.array([-self.a[1], self.a[0], 0.0])  # inward: a x n = z
        self.R = np.stack([self.a, self.n, [0.0, 0.0, 1.0]], axis=1)
        self.length = room_x if wall % 2 == 0 else room_y


class _Builder:
    def __init__(self, rng: np.random.Generator):
        self.rng, self.shapes = rng, []

    def box(self, frame: _WallFrame, s0, s1, t0, t1, z0, z1, material, color):
        center = frame.origin + frame.a * (s0 + s1) / 2 + frame.n * (t0 + t1) / 2 + np.array([0, 0, (z0 + z1) / 2])
        half = np.abs(np.array([s1 - s0, t1 - t0, z1 - z0])) / 2
        self.shapes.append(Shape(BOX, frame.R, center, half, material, np.asarray(color, dtype=np.float64)))

    def cylinder(self, frame: _WallFrame, s, t, z0, z1, radius, material, color):
        center = frame.origin + frame.a * s + frame.n * t + np.array([0, 0, (z0 + z1) / 2])
        self.shapes.append(Shape(CYLINDER, np.eye(3), center, np.array([radius, radius, (z1 - z0) / 2]), material,
                                 np.asarray(color, dtype=np.float64)))

    def ellipsoid(self, frame: _WallFrame, s, t, z, radii, material, color):
        center = frame.origin + frame.a * s + frame.n * t + np.array([0, 0, z])
        self.shapes.append(Shape(ELLIPSOID, frame.R, center, np.asarray(radii, dtype=np.float64), material,
                                 np.asarray(color, dtype=np.float64)))

    def color(self, base, spread=0.15):
        return np.clip(np.asarray(base) * self.rng.uniform(1 - spread, 1 + spread, 3), 0, 1)

    # furniture, each in wall coordinates from s0 over ``width`` metres -------------------------------------
    def bookshelf(self, f, s0, width):
        rng = self.rng
        depth, height = rng.uniform(0.28, 0.4), rng.uniform(1.5, 2.1)
        wood = self.color([0.55, 0.38, 0.22])
        s1, th = s0 + width, 0.025
        self.box(f, s0, s0 + th, 0, depth, 0, height, WOOD, wood)
        self.box(f, s1 - th, s1, 0, depth, 0, height, WOOD, wood)
        self.box(f, s0 + th, s1 - th, 0, th, 0, height, WOOD, wood * 0.8)
        levels = np.linspace(0.08, height - th, rng.integers(4, 6))
        for k, z in enumerate(levels):
            self.box(f, s0 + th, s1 - th, th, depth, z - th, z, WOOD, wood)
            if k + 1 < len(levels):  # blocks of books on this shelf
                s, room_up = s0 + th + rng.uniform(0, 0.1), levels[k + 1] - z - th
                while s < s1 - th - 0.1:
                    w = min(rng.uniform(0.08, 0.35), s1 - th - s)
                    h = min(rng.uniform(0.16, 0.3), room_up - 0.02)
                    d = rng.uniform(0.15, depth - 0.05)
                    if h > 0.08 and rng.random() < 0.85:
                        self.box(f, s, s + w, th, th + d, z, z + h, BOOKS, self.color(rng.choice(_BOOK_COLOURS)))
                    s += w + rng.uniform(0.0, 0.12)

    def sideboard(self, f, s0, width):
        rng = self.rng
        depth, height = rng.uniform(0.4, 0.55), rng.uniform(0.7, 0.95)
        paint = self.color(rng.choice(np.array([[0.85, 0.85, 0.82], [0.3, 0.32, 0.35], [0.6, 0.45, 0.3]])))
        s1 = s0 + width
        self.box(f, s0 + 0.04, s1 - 0.04, 0, depth - 0.05, 0, 0.1, PAINTED, paint * 0.5)          # plinth
        self.box(f, s0, s1, 0, depth, 0.1, height - 0.03, PAINTED, paint)                       # body
        self.box(f, s0 - 0.02, s1 + 0.02, 0, depth + 0.03, height - 0.03, height, WOOD, self.color([0.5, 0.35, 0.2]))
        doors = max(1, int(round(width / 0.5)))
        edges = np.linspace(s0, s1, doors + 1)
        for a, b in zip(edges[:-1], edges[1:]):                                                 # doors and knobs
            self.box(f, a + 0.01, b - 0.01, depth, depth + 0.018, 0.13, height - 0.06, PAINTED, paint * 0.95)
            self.cylinder(f, (a + b) / 2, depth + 0.03, height - 0.2, height - 0.16, 0.015, METAL, [0.7, 0.7, 0.7])
        self.things_on_top(f, s0, s1, 0.0, depth, height)

    def things_on_top(self, f, s0, s1, t0, t1, z):
        """One to three things standing on the surface [s0, s1] x [t0, t1] at height z, clear of the wall."""
        rng = self.rng
        for _ in range(rng.integers(1, 4)):
            kind = rng.integers(4)
            r = (rng.uniform(0.04, 0.08), rng.uniform(0.06, 0.12), rng.uniform(0.06, 0.15),
                 rng.uniform(0.1, 0.16))[kind]
            if t1 - t0 < 2 * r + 0.04 or s1 - s0 < 2 * r + 0.04:
                continue
            s, t = rng.uniform(s0 + r + 0.02, s1 - r - 0.02), rng.uniform(t0 + r + 0.02, t1 - r - 0.02)
            if kind == 0:    # vase
                self.cylinder(f, s, t, z, z + rng.uniform(0.15, 0.35), r, PAINTED, self.color(rng.choice(_ACCENTS)))
            elif kind == 1:  # bowl / ball
                self.ellipsoid(f, s, t, z + r * 0.5, [r, r, r * 0.6], PAINTED, self.color(rng.choice(_ACCENTS)))
            elif kind == 2:  # box / stack of books lying down
                w = rng.uniform(r, 2 * r)
                self.box(f, s - w, s + w, t - r, t + r, z, z + rng.uniform(0.04, 0.15), BOOKS,
                         self.color(rng.choice(_BOOK_COLOURS)))
            else:            # lamp: base, stem, shade
                self.cylinder(f, s, t, z, z + 0.03, 0.08, METAL, [0.3, 0.3, 0.3])
                self.cylinder(f, s, t, z + 0.03, z + 0.35, 0.012, METAL, [0.6, 0.6, 0.6])
                self.cylinder(f, s, t, z + 0.3, z + 0.5, r, FABRIC, self.color([0.9, 0.85, 0.7]))

    def sofa(self, f, s0, width):
        rng = self.rng
        depth = rng.uniform(0.8, 0.95)
        cloth = self.color(rng.choice(np.array([[0.45, 0.5, 0.6], [0.6, 0.3, 0.25], [0.5, 0.5, 0.45],
                                                [0.25, 0.35, 0.3]])))
        s1, arm = s0 + width, 0.18
        self.box(f, s0 + 0.05, s1 - 0.05, 0.05, depth - 0.05, 0, 0.1, WOOD, [0.2, 0.15, 0.1])
        self.box(f, s0, s1, 0, depth, 0.1, 0.42, FABRIC, cloth)
        self.box(f, s0 + arm, s1 - arm, 0, 0.22, 0.42, 0.85, FABRIC, cloth * 0.95)
        for a in (s0, s1 - arm):
            self.box(f, a, a + arm, 0, depth, 0.42, 0.62, FABRIC, cloth * 0.9)
        seats = max(2, int(round((width - 2 * arm) / 0.65)))
        edges = np.linspace(s0 + arm, s1 - arm, seats + 1)
        for a, b in zip(edges[:-1], edges[1:]):
            self.box(f, a + 0.01, b - 0.01, 0.22, depth - 0.02, 0.42, 0.55, FABRIC, cloth * 1.05)
        for _ in range(rng.integers(0, 3)):
            s = rng.uniform(s0 + arm + 0.25, s1 - arm - 0.25)
            self.ellipsoid(f, s, 0.32, 0.72, [0.2, 0.09, 0.18], FABRIC, self.color(rng.choice(_ACCENTS)))

    def table(self, f, s0, width):
        rng = self.rng
        depth, height = rng.uniform(0.7, 0.9), rng.uniform(0.72, 0.78)
        wood = self.color([0.6, 0.42, 0.25])
        s1, t0, t1 = s0 + width, 0.08, 0.08 + depth
        self.box(f, s0, s1, t0, t1, height - 0.035, height, WOOD, wood)
        for s in (s0 + 0.05, s1 - 0.1):
            for t in (t0 + 0.05, t1 - 0.1):
                self.box(f, s, s + 0.05, t, t + 0.05, 0, height - 0.035, WOOD, wood * 0.85)
        self.things_on_top(f, s0, s1, t0, t1, height)
        for s in rng.uniform(s0 + 0.3, s1 - 0.3, rng.integers(1, 3)):  # chairs in front
            self.chair(f, s, t1 + rng.uniform(0.05, 0.25), wood)

    def chair(self, f, s, t, wood):
        self.box(f, s - 0.22, s + 0.22, t, t + 0.42, 0.43, 0.47, WOOD, wood)
        for ds in (-0.2, 0.16):
            for dt in (0.0, 0.38):
                self.box(f, s + ds, s + ds + 0.04, t + dt, t + dt + 0.04, 0, 0.43, WOOD, wood * 0.85)
        self.box(f, s - 0.22, s + 0.22, t + 0.38, t + 0.42, 0.47, 0.92, WOOD, wood)

    def plant(self, f, s0, width):
        rng = self.rng
        s, r = s0 + width / 2, rng.uniform(0.12, 0.2)
        h = rng.uniform(0.3, 0.5)
        t = 1.4 * r + 0.05  # the foliage clears the wall
        self.cylinder(f, s, t, 0, h, r, PAINTED, self.color(rng.choice(_ACCENTS)))
        self.ellipsoid(f, s, t, h + rng.uniform(0.2, 0.4), [r * 1.4, r * 1.4, rng.uniform(0.25, 0.45)], PLANT,
                       self.color([0.2, 0.4, 0.15]))

    def wall_things(self, f, height):
        """Pictures, sometimes a door or a window, a skirting board."""
        rng = self.rng
        self.box(f, 0, f.length, 0, 0.015, 0, 0.08, PAINTED, [0.9, 0.9, 0.88])
        s = rng.uniform(0.4, 1.2)
        while s < f.length - 0.8:
            kind = rng.random()
            if kind < 0.15 and s < f.length - 1.2:     # door with its frame
                self.box(f, s - 0.06, s + 0.96, 0, 0.02, 0, 2.1, PAINTED, [0.92, 0.92, 0.9])
                self.box(f, s, s + 0.9, 0.02, 0.045, 0, 2.03, WOOD, self.color([0.7, 0.55, 0.4]))
                self.cylinder(f, s + 0.8, 0.07, 1.0, 1.02, 0.02, METAL, [0.75, 0.75, 0.7])
                s += 1.1
            elif kind < 0.3 and s < f.length - 1.4:    # window: frame, pane and sill
                w, z0 = rng.uniform(0.9, 1.3), rng.uniform(0.85, 1.0)
                z1 = min(z0 + rng.uniform(1.1, 1.4), height - 0.2)
                self.box(f, s, s + w, 0, 0.05, z0, z1, PAINTED, [0.95, 0.95, 0.95])
                self.box(f, s + 0.06, s + w - 0.06, 0.05, 0.06, z0 + 0.06, z1 - 0.06, GLASS, [0.75, 0.85, 0.95])
                self.box(f, s - 0.05, s + w + 0.05, 0, 0.18, z0 - 0.04, z0, PAINTED, [0.9, 0.9, 0.9])
                s += w + 0.3
            else:                                      # picture
                w, h = min(rng.uniform(0.3, 0.9), f.length - 0.1 - s), rng.uniform(0.25, 0.7)
                z0 = rng.uniform(1.3, 1.7)
                self.box(f, s, s + w, 0, rng.uniform(0.02, 0.05), z0, min(z0 + h, height - 0.1), PICTURE,
                         self.color(rng.choice(_ACCENTS)))
                s += w + rng.uniform(0.3, 1.0)


_BOOK_COLOURS = np.array([[0.7, 0.15, 0.12], [0.15, 0.25, 0.55], [0.2, 0.45, 0.25], [0.85, 0.75, 0.3],
                          [0.9, 0.88, 0.82], [0.3, 0.2, 0.15], [0.5, 0.2, 0.45]])
_ACCENTS = np.array([[0.8, 0.3, 0.2], [0.2, 0.4, 0.7], [0.9, 0.75, 0.2], [0.3, 0.6, 0.4], [0.85, 0.85, 0.85],
                     [0.25, 0.25, 0.3]])
_FURNITURE = ("bookshelf", "sideboard", "sofa", "table", "plant")
_FURNITURE_ODDS = (0.25, 0.25, 0.2, 0.2, 0.1)
_WIDTHS = {"bookshelf": (0.8, 1.6), "sideboard": (1.0, 2.0), "sofa": (1.7, 2.4), "table": (1.0, 1.6),
           "plant": (0.5, 0.7)}
CORNER_M = 0.55  # furniture keeps this far from the corners, so pieces on adjacent walls never overlap


def build_room(rng: np.random.Generator) -> Room:
    """A furnished room of 5.5-7.5 x 4.8-6 x 2.6-3 m (deterministic given ``rng``)."""
    size_x, size_y, height = rng.uniform(5.5, 7.5), rng.uniform(4.8, 6.0), rng.uniform(2.6, 3.0)
    b = _Builder(rng)
    wall_paint = b.color(rng.choice(np.array([[0.88, 0.86, 0.8], [0.75, 0.82, 0.85], [0.9, 0.8, 0.7],
                                              [0.8, 0.85, 0.75]])), 0.05)
    slab = 0.3
    shell = [  # walls and ceiling: slabs outside the room (the camera is outside every shape)
        ((-slab / 2, size_y / 2, height / 2), (slab / 2, size_y / 2 + slab, height / 2 + slab), WALL, wall_paint),
        ((size_x + slab / 2, size_y / 2, height / 2), (slab / 2, size_y / 2 + slab, height / 2 + slab), WALL,
         wall_paint * 0.97),
        ((size_x / 2, -slab / 2, height / 2), (size_x / 2 + slab, slab / 2, height / 2 + slab), WALL, wall_paint),
        ((size_x / 2, size_y + slab / 2, height / 2), (size_x / 2 + slab, slab / 2, height / 2 + slab), WALL,
         wall_paint * 0.97),
        ((size_x / 2, size_y / 2, height + slab / 2), (size_x / 2 + slab, size_y / 2 + slab, slab / 2), CEILING,
         np.array([0.95, 0.95, 0.93])),
    ]
    for center, half, material, color in shell:
        b.shapes.append(Shape(BOX, np.eye(3), np.array(center), np.array(half), material, np.asarray(color)))
    for wall in range(4):
        f = _WallFrame(size_x, size_y, wall)
        b.wall_things(f, height)
        s = CORNER_M + rng.uniform(0.0, 0.4)
        while True:
            kind = _FURNITURE[rng.choice(len(_FURNITURE), p=_FURNITURE_ODDS)]
            width = rng.uniform(*_WIDTHS[kind])
            if s + width > f.length - CORNER_M:
                break
            getattr(b, kind)(f, s, width)
            s += width + rng.uniform(0.1, 0.6)
    centre = _WallFrame(size_x, size_y, 0)
    cx, cy = size_x / 2 + rng.uniform(-0.5, 0.5), size_y / 2 + rng.uniform(-0.4, 0.4)
    rug_x, rug_y = rng.uniform(1.2, 1.6), rng.uniform(0.8, 1.1)
    b.box(centre, cx - rug_x, cx + rug_x, cy - rug_y, cy + rug_y, 0, 0.012, RUG, b.color([0.6, 0.25, 0.2]))
    w, d, h = rng.uniform(0.4, 0.6), rng.uniform(0.3, 0.45), rng.uniform(0.38, 0.45)     # low table
    b.box(centre, cx - w, cx + w, cy - d, cy + d, h - 0.04, h, WOOD, b.color([0.45, 0.3, 0.18]))
    b.box(centre, cx - w + 0.05, cx + w - 0.05, cy - d + 0.05, cy + d - 0.05, 0.012, h - 0.04, WOOD,
          b.color([0.35, 0.25, 0.15]))
    b.things_on_top(centre, cx - w, cx + w, cy - d, cy + d, h)
    lamp = np.array([size_x / 2, size_y / 2, height - 0.45])
    b.cylinder(centre, lamp[0], lamp[1], height - 0.4, height, 0.01, METAL, [0.5, 0.5, 0.5])
    b.cylinder(centre, lamp[0], lamp[1], height - 0.6, height - 0.38, 0.22, FABRIC, [0.95, 0.92, 0.8])
    return Room(size_x, size_y, height, b.shapes, lamp)
