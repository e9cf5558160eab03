"""Compiled finishing kernels: normalise a normal and orient it toward the camera."""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .._parallel import run_rows

__all__ = ["finish", "oriented_unit", "store_nan", "store_normal"]


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


@nb.njit(cache=True, error_model="numpy", inline="always")
def store_nan(out, v, u):
    """No normal at pixel (v, u): NaN in all three components."""
    out[v, u, 0] = np.nan
    out[v, u, 1] = np.nan
    out[v, u, 2] = np.nan


@nb.njit(cache=True, error_model="numpy", nogil=True)
def _finish_rows(v0, v1, normals, z, fx, fy, cx, cy):
    w = z.shape[1]
    for v in range(v0, v1):
        for u in range(w):
            zz = z[v, u]
            if not (zz == zz):
                store_nan(normals, v, u)
                continue
            store_normal(normals, v, u, normals[v, u, 0], normals[v, u, 1], normals[v, u, 2],
                         (u - cx) * zz / fx, (v - cy) * zz / fy, zz)


def finish(normals: np.ndarray, z: np.ndarray, fx: float, fy: float, cx: float, cy: float) -> None:
    """Renormalise and orient a float normal map in place (NaN where z is invalid)."""
    run_rows(_finish_rows, z.shape[0], normals, z, fx, fy, cx, cy)
