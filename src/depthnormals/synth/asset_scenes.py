"""Scene recipes built from real asset meshes (:mod:`depthnormals.synth.assets`), with the
procedural rooms and streets of :mod:`depthnormals.synth.scenes` as their shell.

Seven indoor recipes (furnished rooms, cluttered tables and shelves, toys, robots) and five
outdoor ones (streets with vehicles, kerbs, poles, cones and vegetation). Like the procedural
recipes, ``recipe(builder) -> Scene`` places parts with the builder's ``rng`` only, so
``make_scene(name, seed=s)`` returns the same mesh for the same seed. Cameras are sampled
like a robot's or a hand-held camera's: centres 0.4-1.8 m above the floor, look-at points
lower (0-1.2 m), so views pitch down a little.

The names are known without trimesh or pybullet (:data:`ASSET_INDOOR`, :data:`ASSET_OUTDOOR`);
building a scene needs both (``pip install 'depthnormals[assets]'``). Each scene's ``meta``
lists the assets it used (``meta["assets"]``); their licences are in
:data:`depthnormals.synth.assets.ASSETS`.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .assets import RANDOM_OBJECTS, load_asset
from .meshes import box, cylinder, icosphere, transform
from .scenes import Scene, _Builder, _building, _car, _chair, _ground, _kerbs, _pole, _room, _table

__all__ = ["ASSET_INDOOR", "ASSET_OUTDOOR", "asset_recipe"]

#: Small objects scattered on tables, shelves and floors.
CLUTTER = ("mug", "lego", "domino", "toy_cylinder", "toy_prism", "torus", "concave_box",
           *(f"object_{k}" for k in RANDOM_OBJECTS))
#: Camera centre heights (robot to hand-held) and look-at heights, metres.
EYE_Z = (0.4, 1.8)
TARGET_Z = (0.2, 1.0)


class _AssetBuilder(_Builder):
    """The procedural builder, plus asset placement and a record of the assets used."""

    def __init__(self, rng: np.random.Generator) -> None:
        super().__init__(rng)
        self.used: set[str] = set()

    def put(self, name: str, x: float, y: float, z: float = 0.0, *, height: float | None = None,
            angle: float | None = None, solid: bool = False) -> None:
        a = self.u(0.0, 360.0) if angle is None else angle
        self.add(load_asset(name, height=height, rotate_z_deg=a, translate=(x, y, z)), solid=solid)
        self.used.add(name)

    def pick(self, names) -> str:
        return names[int(self.rng.integers(len(names)))]

    def scene(self, name: str, kind: str, eye_box, target_box) -> Scene:
        s = super().scene(name, kind, eye_box, target_box)
        s.meta = {"recipe": name, "assets": sorted(self.used)}
        return s


# ---------------------------------------------------------------- parts

def _clutter(b: _AssetBuilder, x0, y0, x1, y1, z, n: int, *, names=CLUTTER) -> None:
    """``n`` small objects on the rectangle [x0, x1] x [y0, y1] at height ``z``."""
    for _ in range(n):
        b.put(b.pick(names), b.u(x0, x1), b.u(y0, y1), z)


def _shelf_with_clutter(b: _AssetBuilder, x, y, w, d, h, angle) -> None:
    """Open shelf (sides, back, boards) whose levels hold asset clutter and books."""
    levels = max(2, int(h / 0.38))
    parts = [box((-w / 2, -d / 2, 0.0), (-w / 2 + 0.02, d / 2, h)),
             box((w / 2 - 0.02, -d / 2, 0.0), (w / 2, d / 2, h)),
             box((-w / 2, d / 2 - 0.02, 0.0), (w / 2, d / 2, h))]
    a = np.radians(angle)
    c, s = np.cos(a), np.sin(a)
    for k in range(levels + 1):
        zk = k * (h - 0.02) / levels
        parts.append(box((-w / 2, -d / 2, zk), (w / 2, d / 2, zk + 0.02)))
        if k == levels:
            break
        u = -w / 2 + 0.04
        while u < w / 2 - 0.1:
            if b.rng.uniform() < 0.4:  # a run of books
                bw, bh = b.u(0.02, 0.05), b.u(0.15, 0.3)
                lo = (u, -d / 2 + b.u(0.0, 0.05), zk + 0.02)
                parts.append(box(lo, (u + bw, d / 2 - 0.03, zk + 0.02 + bh)))
                u += bw + b.u(0.0, 0.01)
            else:  # an object
                lx, ly = u + 0.05, b.u(-d / 4, d / 4)
                b.put(b.pick(CLUTTER), x + c * lx - s * ly, y + s * lx + c * ly, zk + 0.02)
                u += b.u(0.08, 0.16)
    for p in parts:
        b.add(transform(p, rotate_z_deg=angle, translate=(x, y, 0.0)), solid=False)
    r = max(w, d) / 2
    b.solids.append(np.array([[x - r, y - r, 0.0], [x + r, y + r, h]]))


def _sofa(b: _Builder, x0, y0, length, angle) -> None:
    parts = [box((0.0, 0.0, 0.0), (length, 0.9, 0.42)), box((0.0, 0.7, 0.42), (length, 0.9, 0.85)),
             box((0.0, 0.0, 0.42), (0.15, 0.9, 0.62)), box((length - 0.15, 0.0, 0.42), (length, 0.9, 0.62))]
    for k in range(int(length / 0.6)):  # cushions
        parts.append(box((0.18 + k * 0.6, 0.05, 0.42), (0.72 + k * 0.6, 0.65, 0.52)))
    for p in parts:
        b.add(transform(p, rotate_z_deg=angle, translate=(x0, y0, 0.0)))


def _shrub(b: _Builder, x, y, r, *, z0: float = 0.0) -> None:
    """A bush: a clump of 6-12 overlapping spheres (vegetation with many occluding edges)."""
    for _ in range(int(b.rng.integers(6, 13))):
        rr = r * b.u(0.35, 0.6)
        c = (x + b.u(-r, r) * 0.7, y + b.u(-r, r) * 0.7, z0 + rr + b.u(0.0, r * 0.8))
        b.add(icosphere(c, rr, level=3), solid=False)


def _leafy_tree(b: _Builder, x, y, h) -> None:
    """Trunk, 3-5 limbs with foliage spheres around it and a crown sphere on top."""
    b.add(cylinder((x, y, 0.0), 0.14, h * 0.55))
    for _ in range(int(b.rng.integers(3, 6))):
        az, L = b.u(0.0, 2 * np.pi), b.u(0.8, 1.5)
        bx, by, bz = x + np.cos(az) * L * 0.6, y + np.sin(az) * L * 0.6, h * b.u(0.55, 0.75)
        b.add(cylinder((x, y, h * 0.45), 0.05, L, axis="z"), solid=False)
        b.add(icosphere((bx, by, bz), b.u(0.5, 0.9), level=3), solid=False)
    b.add(icosphere((x, y, h * 0.8), h * 0.18, level=4), solid=False)


def _bollards(b: _Builder, x0, x1, y, step) -> None:
    x = x0
    while x < x1:
        b.add(cylinder((x, y, 0.15), 0.08, 0.9))
        b.add(icosphere((x, y, 1.05), 0.08, level=3), solid=False)
        x += step


def _bin(b: _Builder, x, y) -> None:
    b.add(cylinder((x, y, 0.0), 0.25, 0.9))
    b.add(cylinder((x, y, 0.9), 0.28, 0.05), solid=False)


def _plant(b: _Builder, x, y, h) -> None:
    """A potted plant ``h`` metres tall: pot, stem and a leafy clump."""
    b.add(cylinder((x, y, 0.0), 0.16, 0.3))
    b.add(cylinder((x, y, 0.3), 0.02, h * 0.5), solid=False)
    _shrub(b, x, y, h * 0.3, z0=0.3 + h * 0.3)


def _cabinet(b: _Builder, x, y, w, d, h, angle) -> None:
    """A chest of drawers: body, drawer fronts standing 1.5 cm proud with 1 cm gaps, handles."""
    parts = [box((-w / 2, -d / 2, 0.0), (w / 2, d / 2, h))]
    n = max(2, int(h / 0.22))
    for k in range(n):
        z0 = 0.05 + k * (h - 0.05) / n
        z1 = z0 + (h - 0.05) / n - 0.01
        parts.append(box((-w / 2 + 0.02, -d / 2 - 0.015, z0), (w / 2 - 0.02, -d / 2, z1)))
        zm = (z0 + z1) / 2
        parts.append(box((-0.08, -d / 2 - 0.04, zm - 0.01), (0.08, -d / 2 - 0.015, zm + 0.01)))
    for p in parts:
        b.add(transform(p, rotate_z_deg=angle, translate=(x, y, 0.0)), solid=False)
    r = max(w, d) / 2
    b.solids.append(np.array([[x - r, y - r, 0.0], [x + r, y + r, h]]))


def _curtain(b: _Builder, x0, x1, y, z0, z1, *, folds: int = 16, depth: float = 0.06) -> None:
    """A pleated curtain along the wall y = ``y`` (a zigzag strip: one crease per fold)."""
    xs = np.linspace(x0, x1, 2 * folds + 1)
    ys = y - depth * (np.arange(xs.size) % 2) - 0.02
    V = np.concatenate([np.stack([xs, ys, np.full(xs.size, z)], 1) for z in (z0, z1)])
    i = np.arange(xs.size - 1)
    m = xs.size
    F = np.concatenate([np.stack([i, i + 1, i + m + 1], 1), np.stack([i, i + m + 1, i + m], 1)])
    b.add((V, F), solid=False)


def _floor_clutter(b: _AssetBuilder, x0, y0, x1, y1, n: int) -> None:
    """``n`` bags, boxes and odd objects on the floor (random objects resized to 10-40 cm)."""
    names = (*(f"object_{k}" for k in RANDOM_OBJECTS), "concave_box", "shape_sorter", "soccerball")
    for _ in range(n):
        b.put(b.pick(names), b.u(x0, x1), b.u(y0, y1), height=b.u(0.1, 0.4))


def _wall_details(b: _AssetBuilder, w, d, h) -> None:
    """Skirting boards, a door with its frame, picture frames, a window with sill and a
    finned radiator: the creases and small steps of a real room's walls."""
    t = 0.015
    for lo, hi in (((0.0, 0.0, 0.0), (w, t, 0.1)), ((0.0, d - t, 0.0), (w, d, 0.1)),
                   ((0.0, 0.0, 0.0), (t, d, 0.1)), ((w - t, 0.0, 0.0), (w, d, 0.1))):
        b.add(box(lo, hi), solid=False)
    dx = b.u(0.6, w - 1.6)  # door on the y = 0 wall
    for lo, hi in (((dx - 0.06, 0.0, 0.0), (dx, 0.04, 2.1)), ((dx + 0.9, 0.0, 0.0), (dx + 0.96, 0.04, 2.1)),
                   ((dx - 0.06, 0.0, 2.1), (dx + 0.96, 0.04, 2.16)), ((dx, 0.0, 0.0), (dx + 0.9, 0.03, 2.1)),
                   ((dx + 0.75, 0.03, 1.0), (dx + 0.85, 0.09, 1.03))):
        b.add(box(lo, hi), solid=False)
    for _ in range(int(b.rng.integers(2, 5))):  # picture frames on the x = 0 wall
        y, z, fw, fh = b.u(0.5, d - 1.0), b.u(1.2, 1.8), b.u(0.3, 0.8), b.u(0.25, 0.6)
        b.add(box((0.0, y, z), (0.03, y + fw, z + fh)), solid=False)
    wy = b.u(0.5, max(0.6, w - 2.0))  # window on the y = d wall, radiator below it
    b.add(box((wy - 0.05, d - 0.2, 0.9), (wy + 1.25, d, 0.94)), solid=False)  # sill
    for k in range(3):
        b.add(box((wy + k * 0.6, d - 0.08, 0.94), (wy + k * 0.6 + 0.05, d, 2.1)), solid=False)  # mullions
    for k in range(18):
        xk = wy + 0.1 + k * 0.055
        b.add(box((xk, d - 0.12, 0.15), (xk + 0.03, d - 0.03, 0.75)), solid=False)
    _curtain(b, wy - 0.5, wy - 0.05, d, 0.3, min(h - 0.1, 2.5), folds=8)
    _curtain(b, wy + 1.25, wy + 1.7, d, 0.3, min(h - 0.1, 2.5), folds=8)


