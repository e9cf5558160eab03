"""Shared pieces of every estimator: input preparation and compiled finishing kernels.

Inside the kernels invalid depth is NaN (see :func:`prepare`), so ``z == z`` tests validity.
Arithmetic is float64 in registers (except 3F2N's FD row pass, which runs in the dtype of the
depth); outputs are float32.
"""

from __future__ import annotations

import math
from typing import Any

import numba as nb
import numpy as np

from .._parallel import run_rows
from .._validate import check_depth
from ..camera import Intrinsics, as_intrinsics

__all__ = ["FLOAT32_RANGE", "NEIGHBOURS8", "finish", "new_output", "nz_candidates", "oriented_unit",
           "prepare", "row_arrays", "row_dtype", "store_normal"]


#: Offsets (dv, du) of the 8-neighbourhood, row by row.
NEIGHBOURS8 = np.array([[-1, -1], [-1, 0], [-1, 1], [0, -1], [0, 1], [1, -1], [1, 0], [1, 1]],
                       dtype=np.int64)


def prepare(depth: Any, K: Any, depth_scale: float | None) -> tuple[np.ndarray, Intrinsics]:
    """Validate inputs; return depth as a C-contiguous float array with NaN at invalid pixels."""
    z = check_depth(depth, depth_scale=depth_scale)
    cam = as_intrinsics(K)
    bad = ~(np.isfinite(z) & (z > 0))
    if bad.any():
        z = np.where(bad, z.dtype.type(np.nan), z)
    return z, cam


def _depth_range(z: np.ndarray) -> tuple[float, float]:
    """(min, max) of the valid depths (NaN skipped by fmin/fmax; NaN, NaN when none)."""
    return float(np.fmin.reduce(z, axis=None)), float(np.fmax.reduce(z, axis=None))


#: Depth range (any unit) and intrinsics magnitude in which the float32 row passes keep full
#: float32 precision: squares of normal components and curvature terms stay normal numbers.
FLOAT32_RANGE = (2.0 ** -24, 2.0 ** 24)


def row_dtype(z: np.ndarray, fx: float = 1.0, fy: float = 1.0, cx: float = 0.0,
              cy: float = 0.0) -> np.ndarray:
    """``z`` as the vectorised row passes should see it: float32 stays float32 (8 lanes per
    vector) when its finite depths and the intrinsics lie in :data:`FLOAT32_RANGE`;
    anything else is promoted to float64 (a copy).
    """
    if z.dtype == np.float64:
        return z
    lo, hi = _depth_range(z)
    big = FLOAT32_RANGE[1]
    fits = (FLOAT32_RANGE[0] <= lo and hi <= big and FLOAT32_RANGE[0] <= min(abs(fx), abs(fy))
            and max(abs(fx), abs(fy), abs(cx) + z.shape[1], abs(cy) + z.shape[0]) <= big)
    if not (lo <= hi):  # no valid pixel at all (NaN)
        fits = True
    return z if fits else z.astype(np.float64)


def row_arrays(z: np.ndarray, fx: float, fy: float, cx: float,
               cy: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Typed inputs of the row kernels, in the dtype of ``z`` (as :func:`row_dtype` gives it).

    ``c = (0.5, 1, inf, -inf, 0, fx, fy, the dtype's largest float)``, ``acol[u] = u - cx``,
    ``bcol[v] = v - cy``. Casting huge or tiny intrinsics to float32 only happens where the
    row passes are not used, so overflow and underflow are silent here.
    """
    h, w = z.shape
    with np.errstate(over="ignore", under="ignore"):
        c = np.array([0.5, 1.0, np.inf, -np.inf, 0.0, fx, fy, np.finfo(z.dtype).max],
                     dtype=z.dtype)
        acol = (np.arange(w) - cx).astype(z.dtype)
        bcol = (np.arange(h) - cy).astype(z.dtype)
    return c, acol, bcol


def new_output(shape: tuple[int, int]) -> np.ndarray:
    """An (H, W, 3) float32 array filled with NaN."""
    return np.full((shape[0], shape[1], 3), np.nan, dtype=np.float32)


@nb.njit(cache=True, error_model="numpy", inline="always")
def oriented_unit(nx, ny, nz, px, py, pz):
    """(nx, ny, nz) normalised and oriented toward the camera (dot with the point < 0).

    NaN (all three) when the vector is not finite or has zero length.
    """
    norm = math.sqrt(nx * nx + ny * ny + nz * nz)
    if not (norm > 0.0) or not math.isfinite(norm):
        return np.nan, np.nan, np.nan
    inv = 1.0 / norm
    if nx * px + ny * py + nz * pz > 0.0:
        inv = -inv
    return nx * inv, ny * inv, nz * inv


@nb.njit(cache=True, error_model="numpy", inline="always")
def store_normal(out, v, u, nx, ny, nz, px, py, pz):
    """Normalise (nx, ny, nz), orient it toward the camera (dot with the point < 0), store it.

    Writes NaN when the vector is not finite or has zero length.
    """
    x, y, t = oriented_unit(nx, ny, nz, px, py, pz)
    out[v, u, 0] = x
    out[v, u, 1] = y
    out[v, u, 2] = t


@nb.njit(cache=True, error_model="numpy", nogil=True)
def _finish_rows(v0, v1, normals, z, fx, fy, cx, cy):
    w = z.shape[1]
    for v in range(v0, v1):
        for u in range(w):
            zz = z[v, u]
            if not (zz == zz):
                normals[v, u, 0] = np.nan
                normals[v, u, 1] = np.nan
                normals[v, u, 2] = np.nan
                continue
            store_normal(normals, v, u, normals[v, u, 0], normals[v, u, 1], normals[v, u, 2],
                         (u - cx) * zz / fx, (v - cy) * zz / fy, zz)


def finish(normals: np.ndarray, z: np.ndarray, fx: float, fy: float, cx: float, cy: float) -> None:
    """Renormalise and orient a float normal map in place (NaN where z is invalid)."""
    run_rows(_finish_rows, z.shape[0], normals, z, fx, fy, cx, cy)


@nb.njit(cache=True, error_model="numpy")
def nz_candidates(z, v, u, nx, ny, fx, fy, cx, cy, nb_off, cand):
    """3F2N's candidates ``nz_i = -(nx dx_i + ny dy_i) / dz_i`` of the neighbours of (v, u).

    Neighbours outside the image, with invalid depth (NaN) or with ``dz = 0`` give none.
    Fills ``cand[:n]`` in the order of ``nb_off`` and returns ``n``.
    """
    h, w = z.shape
    zq = z[v, u]
    xq = (u - cx) * zq / fx
    yq = (v - cy) * zq / fy
    n = 0
    for k in range(nb_off.shape[0]):
        r = v + nb_off[k, 0]
        c = u + nb_off[k, 1]
        if r < 0 or r >= h or c < 0 or c >= w:
            continue
        zn = z[r, c]
        if not (zn == zn):
            continue
        dz = zn - zq
        if dz == 0.0:
            continue
        dx = (c - cx) * zn / fx - xq
        dy = (r - cy) * zn / fy - yq
        cand[n] = -(nx * dx + ny * dy) / dz
        n += 1
    return n
