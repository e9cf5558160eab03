"""Analytic scenes with exact depth and exact normals, ray-cast in closed form.

Primitives: infinite planes, spheres and oriented boxes. Each pixel's ray passes through
its integer position ``((u - cx) / fx, (v - cy) / fy, 1)``, so the ray parameter is the
planar depth. Misses are depth 0 (invalid) with NaN normals. Every primitive face gets an
id, so tests can select pixels whose neighbourhood lies on one plane
(:func:`planar_interior`).

Examples
--------
>>> from depthnormals.analytic import box_on_floor
>>> r = box_on_floor().render()
>>> r.depth.shape, r.normals.dtype.name
((480, 640), 'float64')
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .camera import Intrinsics, as_intrinsics

__all__ = [
    "Box",
    "Plane",
    "Render",
    "Scene",
    "Sphere",
    "box_on_floor",
    "demo_room",
    "make_scene",
    "planar_interior",
    "scene_names",
    "sphere_before_wall",
    "stairs",
    "tilted_plane",
]

DEFAULT_K = Intrinsics(525.0, 525.0, 319.5, 239.5)
DEFAULT_SHAPE = (480, 640)


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def _rot(rx: float = 0.0, ry: float = 0.0, rz: float = 0.0) -> np.ndarray:
    """Rotation matrix from angles in degrees about x, then y, then z."""
    a, b, c = np.radians([rx, ry, rz])
    Rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    Ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    Rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


@dataclass(frozen=True)
class Plane:
    """The infinite plane ``normal . p = offset``."""

    normal: tuple[float, float, float]
    offset: float
    planar = True
    n_faces = 1

    def intersect(self, rays: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = _unit(self.normal)
        denom = rays @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = self.offset / denom
        t = np.where(np.isfinite(t) & (t > 0), t, np.inf)
        return t, np.broadcast_to(n, rays.shape), np.zeros(t.shape, np.int64)


@dataclass(frozen=True)
class Sphere:
    """A sphere (a curved surface: no pixel of it counts as planar)."""

    center: tuple[float, float, float]
    radius: float
    planar = False
    n_faces = 1

    def intersect(self, rays: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        c = np.asarray(self.center, dtype=np.float64)
        a = np.einsum("...i,...i->...", rays, rays)
        b = -2.0 * (rays @ c)
        cc = c @ c - self.radius ** 2
        disc = b * b - 4 * a * cc
        with np.errstate(invalid="ignore"):
            t = (-b - np.sqrt(disc)) / (2 * a)
        t = np.where((disc >= 0) & (t > 0), t, np.inf)
        p = rays * np.where(np.isfinite(t), t, 0.0)[..., None]
        return t, (p - c) / self.radius, np.zeros(t.shape, np.int64)


@dataclass(frozen=True)
class Box:
    """An oriented box: centre, half sizes along its axes, rotation (degrees, x-y-z)."""

    center: tuple[float, float, float]
    half: tuple[float, float, float]
    angles: tuple[float, float, float] = (0.0, 0.0, 0.0)
    planar = True
    n_faces = 6

    def intersect(self, rays: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        R = _rot(*self.angles)
        c = np.asarray(self.center, dtype=np.float64)
        h = np.asarray(self.half, dtype=np.float64)
        d = rays @ R  # ray directions in the box frame
        o = -(c @ R)  # camera origin in the box frame
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (-h - o) / d
            t2 = (h - o) / d
        tmin = np.minimum(t1, t2)
        tmax = np.maximum(t1, t2)
        tmin = np.where(np.isnan(tmin), -np.inf, tmin)
        tmax = np.where(np.isnan(tmax), np.inf, tmax)
        axis = np.argmax(tmin, axis=-1)
        t_near = np.max(tmin, axis=-1)
        t_far = np.min(tmax, axis=-1)
        hit = (t_near <= t_far) & (t_near > 0)
        t = np.where(hit, t_near, np.inf)
        local = np.zeros(rays.shape)
        sign = -np.sign(np.take_along_axis(d, axis[..., None], -1))[..., 0]
        np.put_along_axis(local, axis[..., None], sign[..., None], -1)
        face = axis * 2 + (sign > 0)
        return t, local @ R.T, face.astype(np.int64)


@dataclass
class Render:
    """Result of :meth:`Scene.render`: exact depth (0 = miss), normals (NaN = miss), face ids."""

    depth: np.ndarray
    normals: np.ndarray
    face: np.ndarray
    planar: np.ndarray
    K: Intrinsics


@dataclass
class Scene:
    """A list of primitives seen by a pinhole camera at the origin (OpenCV frame)."""

    primitives: list = field(default_factory=list)
    name: str = "scene"

    def render(self, K=DEFAULT_K, shape: tuple[int, int] = DEFAULT_SHAPE) -> Render:
        """Ray-cast the scene: exact planar depth and camera-facing unit normals (float64)."""
        cam = as_intrinsics(K)
        h, w = shape
        u = np.arange(w, dtype=np.float64)[None, :]
        v = np.arange(h, dtype=np.float64)[:, None]
        rays = np.stack(np.broadcast_arrays((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy,
                                            np.ones((h, w))), axis=-1)
        depth = np.full((h, w), np.inf)
        normals = np.full((h, w, 3), np.nan)
        face = np.full((h, w), -1, np.int64)
        planar = np.zeros((h, w), bool)
        base = 0
        for prim in self.primitives:
            t, n, f = prim.intersect(rays)
            closer = t < depth
            depth[closer] = t[closer]
            normals[closer] = np.broadcast_to(n, rays.shape)[closer]
            face[closer] = base + f[closer]
            planar[closer] = prim.planar
            base += prim.n_faces
        miss = ~np.isfinite(depth)
        depth[miss] = 0.0
        pts = rays * depth[..., None]
        flip = np.einsum("...i,...i->...", normals, pts) > 0
        normals[flip] *= -1
        normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
        planar[miss] = False
        return Render(depth, normals, face, planar, cam)


def planar_interior(render: Render, radius: int = 1) -> np.ndarray:
    """Pixels whose (2 radius + 1)^2 neighbourhood lies on one plane face (bool (H, W))."""
    f = np.where(render.planar, render.face, -1)
    h, w = f.shape
    ok = f >= 0
    pad = np.pad(f, radius, constant_values=-2)
    for dv in range(-radius, radius + 1):
        for du in range(-radius, radius + 1):
            ok &= pad[radius + dv:radius + dv + h, radius + du:radius + du + w] == f
    return ok


def tilted_plane(normal=(0.3, -0.4, -1.0), distance: float = 2.0) -> Scene:
    """One infinite tilted plane at ``distance`` from the camera along its normal."""
    n = _unit(normal)
    return Scene([Plane(tuple(n), -distance if n[2] < 0 else distance)], "tilted-plane")


def box_on_floor() -> Scene:
    """A rotated box standing on a floor in front of a wall: creases and occlusion edges."""
    return Scene([
        Plane((0.0, -1.0, 0.0), -1.0),    # floor y = 1 (y points down)
        Plane((0.0, 0.0, -1.0), -6.0),    # back wall z = 6
        Box((0.2, 0.55, 3.5), (0.6, 0.45, 0.5), (0.0, 35.0, 0.0)),
    ], "box-on-floor")


def stairs(steps: int = 5) -> Scene:
    """A staircase rising away from the camera, with a side wall."""
    prims: list = [Plane((0.0, -1.0, 0.0), -1.2), Plane((-1.0, 0.0, -0.15), -2.5),
                   Plane((0.0, 0.0, -1.0), -7.0)]
    for i in range(steps):
        height = 0.2 * (i + 1)
        prims.append(Box((-0.3, 1.2 - height / 2, 2.6 + 0.35 * i), (1.2, height / 2, 0.175),
                         (0.0, 10.0, 0.0)))
    return Scene(prims, "stairs")


def sphere_before_wall() -> Scene:
    """A sphere in front of a slightly tilted wall, with a floor."""
    return Scene([
        Plane(tuple(_unit((0.1, 0.05, -1.0))), -5.0),
        Plane((0.0, -1.0, 0.0), -1.0),
        Sphere((0.3, 0.1, 3.0), 0.8),
    ], "sphere-before-wall")


def demo_room() -> Scene:
    """Floor, two walls, a rotated box and a sphere: the scene of ``depthnormals demo``."""
    return Scene([
        Plane((0.0, -1.0, 0.0), -1.0),
        Plane((0.0, 0.0, -1.0), -6.0),
        Plane(tuple(_unit((1.0, 0.0, -0.35))), 0.25),
        Box((0.45, 0.6, 3.6), (0.55, 0.4, 0.45), (0.0, 30.0, 0.0)),
        Box((-0.55, 0.85, 2.8), (0.25, 0.15, 0.25), (0.0, -20.0, 0.0)),
        Sphere((-0.35, 0.1, 4.2), 0.55),
    ], "demo-room")


_SCENES = {
    "tilted-plane": tilted_plane,
    "box-on-floor": box_on_floor,
    "stairs": stairs,
    "sphere-before-wall": sphere_before_wall,
    "demo-room": demo_room,
}


def scene_names() -> tuple[str, ...]:
    """Names accepted by :func:`make_scene`."""
    return tuple(_SCENES)


def make_scene(name: str) -> Scene:
    """A built-in analytic scene by name (see :func:`scene_names`)."""
    if name not in _SCENES:
        raise ValueError(f"unknown scene {name!r}; valid scenes: {', '.join(_SCENES)}")
    return _SCENES[name]()