def _fence(b: _Builder, x0, x1, y, h, *, gap: float = 0.06) -> None:
    """A picket fence along y = ``y``: two rails and 4 cm slats ``gap`` apart."""
    b.add(box((x0, y - 0.04, h * 0.25), (x1, y - 0.02, h * 0.33)), solid=False)
    b.add(box((x0, y - 0.04, h * 0.7), (x1, y - 0.02, h * 0.78)), solid=False)
    x = x0
    while x < x1 - 0.04:
        b.add(box((x, y - 0.02, 0.0), (x + 0.04, y, h)), solid=False)
        x += 0.04 + gap


def _indoor_view(w, d):
    return ([[0.4, 0.4, EYE_Z[0]], [w - 0.4, d - 0.4, EYE_Z[1]]],
            [[0.0, 0.0, TARGET_Z[0]], [w, d, TARGET_Z[1]]])


# ---------------------------------------------------------------- indoor recipes

def furnished_living(b: _AssetBuilder) -> Scene:
    w, d, h = b.u(4.5, 6.0), b.u(4.0, 5.5), b.u(2.5, 2.9)
    _room(b, w, d, h)
    _wall_details(b, w, d, h)
    _sofa(b, 0.4, d - 1.3, 2.4, 0.0)
    _table(b, 1.6, d - 2.2, 1.1, 0.6, 0.45)
    _clutter(b, 1.1, d - 2.45, 2.1, d - 1.95, 0.45, 7)
    _shelf_with_clutter(b, w - 0.25, 1.6, 1.4, 0.35, 1.9, 90.0)
    _shelf_with_clutter(b, 1.0, 0.25, 1.2, 0.35, 1.5, 180.0)
    b.put("teddy", 0.9, d - 1.0, 0.42, height=b.u(0.3, 0.45))
    b.put("soccerball", w - 1.4, d - 0.8)
    b.put("r2d2", w - 1.3, 2.4, solid=True)
    _plant(b, w - 0.5, d - 0.5, b.u(0.8, 1.4))
    _plant(b, 0.5, 1.2, b.u(0.6, 1.1))
    _cabinet(b, 0.3, d / 2, 0.9, 0.45, 0.9, -90.0)
    _clutter(b, 0.15, d / 2 - 0.4, 0.45, d / 2 + 0.4, 0.9, 5)
    _floor_clutter(b, 0.6, 0.6, w - 0.6, d - 1.5, 26)
    b.add(box((2.8, d - 0.5, 0.0), (3.4, d - 0.1, 0.6)))  # side cabinet with a lamp
    b.add(cylinder((3.1, d - 0.3, 0.6), 0.02, 0.45), solid=False)
    b.add(cylinder((3.1, d - 0.3, 1.0), 0.15, 0.2, sections=128), solid=False)
    _clutter(b, 0.5, 0.8, w - 0.8, d - 2.6, 0.0, 8,
             names=("shape_sorter", "concave_box", "soccerball", "tray"))
    return b.scene("furnished_living", "indoor", *_indoor_view(w, d))


