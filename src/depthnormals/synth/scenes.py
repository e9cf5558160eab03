"""Procedural scene recipes (10 indoor, 10 outdoor), each reproducible from a seed.

World frame: metres, z up, floor / ground at z = 0. A recipe is a function
``recipe(rng) -> Scene`` that places parts with ``rng`` only, so
``make_scene(name, seed=s)`` always returns the same mesh. Curved parts are finely
tessellated (icosphere level 5, 128 cylinder sections).

Examples
--------
>>> from depthnormals.synth.scenes import make_scene, scene_names
>>> len(scene_names("indoor")), len(scene_names("outdoor"))
(10, 10)
>>> s = make_scene("office", seed=3)
>>> s.kind, s.faces.shape[1], bool(s.faces.shape[0] > 1000)
('indoor', 3, True)
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .meshes import Mesh, box, cone, cylinder, icosphere, merge, transform

__all__ = ["PART_NAMES", "Scene", "load_mesh_scene", "make_scene", "scene_names"]

#: Part labels of :attr:`Scene.parts` (the label is the index). The procedural recipes tag
#: the ground (whose visible top is the drivable surface in the street and open recipes),
#: kerbs (raised pavements), buildings, vehicles, vegetation, poles and benches; every other
#: part (furniture, rooms, fountains, spheres) is "other". Append only: labels are stored.
PART_NAMES = ("other", "ground", "kerb", "building", "vehicle", "vegetation", "pole", "bench")


@dataclass
class Scene:
    """A triangle mesh with what the camera sampler needs.

    Attributes
    ----------
    name : str
        Recipe name (or file stem for user meshes).
    kind : str
        ``"indoor"``, ``"outdoor"`` or ``"mesh"``.
    vertices : ndarray (N, 3) float64, metres, z up
    faces : ndarray (M, 3) int64
    solids : ndarray (S, 2, 3)
        Axis-aligned boxes (lo, hi) of closed objects; the camera may not be inside one.
    eye_box : ndarray (2, 3)
        Box where camera centres are drawn.
    target_box : ndarray (2, 3)
        Box where look-at points are drawn.
    meta : dict
        Recipe and seed (or source file).
    parts : ndarray (M,) uint8 or None
        Part label of each face, an index into :data:`PART_NAMES` (procedural recipes);
        None when unknown (user meshes).
    """

    name: str
    kind: str
    vertices: np.ndarray
    faces: np.ndarray
    solids: np.ndarray
    eye_box: np.ndarray
    target_box: np.ndarray
    meta: dict = field(default_factory=dict)
    parts: np.ndarray | None = None


class _Builder:
    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.parts: list[Mesh] = []
        self.solids: list[np.ndarray] = []
        self.labels: list[np.ndarray] = []

    def add(self, mesh: Mesh, *, solid: bool = True, part: str = "other") -> None:
        self.parts.append(mesh)
        self.labels.append(np.full(mesh[1].shape[0], PART_NAMES.index(part), dtype=np.uint8))
        if solid:
            V = mesh[0]
            self.solids.append(np.stack([V.min(0), V.max(0)]))

    def u(self, lo: float, hi: float) -> float:
        return float(self.rng.uniform(lo, hi))

    def scene(self, name: str, kind: str, eye_box, target_box) -> Scene:
        V, F = merge(self.parts)
        solids = np.array(self.solids) if self.solids else np.zeros((0, 2, 3))
        return Scene(name, kind, V, F, solids, np.asarray(eye_box, float), np.asarray(target_box, float),
                     {"recipe": name}, np.concatenate(self.labels))


# ---------------------------------------------------------------- furniture and street parts

def _room(b: _Builder, w: float, d: float, h: float) -> None:
    """Floor, ceiling and four walls (inward-facing shell, not a solid)."""
    t = 0.1
    b.add(box((-t, -t, -t), (w + t, d + t, 0.0)), solid=False)
    b.add(box((-t, -t, h), (w + t, d + t, h + t)), solid=False)
    b.add(box((-t, -t, 0.0), (0.0, d + t, h)), solid=False)
    b.add(box((w, -t, 0.0), (w + t, d + t, h)), solid=False)
    b.add(box((-t, -t, 0.0), (w + t, 0.0, h)), solid=False)
    b.add(box((-t, d, 0.0), (w + t, d + t, h)), solid=False)


def _table(b: _Builder, x, y, w, d, h, *, round_top=False) -> None:
    if round_top:
        b.add(cylinder((x, y, h - 0.04), min(w, d) / 2, 0.04))
        b.add(cylinder((x, y, 0.0), 0.04, h - 0.04))
        b.add(cylinder((x, y, 0.0), 0.25, 0.02))
        return
    b.add(box((x - w / 2, y - d / 2, h - 0.04), (x + w / 2, y + d / 2, h)))
    for sx in (-1, 1):
        for sy in (-1, 1):
            b.add(cylinder((x + sx * (w / 2 - 0.05), y + sy * (d / 2 - 0.05), 0.0), 0.025, h - 0.04))


def _chair(b: _Builder, x, y, angle) -> None:
    parts = [box((-0.22, -0.22, 0.42), (0.22, 0.22, 0.46)), box((-0.22, 0.18, 0.46), (0.22, 0.22, 0.9))]
    parts += [box((sx * 0.2 - 0.02, sy * 0.2 - 0.02, 0.0), (sx * 0.2 + 0.02, sy * 0.2 + 0.02, 0.42))
              for sx in (-1, 1) for sy in (-1, 1)]
    for p in parts:
        b.add(transform(p, rotate_z_deg=angle, translate=(x, y, 0.0)))


def _shelf(b: _Builder, x, y, w, d, h, angle, *, books=True) -> None:
    parts = [box((-w / 2, -d / 2, 0.0), (-w / 2 + 0.02, d / 2, h)),
             box((w / 2 - 0.02, -d / 2, 0.0), (w / 2, d / 2, h)),
             box((-w / 2, d / 2 - 0.02, 0.0), (w / 2, d / 2, h))]
    levels = max(2, int(h / 0.4))
    for k in range(levels + 1):
        z = k * (h - 0.02) / levels
        parts.append(box((-w / 2, -d / 2, z), (w / 2, d / 2, z + 0.02)))
        if books and k < levels:
            u = -w / 2 + 0.03
            while u < w / 2 - 0.08:
                bw = b.u(0.02, 0.06)
                bh = b.u(0.15, 0.3)
                lo = (u, -d / 2 + b.u(0.0, 0.05), z + 0.02)
                parts.append(box(lo, (u + bw, d / 2 - 0.03, z + 0.02 + bh)))
                u += bw + b.u(0.0, 0.01)
    for p in parts:
        b.add(transform(p, rotate_z_deg=angle, translate=(x, y, 0.0)), solid=False)
    r = max(w, d) / 2
    b.solids.append(np.array([[x - r, y - r, 0.0], [x + r, y + r, h]]))


def _stairs(b: _Builder, x, y, w, steps, rise, run) -> None:
    for k in range(steps):
        b.add(box((x, y + k * run, 0.0), (x + w, y + (k + 1) * run, (k + 1) * rise)))


def _building(b: _Builder, x0, y0, x1, y1, h, *, windows=True) -> None:
    b.add(box((x0, y0, 0.0), (x1, y1, h)), part="building")
    if not windows:
        return
    # window sills and frames protrude 5 cm from the two long facades
    n = max(1, int((x1 - x0) / 2.5))
    for i in range(n):
        xc = x0 + (i + 0.5) * (x1 - x0) / n
        for level in range(1, int(h / 3.0)):
            z = level * 3.0 - 1.8
            for ys, yo in ((y0, -0.05), (y1, 0.05)):
                lo = (xc - 0.6, min(ys, ys + yo), z)
                hi = (xc + 0.6, max(ys, ys + yo), z + 0.08)
                b.add(box(lo, hi), solid=False, part="building")


def _car(b: _Builder, x, y, angle) -> None:
    parts = [box((-2.1, -0.85, 0.3), (2.1, 0.85, 0.9)), box((-1.2, -0.75, 0.9), (0.9, 0.75, 1.4))]
    for sx in (-1.3, 1.3):
        for sy in (-0.75, 0.55):
            parts.append(cylinder((sx, sy, 0.33), 0.33, 0.2, axis="y"))
    for p in parts:
        b.add(transform(p, rotate_z_deg=angle, translate=(x, y, 0.0)), part="vehicle")


def _tree(b: _Builder, x, y, h) -> None:
    b.add(cylinder((x, y, 0.0), 0.15, h * 0.6), part="vegetation")
    r = h * 0.3
    if b.rng.uniform() < 0.5:
        b.add(icosphere((x, y, h * 0.6 + r * 0.6), r), part="vegetation")
    else:
        b.add(cone((x, y, h * 0.45), r * 1.1, h * 0.7), part="vegetation")


def _pole(b: _Builder, x, y, h) -> None:
    b.add(cylinder((x, y, 0.0), 0.06, h), part="pole")
    b.add(icosphere((x, y, h + 0.15), 0.2, level=4), part="pole")


def _bench(b: _Builder, x, y, angle) -> None:
    parts = [box((-0.9, -0.2, 0.42), (0.9, 0.2, 0.47)), box((-0.9, 0.17, 0.47), (0.9, 0.22, 0.85)),
             box((-0.8, -0.2, 0.0), (-0.75, 0.2, 0.42)), box((0.75, -0.2, 0.0), (0.8, 0.2, 0.42))]
    for p in parts:
        b.add(transform(p, rotate_z_deg=angle, translate=(x, y, 0.0)), part="bench")


def _ground(b: _Builder, x0, y0, x1, y1) -> None:
    b.add(box((x0, y0, -0.2), (x1, y1, 0.0)), solid=False, part="ground")


def _kerbs(b: _Builder, x0, x1, y_left, y_right) -> None:
    b.add(box((x0, y_left - 2.5, 0.0), (x1, y_left, 0.15)), solid=False, part="kerb")
    b.add(box((x0, y_right, 0.0), (x1, y_right + 2.5, 0.15)), solid=False, part="kerb")


def _indoor_eye(w, d, h=1.8):
    return [[0.4, 0.4, 1.0], [w - 0.4, d - 0.4, min(h - 0.3, 1.9)]], [[0.0, 0.0, 0.0], [w, d, min(h, 2.0)]]


# ---------------------------------------------------------------- indoor recipes

def living_room(b: _Builder) -> Scene:
    w, d, h = b.u(4.5, 6), b.u(4, 5.5), b.u(2.5, 2.9)
    _room(b, w, d, h)
    b.add(box((0.4, d - 1.3, 0.0), (2.6, d - 0.4, 0.45)))  # sofa seat
    b.add(box((0.4, d - 0.6, 0.45), (2.6, d - 0.4, 0.9)))   # sofa back
    _table(b, 1.5, d - 2.2, 1.1, 0.6, 0.45)
    _shelf(b, w - 0.3, 1.5, 1.2, 0.35, 1.8, 90.0)
    b.add(icosphere((w - 1.0, d - 1.0, 0.3), 0.3))
    b.add(cylinder((w - 1.0, 0.6, 0.0), 0.25, 0.6))
    return b.scene("living_room", "indoor", *_indoor_eye(w, d, h))


def office(b: _Builder) -> Scene:
    w, d, h = b.u(5, 7), b.u(4, 6), b.u(2.6, 3.0)
    _room(b, w, d, h)
    for i in range(3):
        x = 1.2 + i * (w - 2.0) / 3
        _table(b, x, d / 2, 1.4, 0.7, 0.74)
        _chair(b, x, d / 2 - 0.7, 180.0 + b.u(-20, 20))
        b.add(box((x - 0.25, d / 2 + 0.05, 0.74), (x + 0.25, d / 2 + 0.1, 1.1)))  # monitor
    _shelf(b, w / 2, d - 0.25, 2.0, 0.4, 2.0, 0.0)
    b.add(cylinder((0.5, 0.5, 0.0), 0.2, 0.45))  # bin
    return b.scene("office", "indoor", *_indoor_eye(w, d, h))


def classroom(b: _Builder) -> Scene:
    w, d, h = b.u(7, 9), b.u(6, 8), b.u(2.8, 3.2)
    _room(b, w, d, h)
    for i in range(3):
        for j in range(3):
            x, y = 1.5 + i * (w - 3) / 2, 1.8 + j * 1.6
            _table(b, x, y, 1.2, 0.5, 0.72)
            _chair(b, x, y - 0.55, 180.0)
    b.add(box((1.0, d - 0.05, 0.9), (w - 1.0, d, 2.1)), solid=False)  # board
    b.add(icosphere((w - 0.8, 0.8, 0.9), 0.25))  # globe
    b.add(cylinder((w - 0.8, 0.8, 0.0), 0.03, 0.65))
    return b.scene("classroom", "indoor", *_indoor_eye(w, d, h))


def library(b: _Builder) -> Scene:
    w, d, h = b.u(6, 8), b.u(6, 8), b.u(2.8, 3.2)
    _room(b, w, d, h)
    for i in range(3):
        _shelf(b, 1.5 + i * (w - 3) / 2, d / 2 + b.u(-0.5, 0.5), 1.8, 0.4, 2.2, 90.0)
    _shelf(b, w / 2, d - 0.25, 3.0, 0.4, 2.2, 0.0)
    _table(b, w / 2, 1.2, 1.2, 1.2, 0.75, round_top=True)
    return b.scene("library", "indoor", *_indoor_eye(w, d, h))


def cafe(b: _Builder) -> Scene:
    w, d, h = b.u(6, 8), b.u(5, 7), b.u(2.7, 3.1)
    _room(b, w, d, h)
    for i in range(2):
        for j in range(2):
            x, y = 1.8 + i * (w - 3.6), 1.6 + j * (d - 3.2)
            _table(b, x, y, 0.8, 0.8, 0.75, round_top=True)
            _chair(b, x - 0.6, y, 90.0)
            _chair(b, x + 0.6, y, -90.0)
            b.add(cylinder((x, y, 0.75), 0.045, 0.1))  # cup
    b.add(box((w - 1.0, 0.5, 0.0), (w - 0.4, d - 0.5, 1.1)))  # counter
    return b.scene("cafe", "indoor", *_indoor_eye(w, d, h))


def stairwell(b: _Builder) -> Scene:
    w, d, h = b.u(4, 5), b.u(6, 7), 4.0
    _room(b, w, d, h)
    _stairs(b, 0.3, 1.8, 1.4, 12, 0.17, 0.28)
    b.add(cylinder((2.0, 1.8, 0.0), 0.03, 3.0))
    b.add(cylinder((2.0, 5.2, 0.0), 0.03, 3.0))
    b.add(cylinder((2.0, 1.8, 0.95), 0.03, 3.6, axis="y", caps=True))  # handrail
    eye = [[2.5, 0.5, 1.0], [w - 0.4, d - 0.4, 1.9]]
    return b.scene("stairwell", "indoor", eye, [[0, 0, 0], [w, d, 2.5]])


def museum(b: _Builder) -> Scene:
    w, d, h = b.u(8, 10), b.u(6, 8), b.u(3.5, 4.5)
    _room(b, w, d, h)
    for i in range(3):
        x, y = 2.0 + i * (w - 4) / 2, d / 2 + b.u(-1, 1)
        b.add(box((x - 0.35, y - 0.35, 0.0), (x + 0.35, y + 0.35, 1.0)))
        b.add(icosphere((x, y, 1.0 + 0.3), 0.3))
    b.add(cylinder((1.0, 1.0, 0.0), 0.35, h))  # columns
    b.add(cylinder((w - 1.0, d - 1.0, 0.0), 0.35, h))
    return b.scene("museum", "indoor", *_indoor_eye(w, d, h))


def gym(b: _Builder) -> Scene:
    w, d, h = b.u(12, 15), b.u(8, 10), 6.0
    _room(b, w, d, h)
    for _ in range(4):
        b.add(icosphere((b.u(2, w - 2), b.u(2, d - 2), 0.12), 0.12))
    b.add(cylinder((0.8, d / 2, 0.0), 0.08, 3.05))  # hoop post
    b.add(box((0.8, d / 2 - 0.9, 2.9), (0.85, d / 2 + 0.9, 3.95)), solid=False)  # board
    _stairs(b, w - 6, d - 1.5, 5.0, 3, 0.4, 0.5)  # bleachers
    return b.scene("gym", "indoor", [[1.5, 0.5, 1.0], [w - 1.0, d - 2.0, 1.9]], [[0, 0, 0], [w, d, 2.0]])


def shop(b: _Builder) -> Scene:
    w, d, h = b.u(6, 8), b.u(5, 7), b.u(2.8, 3.2)
    _room(b, w, d, h)
    for i in range(2):
        _shelf(b, 2.0 + i * (w - 4), d / 2, 2.5, 0.5, 1.6, 90.0)
    for _ in range(6):
        x, y = b.u(0.5, w - 0.5), b.u(0.3, 1.0)
        b.add(box((x - 0.2, y - 0.15, 0.0), (x + 0.2, y + 0.15, b.u(0.2, 0.6))))
    b.add(cylinder((w - 0.8, d - 0.8, 0.0), 0.3, 1.0))
    return b.scene("shop", "indoor", *_indoor_eye(w, d, h))


def auditorium(b: _Builder) -> Scene:
    w, d, h = b.u(10, 12), b.u(9, 11), 5.0
    _room(b, w, d, h)
    _stairs(b, 0.0, 3.0, w, 6, 0.3, 0.9)  # tiered floor
    for k in range(6):
        for i in range(int(w / 1.2)):
            x, y = 0.6 + i * 1.2, 3.0 + k * 0.9 + 0.5
            z = (k + 1) * 0.3
            b.add(box((x - 0.25, y - 0.05, z), (x + 0.25, y + 0.05, z + 0.8)), solid=False)
    b.add(box((1.0, 0.0, 0.0), (w - 1.0, 2.0, 0.8)))  # stage
    b.add(icosphere((w / 2, 1.0, 1.1), 0.3))
    eye = [[0.5, 3.0, 2.2], [w - 0.5, d - 0.6, 3.0]]
    return b.scene("auditorium", "indoor", eye, [[0, 0, 0], [w, d, 2.0]])


# ---------------------------------------------------------------- outdoor recipes

def _street_scene(b: _Builder, name: str, length: float, width: float, *, cars: int, trees: int,
                  poles: int, height=(6.0, 15.0), benches: int = 0) -> Scene:
    yl, yr = -width / 2, width / 2
    _ground(b, -5, yl - 12, length + 5, yr + 12)
    _kerbs(b, -5, length + 5, yl, yr)
    x = -5.0
    while x < length + 5:
        lx = b.u(6, 14)
        _building(b, x, yl - 12.0, x + lx - 0.3, yl - 2.5, b.u(*height))
        x += lx
    x = -5.0
    while x < length + 5:
        lx = b.u(6, 14)
        _building(b, x, yr + 2.5, x + lx - 0.3, yr + 12.0, b.u(*height))
        x += lx
    for _ in range(cars):
        _car(b, b.u(2, length - 2), b.u(yl + 1.2, yr - 1.2), b.u(-8, 8) + 180.0 * (b.rng.uniform() < 0.5))
    for _ in range(trees):
        side = yl - 1.2 if b.rng.uniform() < 0.5 else yr + 1.2
        _tree(b, b.u(1, length - 1), side, b.u(3.5, 6))
    for k in range(poles):
        _pole(b, (k + 0.5) * length / max(poles, 1), yr + 0.5, 4.5)
    for _ in range(benches):
        side = yl - 1.5 if b.rng.uniform() < 0.5 else yr + 1.5
        _bench(b, b.u(1, length - 1), side, 0.0 if side > 0 else 180.0)
    eye = [[0.0, yl - 2.0, 1.2], [length, yr + 2.0, 1.8]]
    target = [[0.0, yl - 3.0, 0.0], [length, yr + 3.0, 1.5]]
    return b.scene(name, "outdoor", eye, target)


def street(b: _Builder) -> Scene:
    return _street_scene(b, "street", 30.0, b.u(7, 9), cars=4, trees=3, poles=3)


def alley(b: _Builder) -> Scene:
    return _street_scene(b, "alley", 20.0, b.u(3.5, 4.5), cars=1, trees=0, poles=2, height=(8, 20))


def boulevard(b: _Builder) -> Scene:
    return _street_scene(b, "boulevard", 40.0, b.u(10, 12), cars=5, trees=5, poles=4, benches=2)


def shopping_street(b: _Builder) -> Scene:
    return _street_scene(b, "shopping_street", 30.0, b.u(5, 6), cars=0, trees=2, poles=4, benches=4,
                         height=(4, 8))


def _open_scene(b: _Builder, name: str, size: float, *, cars=0, trees=0, benches=0, spheres=0,
                fountain=False, houses=0, poles=0) -> Scene:
    _ground(b, -size, -size, size, size)
    r = size * 0.8
    for _ in range(cars):
        _car(b, b.u(-r, r), b.u(-r, r), b.u(0, 360))
    for _ in range(trees):
        _tree(b, b.u(-r, r), b.u(-r, r), b.u(3, 6))
    for _ in range(benches):
        _bench(b, b.u(-r, r), b.u(-r, r), b.u(0, 360))
    for _ in range(spheres):
        rad = b.u(0.3, 0.8)
        b.add(icosphere((b.u(-r, r), b.u(-r, r), rad), rad))
    for _ in range(poles):
        _pole(b, b.u(-r, r), b.u(-r, r), 4.0)
    if fountain:
        b.add(cylinder((0.0, 0.0, 0.0), 2.0, 0.5))
        b.add(cylinder((0.0, 0.0, 0.5), 0.3, 1.2))
        b.add(icosphere((0.0, 0.0, 1.9), 0.4))
    for k in range(houses):
        a = 2 * np.pi * k / houses
        cx, cy = 0.9 * size * np.cos(a), 0.9 * size * np.sin(a)
        hx, hy, hz = b.u(4, 7), b.u(4, 7), b.u(3, 6)
        _building(b, cx - hx / 2, cy - hy / 2, cx + hx / 2, cy + hy / 2, hz, windows=False)
        b.add(cone((cx, cy, hz), max(hx, hy) * 0.72, 2.5, sections=4), solid=False,  # pyramid roof
              part="building")
    eye = [[-r, -r, 1.2], [r, r, 1.8]]
    target = [[-r, -r, 0.0], [r, r, 1.5]]
    return b.scene(name, "outdoor", eye, target)


def plaza(b: _Builder) -> Scene:
    return _open_scene(b, "plaza", 15.0, benches=4, fountain=True, poles=3, houses=6)


def parking_lot(b: _Builder) -> Scene:
    _open = _open_scene(b, "parking_lot", 14.0, cars=10, poles=4, houses=3)
    return _open


def park(b: _Builder) -> Scene:
    return _open_scene(b, "park", 15.0, trees=5, benches=4, spheres=2)


def courtyard(b: _Builder) -> Scene:
    return _open_scene(b, "courtyard", 10.0, trees=2, benches=2, fountain=True, houses=8)


def suburb(b: _Builder) -> Scene:
    return _open_scene(b, "suburb", 18.0, cars=3, trees=4, houses=7, poles=2)


def playground(b: _Builder) -> Scene:
    s = _open_scene(b, "playground", 12.0, spheres=5, benches=3, trees=2)
    return s


_INDOOR: dict[str, Callable[[_Builder], Scene]] = {
    f.__name__: f for f in (living_room, office, classroom, library, cafe, stairwell, museum, gym,
                            shop, auditorium)}
_OUTDOOR: dict[str, Callable[[_Builder], Scene]] = {
    f.__name__: f for f in (street, alley, boulevard, shopping_street, plaza, parking_lot, park,
                            courtyard, suburb, playground)}


def scene_names(kind: str | None = None) -> tuple[str, ...]:
    """Names of the procedural recipes: ``kind`` ``"indoor"``, ``"outdoor"`` or None (all)."""
    if kind is None:
        return tuple(_INDOOR) + tuple(_OUTDOOR)
    if kind == "indoor":
        return tuple(_INDOOR)
    if kind == "outdoor":
        return tuple(_OUTDOOR)
    raise ValueError(f"kind must be 'indoor', 'outdoor' or None; got {kind!r}")


def make_scene(name: str, *, seed: int = 0) -> Scene:
    """Build the procedural scene ``name`` from ``seed`` (same seed, same mesh, bit for bit).

    Parameters
    ----------
    name : str
        One of :func:`scene_names`.
    seed : int, keyword-only
        Non-negative seed of the recipe's random choices (sizes, placements).

    Returns
    -------
    Scene

    Examples
    --------
    >>> a, b = make_scene("park", seed=1), make_scene("park", seed=1)
    >>> bool(np.array_equal(a.vertices, b.vertices))
    True
    """
    recipes = {**_INDOOR, **_OUTDOOR}
    if name not in recipes:
        raise ValueError(f"unknown scene recipe {name!r}; valid: {', '.join(recipes)}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer; got {seed!r}")
    scene = recipes[name](_Builder(np.random.default_rng(int(seed))))
    scene.meta = {"recipe": name, "seed": int(seed)}
    return scene


def load_mesh_scene(path: str | Path, *, eye_box: Any = None, target_box: Any = None,
                    scale: float = 1.0) -> Scene:
    """Load a user mesh (OBJ, PLY, STL, GLB/GLTF, OFF) through trimesh as a :class:`Scene`.

    trimesh is imported only here (``pip install 'depthnormals[synth]'``). Multi-mesh files
    are flattened into one triangle soup. Default camera boxes: the mesh bounding box
    enlarged by max(its largest side, 4 m) on every side (eyes) and the bounding box itself
    (targets); world z is taken as up.

    Parameters
    ----------
    path : str or Path
        Mesh file.
    eye_box, target_box : array_like (2, 3), optional, keyword-only
        World boxes for camera centres and look-at points.
    scale : float, keyword-only
        Multiplies the vertices (e.g. 0.001 for a mesh in millimetres).

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ValueError
        If the file cannot be parsed or holds no triangles.
    ImportError
        If trimesh is not installed.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"mesh file {path} does not exist")
    try:
        import trimesh
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("loading user meshes needs trimesh: pip install 'depthnormals[synth]'") from exc
    try:
        loaded = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for corrupt files
        raise ValueError(f"{path}: cannot read mesh ({type(exc).__name__}: {exc})") from exc
    V = np.asarray(getattr(loaded, "vertices", np.zeros((0, 3))), dtype=np.float64) * float(scale)
    F = np.asarray(getattr(loaded, "faces", np.zeros((0, 3))), dtype=np.int64)
    if F.ndim != 2 or F.shape[0] == 0 or V.shape[0] == 0:
        raise ValueError(f"{path}: the mesh holds no triangles (empty or unreadable file)")
    if not np.all(np.isfinite(V)):
        raise ValueError(f"{path}: the mesh has non-finite vertices")
    lo, hi = V.min(0), V.max(0)
    m = max(float((hi - lo).max()), 4.0)  # room for viewing distances up to ~4 m
    eb = np.asarray(eye_box, float) if eye_box is not None else np.stack([lo - m, hi + m])
    tb = np.asarray(target_box, float) if target_box is not None else np.stack([lo, hi])
    for name, bx in (("eye_box", eb), ("target_box", tb)):
        if bx.shape != (2, 3):
            raise ValueError(f"{name} must be (2, 3) (lo, hi); got {bx.shape}")
    return Scene(path.stem, "mesh", V, F, np.zeros((0, 2, 3)), eb, tb,
                 {"source": path.name, "scale": float(scale)})
