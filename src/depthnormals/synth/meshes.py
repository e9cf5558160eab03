"""Triangle-mesh primitives for the procedural scenes (numpy, vectorised).

All functions return ``(vertices (N, 3) float64, faces (M, 3) int64)``. Curved surfaces are
finely tessellated by default (icosphere subdivision 5, 128 cylinder sections) so that the
face-normal ground truth stays within ~0.5 deg of the smooth surface.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

__all__ = ["box", "cone", "cylinder", "icosphere", "merge", "quad", "transform"]

Mesh = tuple[np.ndarray, np.ndarray]


def box(lo, hi) -> Mesh:
    """Axis-aligned box between corners ``lo`` and ``hi`` (12 triangles).

    Examples
    --------
    >>> V, F = box((0, 0, 0), (1, 2, 3))
    >>> V.shape, F.shape
    ((8, 3), (12, 3))
    """
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    if lo.shape != (3,) or hi.shape != (3,) or np.any(hi <= lo):
        raise ValueError(f"box needs lo < hi (3 numbers each); got {lo} and {hi}")
    idx = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)])
    V = np.where(idx == 1, hi, lo)
    F = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6],   # z faces
                  [0, 1, 4], [1, 5, 4], [2, 6, 3], [3, 6, 7],   # y faces
                  [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]])  # x faces
    return V, F


def quad(corners) -> Mesh:
    """A planar quadrilateral from 4 corners in order (2 triangles)."""
    V = np.asarray(corners, dtype=np.float64)
    if V.shape != (4, 3):
        raise ValueError(f"quad needs 4 corners (4, 3); got {V.shape}")
    return V, np.array([[0, 1, 2], [0, 2, 3]])


@lru_cache(maxsize=8)
def _unit_icosphere(level: int) -> Mesh:
    t = (1.0 + 5.0 ** 0.5) / 2.0
    V = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                  [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]],
                 dtype=np.float64)
    F = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9],
                  [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2],
                  [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
                  [8, 6, 7], [9, 8, 1]], dtype=np.int64)
    V /= np.linalg.norm(V, axis=1, keepdims=True)
    for _ in range(level):
        edges = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
        edges.sort(axis=1)
        uniq, inv = np.unique(edges, axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        mid = V[uniq[:, 0]] + V[uniq[:, 1]]
        mid /= np.linalg.norm(mid, axis=1, keepdims=True)
        m = inv.reshape(3, -1).T + V.shape[0]  # midpoints of edges 01, 12, 20
        a, b, c = F[:, 0], F[:, 1], F[:, 2]
        F = np.concatenate([np.stack([a, m[:, 0], m[:, 2]], 1), np.stack([b, m[:, 1], m[:, 0]], 1),
                            np.stack([c, m[:, 2], m[:, 1]], 1), m])
        V = np.concatenate([V, mid])
    V.setflags(write=False)
    F.setflags(write=False)
    return V, F


def icosphere(center, radius: float, *, level: int = 5) -> Mesh:
    """Sphere as a subdivided icosahedron (``20 * 4**level`` faces; level 5: 20480).

    Examples
    --------
    >>> V, F = icosphere((0, 0, 0), 1.0, level=5)
    >>> F.shape[0], bool(np.allclose(np.linalg.norm(V, axis=1), 1.0))
    (20480, True)
    """
    if not (isinstance(level, int) and 0 <= level <= 7):
        raise ValueError(f"level must be an integer 0..7; got {level!r}")
    V, F = _unit_icosphere(level)
    return V * float(radius) + np.asarray(center, dtype=np.float64), F.copy()


def cylinder(base, radius: float, height: float, *, sections: int = 128, axis: str = "z",
             caps: bool = True) -> Mesh:
    """Closed circular cylinder with ``sections`` sides, from ``base`` along +``axis``."""
    if sections < 3:
        raise ValueError(f"sections must be >= 3; got {sections}")
    a = np.linspace(0.0, 2.0 * np.pi, sections, endpoint=False)
    ring = np.stack([radius * np.cos(a), radius * np.sin(a), np.zeros(sections)], 1)
    top = ring + np.array([0.0, 0.0, height])
    V = np.concatenate([ring, top, [[0.0, 0.0, 0.0], [0.0, 0.0, height]]])
    i = np.arange(sections)
    j = (i + 1) % sections
    side = np.concatenate([np.stack([i, j, j + sections], 1), np.stack([i, j + sections, i + sections], 1)])
    parts = [side]
    if caps:
        parts += [np.stack([np.full(sections, 2 * sections), j, i], 1),
                  np.stack([np.full(sections, 2 * sections + 1), i + sections, j + sections], 1)]
    return _orient(V, axis) + np.asarray(base, dtype=np.float64), np.concatenate(parts)


def cone(base, radius: float, height: float, *, sections: int = 128, axis: str = "z") -> Mesh:
    """Closed circular cone (apex at ``base + height * axis``)."""
    a = np.linspace(0.0, 2.0 * np.pi, sections, endpoint=False)
    ring = np.stack([radius * np.cos(a), radius * np.sin(a), np.zeros(sections)], 1)
    V = np.concatenate([ring, [[0.0, 0.0, height], [0.0, 0.0, 0.0]]])
    i = np.arange(sections)
    j = (i + 1) % sections
    F = np.concatenate([np.stack([i, j, np.full(sections, sections)], 1),
                        np.stack([np.full(sections, sections + 1), j, i], 1)])
    return _orient(V, axis) + np.asarray(base, dtype=np.float64), F


def _orient(V: np.ndarray, axis: str) -> np.ndarray:
    if axis == "z":
        return V
    if axis == "x":
        return V[:, [2, 0, 1]]
    if axis == "y":
        return V[:, [1, 2, 0]]
    raise ValueError(f"axis must be 'x', 'y' or 'z'; got {axis!r}")


def transform(mesh: Mesh, *, rotate_z_deg: float = 0.0, translate=(0.0, 0.0, 0.0)) -> Mesh:
    """Rotate about the world z axis (through the origin), then translate."""
    V, F = mesh
    a = np.radians(rotate_z_deg)
    R = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    return V @ R.T + np.asarray(translate, dtype=np.float64), F


def merge(meshes) -> Mesh:
    """Concatenate meshes into one."""
    meshes = list(meshes)
    if not meshes:
        raise ValueError("nothing to merge: the scene has no parts")
    Vs, Fs, off = [], [], 0
    for V, F in meshes:
        Vs.append(V)
        Fs.append(F + off)
        off += V.shape[0]
    return np.concatenate(Vs), np.concatenate(Fs)