def robot_lab(b: _AssetBuilder) -> Scene:
    w, d, h = b.u(6.0, 8.0), b.u(5.0, 6.5), b.u(2.8, 3.2)
    _room(b, w, d, h)
    _wall_details(b, w, d, h)
    for i in range(2):
        x = 1.6 + i * (w - 3.2)
        _table(b, x, 1.0, 1.6, 0.8, 0.8)
        b.put(b.pick(("kuka_iiwa", "panda")), x - 0.45, 1.0, 0.8, angle=b.u(0, 360))
        _clutter(b, x - 0.1, 0.7, x + 0.7, 1.3, 0.8, 8)
        b.put("tray", x + 0.35, 1.0, 0.8)
    _table(b, w / 2, d - 1.2, 2.0, 0.8, 0.9)
    _clutter(b, w / 2 - 0.9, d - 1.5, w / 2 + 0.9, d - 0.9, 0.9, 16)
    _shelf_with_clutter(b, w / 2 - 1.8, d - 0.25, 1.2, 0.35, 1.8, 0.0)
    _chair(b, w / 2 - 0.5, d - 1.85, b.u(-30, 30))
    _chair(b, w / 2 + 0.5, d - 1.85, b.u(-30, 30))
    b.put("husky", w / 2 + b.u(-0.8, 0.8), d / 2, solid=True)
    b.put("kiva_pod", w - 0.6, d - 0.6, angle=b.u(-10, 10), solid=True)
    _shelf_with_clutter(b, 0.25, d / 2 + 0.5, 1.6, 0.4, 2.0, 90.0)
    _cabinet(b, w - 0.3, d / 2, 1.0, 0.5, 1.1, 90.0)
    _floor_clutter(b, 0.6, 1.6, w - 0.6, d - 1.8, 24)
    return b.scene("robot_lab", "indoor", *_indoor_view(w, d))


