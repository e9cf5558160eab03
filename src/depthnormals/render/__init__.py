"""Exact z-buffer rendering of triangle meshes into planar depth and face-normal ground truth.

Conventions: OpenCV camera frame (x right, y down, z forward); the pixel at row ``v``,
column ``u`` samples the ray through the integer position ``(u, v)``; depth is planar z.
Poses are camera-to-world 4x4 matrices ``T`` with ``X_world = R X_cam + t``.

Examples
--------
>>> import numpy as np
>>> from depthnormals.render import render_mesh
>>> V = np.array([[-5, -5, 2.0], [5, -5, 2.0], [5, 5, 2.0], [-5, 5, 2.0]])
>>> F = np.array([[0, 1, 2], [0, 2, 3]])
>>> r = render_mesh(V, F, width=64, height=48)
>>> float(r.depth[10, 20]), r.normals[10, 20].tolist()
(2.0, [0.0, 0.0, -1.0])
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validate import check_positive
from ..camera import Intrinsics, as_intrinsics
from . import _raster

__all__ = ["KINECT_V2", "KINECT_V2_SIZE", "RenderResult", "look_at", "render_mesh", "render_subsamples"]

#: Kinect v2 depth camera (NOTES.md section 6): fx = fy = 365.5 px, principal point at the
#: image centre of the 512 x 424 image (0-based).
KINECT_V2 = Intrinsics(365.5, 365.5, 255.5, 211.5)
#: (height, width) of the Kinect v2 depth image.
KINECT_V2_SIZE = (424, 512)


@dataclass(frozen=True)
class RenderResult:
    """The output of :func:`render_mesh`.

    Attributes
    ----------
    depth : ndarray (H, W), float64
        Planar depth in the mesh's unit; 0 where no surface is seen.
    face : ndarray (H, W), int32
        Index of the visible face, -1 where none.
    normals : ndarray (H, W, 3), float64
        Unit face normal in the camera frame, facing the camera (``n . X < 0``); NaN
        where no surface is seen.
    K : Intrinsics
        The intrinsics used.
    """

    depth: np.ndarray
    face: np.ndarray
    normals: np.ndarray
    K: Intrinsics

    @property
    def valid(self) -> np.ndarray:
        """Boolean (H, W): True where a surface is seen."""
        return self.face >= 0


def look_at(eye: Any, target: Any, *, up: Any = (0.0, 0.0, 1.0)) -> np.ndarray:
    """Camera-to-world pose of an OpenCV camera at ``eye`` looking at ``target``.

    Parameters
    ----------
    eye, target : array_like, shape (3,)
        Camera centre and a point on the optical axis, world coordinates.
    up : array_like, shape (3,), keyword-only
        World direction that appears up in the image (image y points opposite to it).

    Returns
    -------
    pose : ndarray (4, 4), float64
        ``[[R, t], [0, 1]]`` with the camera axes (x right, y down, z forward) as the
        columns of ``R`` and ``t = eye``.

    Examples
    --------
    >>> T = look_at((0, 0, 0), (0, 1, 0))
    >>> T[:3, 2].tolist(), T[:3, 1].tolist()
    ([0.0, 1.0, 0.0], [0.0, 0.0, -1.0])
    """
    eye = np.asarray(eye, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    up = np.asarray(up, dtype=np.float64)
    if eye.shape != (3,) or target.shape != (3,) or up.shape != (3,):
        raise ValueError("eye, target and up must each be 3 numbers")
    z = target - eye
    nz = np.linalg.norm(z)
    if not nz > 0:
        raise ValueError("target must differ from eye")
    z /= nz
    x = np.cross(z, up)
    nx = np.linalg.norm(x)
    if not nx > 1e-9:
        raise ValueError("the viewing direction is parallel to up; pass another up vector")
    x /= nx
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, eye
    return T


def _check_pose(pose: Any) -> np.ndarray:
    T = np.asarray(pose, dtype=np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"pose must be a finite 4x4 camera-to-world matrix; got shape {T.shape}")
    R = T[:3, :3]
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise ValueError("pose rotation must be a proper rotation (orthonormal, det +1)")
    return T


def check_mesh(vertices: Any, faces: Any) -> tuple[np.ndarray, np.ndarray]:
    """Validate a triangle mesh; returns float64 (N, 3) vertices and int64 (M, 3) faces."""
    V = np.asarray(vertices)
    F = np.asarray(faces)
    if V.dtype.kind not in "iuf" or V.ndim != 2 or V.shape[1] != 3:
        raise ValueError(f"vertices must be a real (N, 3) array; got {V.dtype} {V.shape}")
    if F.dtype.kind not in "iu" or F.ndim != 2 or F.shape[1] != 3:
        raise ValueError(f"faces must be an integer (M, 3) array of vertex indices; got {F.dtype} {F.shape}")
    if F.shape[0] == 0 or V.shape[0] == 0:
        raise ValueError("the mesh is empty (no faces): nothing to render")
    if F.min() < 0 or F.max() >= V.shape[0]:
        raise ValueError(f"faces index vertices 0..{V.shape[0] - 1}; got {F.min()}..{F.max()}")
    V = np.ascontiguousarray(V, dtype=np.float64)
    if not np.all(np.isfinite(V)):
        raise ValueError("vertices must be finite")
    return V, np.ascontiguousarray(F, dtype=np.int64)


def render_mesh(vertices: Any, faces: Any, K: Any = KINECT_V2, *, pose: Any = None,
                width: int = KINECT_V2_SIZE[1], height: int = KINECT_V2_SIZE[0],
                near: float = 0.05, far: float = np.inf) -> RenderResult:
    """Render planar depth, face index and face normals of a triangle mesh (exact z-buffer).

    Every pixel's ray through its integer position is intersected with the plane of the
    nearest covering triangle, so the depth is exact (to float64 rounding) and the normal
    is that triangle's normal. Triangles are clipped at the near plane, so cameras may sit
    inside rooms. Compiled with numba; tiles run in parallel, with a deterministic result.

    Parameters
    ----------
    vertices : array_like, shape (N, 3)
        Vertex positions in world units (metres by convention).
    faces : array_like, shape (M, 3), integer
        Triangles as vertex indices. Winding does not matter.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy), default KINECT_V2
        Intrinsics in pixels, 0-based pixel centres.
    pose : array_like, shape (4, 4), optional, keyword-only
        Camera-to-world transform (OpenCV camera axes). Default: identity (the vertices
        are already in the camera frame).
    width, height : int, keyword-only
        Image size in pixels; default 512 x 424 (Kinect v2).
    near : float, keyword-only
        Near clipping distance (> 0), same unit as the vertices.
    far : float, keyword-only
        Surfaces farther than this are not drawn (the pixel stays empty).

    Returns
    -------
    RenderResult
        ``depth`` (H, W) float64 (0 = nothing), ``face`` (H, W) int32 (-1 = nothing),
        ``normals`` (H, W, 3) float64 camera-frame unit normals facing the camera.

    Examples
    --------
    >>> import numpy as np
    >>> V = np.array([[-1, -1, 3.0], [1, -1, 3.0], [0, 1, 3.0]])
    >>> r = render_mesh(V, [[0, 1, 2]], (100.0, 100.0, 15.5, 15.5), width=32, height=32)
    >>> float(r.depth[15, 15]), int(r.face[15, 15]), int(r.face[31, 0])
    (3.0, 0, -1)
    """
    cam, Vc, F, width, height, near, far = _prepare(vertices, faces, K, pose, width, height, near, far)
    depth, face, face_normal = _run(Vc, F, cam, width, height, near, far, np.zeros((1, 2)),
                                    np.ones((height, width), dtype=np.bool_), 0.0)
    depth, face = depth[..., 0], face[..., 0]
    normals = _raster.gather_normals(face, face_normal)
    return RenderResult(depth=depth, face=face, normals=normals, K=cam)


def _prepare(vertices, faces, K, pose, width, height, near, far):
    V, F = check_mesh(vertices, faces)
    cam = as_intrinsics(K)
    for name, value in (("width", width), ("height", height)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"{name} must be a positive integer; got {value!r}")
    near = check_positive(near, "near")
    if not (isinstance(far, (int, float)) and far > near):
        raise ValueError(f"far must be a number > near ({near}); got {far!r}")
    if pose is not None:
        T = _check_pose(pose)
        Vc = np.ascontiguousarray((V - T[:3, 3]) @ T[:3, :3])
    else:
        Vc = V
    return cam, Vc, F, int(width), int(height), near, float(far)


def _run(Vc, F, cam, width, height, near, far, offsets, mask, margin):
    normal, offset, edges, nvert, fbox = _raster.setup_faces(
        Vc, F, cam.fx, cam.fy, cam.cx, cam.cy, width, height, near)
    active, bbox = _raster.int_boxes(nvert, fbox, margin, width, height)
    tiles_u = (width + _raster.TILE - 1) // _raster.TILE
    tiles_v = (height + _raster.TILE - 1) // _raster.TILE
    start, items = _raster.bin_faces(active, bbox, tiles_u, tiles_v)
    depth, face = _raster.raster_tiles((normal, offset, edges, active, bbox),
                                       (start, items, tiles_u, tiles_v),
                                       (cam.fx, cam.fy, cam.cx, cam.cy),
                                       (width, height, near, far), offsets, mask)
    return depth, face, normal


def render_subsamples(vertices: Any, faces: Any, K: Any = KINECT_V2, *, pose: Any = None,
                      width: int = KINECT_V2_SIZE[1], height: int = KINECT_V2_SIZE[0],
                      factor: int = 3, mask: Any = None, near: float = 0.05,
                      far: float = np.inf) -> np.ndarray:
    """Planar depth at ``factor x factor`` sub-pixel positions of each (masked) pixel.

    The sub-samples of pixel (u, v) sit at ``(u + (i - (factor - 1) / 2) / factor,
    v + (j - (factor - 1) / 2) / factor)``, i.e. on the regular grid of a ``factor`` times
    finer image; the middle one is the pixel itself. Used for flying pixels
    (:func:`depthnormals.synth.noise.mix_supersampled`): rendering only the pixels near
    discontinuities (``mask``) is much cheaper than a full high-resolution image.

    Parameters
    ----------
    vertices, faces, K, pose, width, height, near, far
        As in :func:`render_mesh`.
    factor : int, keyword-only
        Odd number of sub-samples per axis (3 or 5).
    mask : array_like (H, W) bool, optional, keyword-only
        Pixels to sample; default all.

    Returns
    -------
    depth : ndarray (H, W, factor**2) float64
        Row-major sub-samples (index ``j * factor + i``); 0 where no surface, NaN for
        pixels outside ``mask``.

    Examples
    --------
    >>> import numpy as np
    >>> V = np.array([[-1, -1, 2.0], [1, -1, 2.0], [1, 1, 2.0], [-1, 1, 2.0]])
    >>> d = render_subsamples(V, [[0, 1, 2], [0, 2, 3]], (10.0, 10.0, 3.5, 3.5), width=8, height=8)
    >>> d.shape, float(d[3, 3, 4])
    ((8, 8, 9), 2.0)
    """
    if isinstance(factor, bool) or not isinstance(factor, (int, np.integer)) or factor < 1 or factor % 2 == 0:
        raise ValueError(f"factor must be an odd positive integer; got {factor!r}")
    cam, Vc, F, width, height, near, far = _prepare(vertices, faces, K, pose, width, height, near, far)
    if mask is None:
        m = np.ones((height, width), dtype=np.bool_)
    else:
        m = np.ascontiguousarray(mask, dtype=np.bool_)
        if m.shape != (height, width):
            raise ValueError(f"mask must have shape {(height, width)}; got {m.shape}")
    g = (np.arange(factor) - (factor - 1) / 2) / factor
    offsets = np.stack(np.meshgrid(g, g, indexing="xy"), axis=-1).reshape(-1, 2)
    depth, _, _ = _run(Vc, F, cam, width, height, near, far, np.ascontiguousarray(offsets), m,
                       float(g[-1]))
    return depth
