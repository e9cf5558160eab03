"""Compiled finishing kernels: normalise a normal and orient it toward the camera."""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .._parallel import run_rows

__all__ = ["TIE_COS", "TIE_COS2", "faces_away", "finish", "oriented_unit", "store_nan",
           "store_normal"]

#: A normal within this cosine of perpendicular to its viewing ray (``|n . X| <= TIE_COS |n|
#: |X|``, 0.00006 deg) has no side the depth can tell: the sign of ``n . X`` there is rounding
#: (3F2N's median of two candidates symmetric about the pixel gives exactly such a normal on
#: quantised depth: 12,753 pixels over the 11 real frames of ``../shared/data/real-sensors``,
#: at ``|cos|`` below 1e-9 in float64 and below 1e-7 in float32), and two implementations of
#: one estimator (numba, torch; float32, float64) decided it differently, 180 deg apart. Such
#: a normal takes ``n_z < 0`` (facing the camera along the optical axis; where ``n_z = 0``,
#: ``n_y < 0``, then ``n_x < 0``): :func:`faces_away`, and the torch backend alike. 1e-6 is
#: ten times float32's rounding of those ties; the normals beyond it are real surfaces seen
#: nearly edge-on (about 150 a decade of ``|cos|`` on those frames), whose side the sign tells.
TIE_COS = 1e-6
TIE_COS2 = TIE_COS * TIE_COS


@nb.njit(cache=True, error_model="numpy", inline="always")
def faces_away(dot, n2, p2, nx, ny, nz, tie2=TIE_COS2):
    """Whether the normal ``(nx, ny, nz)`` (squared length ``n2``) must be negated to face the
    camera, ``dot = n . X`` for the pixel's point or ray ``X`` (squared length ``p2``):
    ``dot > 0``, but within :data:`TIE_COS` of perpendicular to the ray the first non-zero of
    ``n_z, n_y, n_x`` decides (negate where it is positive). Branch-free (selects). ``tie2``:
    :data:`TIE_COS2` in the loop's type (the row passes read it from their constants row,
    :data:`depthnormals.kernels.depth.C_TIE2`, so that float32 stays float32)."""
    key = nz if nz != 0.0 else (ny if ny != 0.0 else nx)
    tie = dot * dot <= tie2 * n2 * p2
    return key > 0.0 if tie else dot > 0.0


@nb.njit(cache=True, error_model="numpy", inline="always")
def oriented_unit(nx, ny, nz, px, py, pz):
    """(nx, ny, nz) normalised and oriented toward the camera (dot with the point < 0; the
    tie rule of :data:`TIE_COS` where the normal is perpendicular to the ray).

    NaN (all three) when the vector is not finite or has zero length.
    """
    n2 = nx * nx + ny * ny + nz * nz
    norm = math.sqrt(n2)
    if not (norm > 0.0) or not math.isfinite(norm):
        return np.nan, np.nan, np.nan
    inv = 1.0 / norm
    if faces_away(nx * px + ny * py + nz * pz, n2, px * px + py * py + pz * pz, nx, ny, nz):
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