def warehouse(b: _AssetBuilder) -> Scene:
    w, d, h = b.u(8.0, 10.0), b.u(7.0, 8.5), 4.0
    _room(b, w, d, h)
    _wall_details(b, w, d, h)
    for i in range(int((w - 3) / 1.3)):
        for j in range(2):
            if b.rng.uniform() < 0.85:
                b.put("kiva_pod", 1.5 + i * 1.3, 2.0 + j * (d - 4.0), angle=90.0 * int(b.rng.integers(4)),
                      solid=True)
    for _ in range(3):
        b.put("husky", b.u(1.5, w - 1.5), d / 2 + b.u(-0.8, 0.8), solid=True)
    for _ in range(24):  # stacked cartons along the front wall and in the aisle
        front = b.rng.uniform() < 0.5
        x, y, zz = b.u(1.0, w - 1.0), b.u(0.4, 1.0) if front else b.u(d / 2 - 1.0, d / 2 + 1.0), 0.0
        for _ in range(int(b.rng.integers(1, 4))):
            s = b.u(0.3, 0.5)
            b.add(box((x - s / 2, y - s / 2, zz), (x + s / 2, y + s / 2, zz + s)))
            zz += s
    for _ in range(5):
        b.put("traffic_cone", b.u(1.0, w - 1.0), d / 2 + b.u(-1.5, 1.5), height=b.u(0.3, 0.5))
    _floor_clutter(b, 1.0, d / 2 - 1.5, w - 1.0, d / 2 + 1.5, 36)
    _shelf_with_clutter(b, 0.25, d / 2, 2.4, 0.45, 2.2, 90.0)
    return b.scene("warehouse", "indoor", *_indoor_view(w, d))


