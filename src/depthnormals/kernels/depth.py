"""Input preparation shared by every estimator and by the module: depth validated, invalid
pixels as NaN, and the dtype the vectorised row passes run in.

Inside the kernels invalid depth is NaN (see :func:`prepare`), so ``z == z`` tests validity.
Arithmetic is float64 in registers (except 3F2N's FD row pass, which runs in the dtype of the
depth); outputs are float32.
"""

from __future__ import annotations

from collections import namedtuple
from typing import Any

import numba as nb
import numpy as np

from .._validate import check_depth
from ..camera import Intrinsics, as_intrinsics
from .orient import TIE_COS2

__all__ = ["C_FX", "C_FY", "C_HALF", "C_INF", "C_MAX", "C_NINF", "C_ONE", "C_TIE2", "C_ZERO",
           "FLOAT32_RANGE", "Pinhole", "new_output", "pinhole", "prepare", "row_arrays", "row_dtype"]


def prepare(depth: Any, K: Any, depth_scale: float | None) -> tuple[np.ndarray, Intrinsics]:
    """Validate inputs; return depth as a C-contiguous float array with NaN at invalid pixels."""
    z = check_depth(depth, depth_scale=depth_scale)
    cam = as_intrinsics(K)
    out, bad = _nan_where_invalid(z)
    return (out if bad else z), cam


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _nan_where_invalid(z):
    """A copy of ``z`` (C-contiguous) with NaN where the depth is invalid (0, negative, NaN,
    inf) and how many such pixels there were: one pass (numpy's mask, test and select were
    0.39 ms on a 640x480 frame against 0.06)."""
    out = np.empty_like(z)
    a = z.ravel()
    o = out.ravel()
    bad = 0
    for i in range(a.size):
        v = a[i]
        ok = (v > 0.0) & (v < np.inf)
        o[i] = v if ok else np.nan
        bad += 0 if ok else 1
    return out, bad


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


#: Pinhole intrinsics as the kernels take them (floats, pixels, 0-based pixel centres).
Pinhole = namedtuple("Pinhole", ["fx", "fy", "cx", "cy"])


def pinhole(cam: Intrinsics) -> Pinhole:
    """The :class:`Pinhole` of validated intrinsics."""
    return Pinhole(float(cam.fx), float(cam.fy), float(cam.cx), float(cam.cy))


#: Slots of the constants row ``c`` that :func:`row_arrays` returns (in the dtype of the
#: depth, so the vectorised row passes never convert): 0.5, 1, +inf, -inf, 0, fx, fy, the
#: dtype's largest finite float and the squared cosine of the orientation's tie
#: (:data:`depthnormals.kernels.orient.TIE_COS2`). Kernels read ``c[C_ONE]``, never ``c[1]``.
C_HALF, C_ONE, C_INF, C_NINF, C_ZERO, C_FX, C_FY, C_MAX, C_TIE2 = range(9)


def row_arrays(z: np.ndarray, fx: float, fy: float, cx: float,
               cy: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Typed inputs of the row kernels, in the dtype of ``z`` (as :func:`row_dtype` gives it).

    ``c``: the constants row (slots :data:`C_HALF` .. :data:`C_TIE2`), ``acol[u] = u - cx``,
    ``bcol[v] = v - cy``. Casting huge or tiny intrinsics to float32 only happens where the
    row passes are not used, so overflow and underflow are silent here.
    """
    h, w = z.shape
    with np.errstate(over="ignore", under="ignore"):
        c = np.array([0.5, 1.0, np.inf, -np.inf, 0.0, fx, fy, np.finfo(z.dtype).max, TIE_COS2],
                     dtype=z.dtype)
        acol = (np.arange(w) - cx).astype(z.dtype)
        bcol = (np.arange(h) - cy).astype(z.dtype)
    return c, acol, bcol


def new_output(shape: tuple[int, int]) -> np.ndarray:
    """An (H, W, 3) float32 array filled with NaN."""
    return np.full((shape[0], shape[1], 3), np.nan, dtype=np.float32)