def kids_room(b: _AssetBuilder) -> Scene:
    w, d, h = b.u(3.5, 4.5), b.u(3.5, 4.5), b.u(2.4, 2.7)
    _room(b, w, d, h)
    _wall_details(b, w, d, h)
    _table(b, w / 2, d / 2, 0.9, 0.6, 0.5)
    _chair(b, w / 2 - 0.7, d / 2, 90.0)
    _clutter(b, w / 2 - 0.4, d / 2 - 0.25, w / 2 + 0.4, d / 2 + 0.25, 0.5, 8,
             names=("lego", "domino", "toy_cylinder", "toy_prism", "torus"))
    toys = ("shape_sorter", "lego", "domino", "toy_cylinder", "toy_prism", "soccerball", "teddy", "torus")
    for _ in range(60):  # toys on the floor, at play-box sizes (resized to 8-30 cm)
        b.put(b.pick(toys), b.u(0.3, w - 0.3), b.u(0.3, d - 1.1), height=b.u(0.08, 0.3))
    _plant(b, 0.4, 0.4, b.u(0.6, 1.0))
    _shelf_with_clutter(b, w - 0.2, d / 2, 1.2, 0.3, 1.2, 90.0)
    b.add(box((0.1, d - 1.0, 0.0), (1.9, d - 0.1, 0.45)))  # bed
    b.put("teddy", 0.6, d - 0.6, 0.45, height=0.35)
    _cabinet(b, w / 2, 0.3, 0.8, 0.4, 0.7, 0.0)
    _shelf_with_clutter(b, 0.2, d / 2 - 0.5, 1.0, 0.3, 1.4, -90.0)
    return b.scene("kids_room", "indoor", *_indoor_view(w, d))


def dining_table(b: _AssetBuilder) -> Scene:
    w, d, h = b.u(4.0, 5.0), b.u(3.5, 4.5), b.u(2.5, 2.8)
    _room(b, w, d, h)
    _wall_details(b, w, d, h)
    tw, td = b.u(1.4, 1.8), b.u(0.8, 1.0)
    _table(b, w / 2, d / 2, tw, td, 0.75)
    for sx in (-1, 1):
        _chair(b, w / 2 + sx * tw / 4, d / 2 - td / 2 - 0.35, 180.0)
        _chair(b, w / 2 + sx * tw / 4, d / 2 + td / 2 + 0.35, 0.0)
    for sx in (-1, 1):
        b.put("tray", w / 2 + sx * tw / 4, d / 2, 0.75)
    _clutter(b, w / 2 - tw / 2 + 0.1, d / 2 - td / 2 + 0.1, w / 2 + tw / 2 - 0.1, d / 2 + td / 2 - 0.1,
             0.75, 18, names=("mug", "mug", "torus", "concave_box", *CLUTTER[7:]))
    _shelf_with_clutter(b, 0.25, d / 2, 1.4, 0.4, 1.8, 90.0)
    b.add(box((w - 0.6, 0.3, 0.0), (w - 0.05, d - 0.3, 0.9)))  # sideboard
    _clutter(b, w - 0.55, 0.4, w - 0.1, d - 0.4, 0.9, 8)
    eye = [[0.5, 0.5, 1.0], [w - 0.7, d - 0.5, EYE_Z[1]]]
    target = [[w / 2 - tw / 2, d / 2 - td / 2, 0.6], [w / 2 + tw / 2, d / 2 + td / 2, 0.9]]
    return b.scene("dining_table", "indoor", eye, target)


def cluttered_office(b: _AssetBuilder) -> Scene:
    w, d, h = b.u(5.0, 6.5), b.u(4.0, 5.5), b.u(2.6, 3.0)
    _room(b, w, d, h)
    _wall_details(b, w, d, h)
    for i in range(2):
        x = 1.4 + i * (w - 2.8)
        _table(b, x, d / 2, 1.4, 0.7, 0.74)
        _chair(b, x, d / 2 - 0.65, 180.0 + b.u(-25, 25))
        b.add(box((x - 0.25, d / 2 + 0.15, 0.74), (x + 0.25, d / 2 + 0.2, 1.08)))  # monitor
        b.add(cylinder((x, d / 2 + 0.2, 0.74), 0.08, 0.02), solid=False)
        _clutter(b, x - 0.6, d / 2 - 0.3, x + 0.6, d / 2 + 0.1, 0.74, 14)
    for k in range(3):
        _shelf_with_clutter(b, 1.0 + k * (w - 2.0) / 2, d - 0.22, 1.0, 0.35, 2.0, 0.0)
    b.put(b.pick(("r2d2", "husky")), w / 2, 0.9, solid=True)
    _plant(b, 0.5, 0.5, b.u(0.8, 1.4))
    _plant(b, w - 0.5, 0.5, b.u(0.8, 1.4))
    _cabinet(b, 0.3, 1.2, 0.5, 0.5, 0.7, -90.0)
    _floor_clutter(b, 0.5, 0.4, w - 0.5, d / 2 - 0.9, 34)
    _curtain(b, 1.0, w - 1.0, d - 0.45, 2.1, min(h - 0.05, 2.6), folds=30, depth=0.04)  # blind
    return b.scene("cluttered_office", "indoor", *_indoor_view(w, d))


def pantry(b: _AssetBuilder) -> Scene:
    w, d, h = b.u(3.0, 4.0), b.u(2.5, 3.5), b.u(2.4, 2.7)
    _room(b, w, d, h)
    _wall_details(b, w, d, h)
    _shelf_with_clutter(b, w / 2, d - 0.22, w - 0.4, 0.4, 2.1, 0.0)
    _shelf_with_clutter(b, 0.22, d / 2 - 0.2, 1.4, 0.4, 2.1, 90.0)
    _shelf_with_clutter(b, w - 0.22, d / 2 - 0.2, 1.4, 0.4, 2.1, -90.0)
    _clutter(b, 0.6, 0.3, w - 0.6, 0.9, 0.0, 6, names=("concave_box", "tray", "soccerball", "mug"))
    eye = [[0.8, 0.2, 1.0], [w - 0.8, 0.9, EYE_Z[1]]]
    return b.scene("pantry", "indoor", eye, [[0.0, 0.9, TARGET_Z[0]], [w, d, 1.6]])


# ---------------------------------------------------------------- outdoor recipes

def _street_shell(b: _AssetBuilder, length: float, width: float, height=(6.0, 15.0)) -> tuple[float, float]:
    yl, yr = -width / 2, width / 2
    _ground(b, -5, yl - 12, length + 5, yr + 12)
    _kerbs(b, -5, length + 5, yl, yr)
    for y0, y1 in ((yl - 12.0, yl - 2.5), (yr + 2.5, yr + 12.0)):
        x = -5.0
        while x < length + 5:
            lx = b.u(6, 14)
            _building(b, x, y0, x + lx - 0.3, y1, b.u(*height))
            x += lx
    return yl, yr


def _street_view(length, yl, yr):
    return ([[0.0, yl - 2.0, EYE_Z[0]], [length, yr + 2.0, EYE_Z[1]]],
            [[0.0, yl - 3.0, TARGET_Z[0]], [length, yr + 3.0, TARGET_Z[1]]])


def street_assets(b: _AssetBuilder) -> Scene:
    length = 30.0
    yl, yr = _street_shell(b, length, b.u(7.0, 9.0))
    for _ in range(3):
        _car(b, b.u(2, length - 2), b.u(yl + 1.2, yr - 1.2), b.u(-8, 8) + 180.0 * (b.rng.uniform() < 0.5))
    for _ in range(2):
        b.put(b.pick(("husky", "racecar")), b.u(1, length - 1), b.u(yl + 0.8, yr - 0.8), solid=True)
    for k in range(4):
        _pole(b, (k + 0.5) * length / 4, yr + 0.5, 4.5)
    for _ in range(4):
        side = yl - 1.3 if b.rng.uniform() < 0.5 else yr + 1.3
        _leafy_tree(b, b.u(1, length - 1), side, b.u(4.0, 6.0))
    for _ in range(6):
        b.put("traffic_cone", b.u(1, length - 1), b.u(yl + 0.3, yr - 0.3), height=b.u(0.45, 0.75))
    for _ in range(5):
        side = yl - b.u(0.6, 2.2) if b.rng.uniform() < 0.5 else yr + b.u(0.6, 2.2)
        _shrub(b, b.u(0, length), side, b.u(0.3, 0.6))
    _bollards(b, 2.0, 12.0, yl - 0.35, 1.5)
    _fence(b, 14.0, 26.0, yl - 2.4, 1.0)
    for _ in range(6):
        _shrub(b, b.u(0, length), yr + b.u(1.5, 2.3), b.u(0.4, 0.7))
    return b.scene("street_assets", "outdoor", *_street_view(length, yl, yr))


def sidewalk(b: _AssetBuilder) -> Scene:
    length = 20.0
    yl, yr = _street_shell(b, length, b.u(5.0, 6.0), height=(4.0, 8.0))
    _bollards(b, 1.0, length - 1.0, yr + 0.35, 1.2)
    for _ in range(4):
        _bin(b, b.u(1, length - 1), yr + b.u(1.0, 2.0))
    for _ in range(8):
        _shrub(b, b.u(0, length), yr + b.u(0.8, 2.2), b.u(0.3, 0.7))
    for _ in range(3):
        x = b.u(1, length - 1)
        b.add(box((x - 0.6, yr + 1.4, 0.15), (x + 0.6, yr + 2.3, 0.6)))  # planter
        _shrub(b, x, yr + 1.85, 0.45)
    for _ in range(4):
        b.put("traffic_cone", b.u(1, length - 1), b.u(yl + 0.3, yr - 0.3), height=b.u(0.45, 0.75))
    for _ in range(4):
        b.put("stone", b.u(1, length - 1), yl - b.u(0.5, 2.0), height=b.u(0.1, 0.4))
    b.put("racecar", b.u(2, length - 2), yr + 1.2, 0.15)
    _fence(b, 0.0, length, yr + 2.45, 1.1)
    _car(b, b.u(3, length - 3), yl + 1.2, 0.0)
    for k in range(3):
        _pole(b, (k + 0.5) * length / 3, yr + 0.5, 4.5)
    eye = [[0.0, yr - 0.5, EYE_Z[0]], [length, yr + 2.3, EYE_Z[1]]]
    target = [[0.0, yl, TARGET_Z[0]], [length, yr + 2.5, TARGET_Z[1]]]
    return b.scene("sidewalk", "outdoor", eye, target)


def park_terrain(b: _AssetBuilder) -> Scene:
    b.put("terrain", 0.0, 0.0, -0.1, angle=0.0)
    _ground(b, -30, -30, 30, 30)
    r = 11.0
    for _ in range(6):
        _leafy_tree(b, b.u(-r, r), b.u(-r, r), b.u(3.5, 6.0))
    for _ in range(12):
        _shrub(b, b.u(-r, r), b.u(-r, r), b.u(0.3, 0.8))
    for _ in range(8):
        b.put("stone", b.u(-r, r), b.u(-r, r), height=b.u(0.15, 0.5))
    for _ in range(2):
        b.put("soccerball", b.u(-r, r), b.u(-r, r))
        b.put("husky", b.u(-r, r), b.u(-r, r), solid=True)
    for _ in range(3):
        x, y, a = b.u(-r, r), b.u(-r, r), b.u(0, 360)
        for p in (box((-0.9, -0.2, 0.42), (0.9, 0.2, 0.47)), box((-0.9, 0.17, 0.47), (0.9, 0.22, 0.85)),
                  box((-0.8, -0.2, 0.0), (-0.75, 0.2, 0.42)), box((0.75, -0.2, 0.0), (0.8, 0.2, 0.42))):
            b.add(transform(p, rotate_z_deg=a, translate=(x, y, 0.0)))
    return b.scene("park_terrain", "outdoor", [[-r, -r, EYE_Z[0]], [r, r, EYE_Z[1]]],
                   [[-r, -r, TARGET_Z[0]], [r, r, TARGET_Z[1]]])


def construction_site(b: _AssetBuilder) -> Scene:
    r = 12.0
    _ground(b, -20, -20, 20, 20)
    for k in range(3):
        a = 2 * np.pi * k / 3 + b.u(-0.3, 0.3)
        cx, cy = 0.85 * 16 * np.cos(a), 0.85 * 16 * np.sin(a)
        _building(b, cx - 3, cy - 3, cx + 3, cy + 3, b.u(4, 9), windows=False)
    for _ in range(14):
        b.put("traffic_cone", b.u(-r, r), b.u(-r, r), height=b.u(0.45, 0.75))
    for _ in range(10):
        b.put("stone", b.u(-r, r), b.u(-r, r), height=b.u(0.1, 0.6))
    for _ in range(3):
        b.put("husky", b.u(-r, r), b.u(-r, r), solid=True)
        _car(b, b.u(-r, r), b.u(-r, r), b.u(0, 360))
    for _ in range(6):  # pallets of blocks
        x, y = b.u(-r, r), b.u(-r, r)
        b.add(box((x - 0.6, y - 0.5, 0.0), (x + 0.6, y + 0.5, 0.15)))
        for i in range(int(b.rng.integers(2, 6))):
            bx, by = x + b.u(-0.45, 0.3), y + b.u(-0.35, 0.2)
            bz = 0.15 + 0.2 * (i % 2)
            b.add(box((bx, by, bz), (bx + 0.2, by + 0.3, bz + 0.2)), solid=False)
    for _ in range(4):
        _pole(b, b.u(-r, r), b.u(-r, r), 4.0)
    for _ in range(5):
        _shrub(b, b.u(-r, r), b.u(-r, r), b.u(0.3, 0.7))
    return b.scene("construction_site", "outdoor", [[-r, -r, EYE_Z[0]], [r, r, EYE_Z[1]]],
                   [[-r, -r, TARGET_Z[0]], [r, r, TARGET_Z[1]]])


def temple_square(b: _AssetBuilder) -> Scene:
    b.put("monastery", 0.0, 0.0, angle=0.0)
    _ground(b, -80, -80, 80, 80)
    r = 14.0
    for _ in range(6):
        _shrub(b, b.u(-r, r), b.u(-r, r), b.u(0.3, 0.8))
    for _ in range(6):
        b.put("stone", b.u(-r, r), b.u(-r, r), height=b.u(0.15, 0.5))
    for _ in range(4):
        b.put("traffic_cone", b.u(-r, r), b.u(-r, r), height=b.u(0.45, 0.75))
    b.put("husky", b.u(-r, r), b.u(-r, r), solid=True)
    return b.scene("temple_square", "outdoor", [[-r, -r, EYE_Z[0]], [r, r, EYE_Z[1]]],
                   [[-r, -r, TARGET_Z[0]], [r, r, TARGET_Z[1]]])


_RECIPES: dict[str, Callable[[_AssetBuilder], Scene]] = {
    f.__name__: f for f in (furnished_living, robot_lab, warehouse, kids_room, dining_table,
                            cluttered_office, pantry, street_assets, sidewalk, park_terrain,
                            construction_site, temple_square)}
#: Names of the indoor and outdoor asset recipes (known without trimesh or pybullet).
ASSET_INDOOR: tuple[str, ...] = ("furnished_living", "robot_lab", "warehouse", "kids_room", "dining_table",
                                 "cluttered_office", "pantry")
ASSET_OUTDOOR: tuple[str, ...] = ("street_assets", "sidewalk", "park_terrain", "construction_site",
                                  "temple_square")


def asset_recipe(name: str) -> Callable[[np.random.Generator], Scene]:
    """The recipe ``name`` as ``recipe(rng) -> Scene`` (:func:`make_scene` calls it)."""
    if name not in _RECIPES:
        raise ValueError(f"unknown asset scene {name!r}; valid: {', '.join(_RECIPES)}")
    return lambda rng: _RECIPES[name](_AssetBuilder(rng))
