"""Plane-fit selection: a noise-robust alternative to the curvature selection of 3F2N+.

Ours, not the paper's.

Every pixel ``q`` takes the normal of the candidate ``r`` (a valid pixel within ``radius`` of
``q``, ``q`` itself included) whose plane - through the point of ``r`` with the normal
estimated at ``r`` - best explains the points around ``q``: the score of a candidate is the
sum over the valid points ``p_i`` of the ``(2 support + 1)^2`` window of ``q`` of
``w_i min(|n_r . (p_i - p_r)| / (z_i / fx), 1)``, a residual in units of the pixel footprint
truncated at one footprint so that points of another surface cost the same whatever their
distance, with ``w_q = 3`` for ``q`` itself and 1 for the others. Ties keep ``q``'s own
normal. This is our extension (not in the paper): measured in docs/3f2n-plus.md.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .._parallel import run_rows
from ..kernels.orient import store_nan, store_normal

__all__ = ["plane_fit_select"]

_SELF_WEIGHT = 3.0
_CAP = 1.0


# no reassociation (as in boxfit.py: code compiled in the process and loaded from numba's
# cache may round reassociated sums differently); no-NaN flags are never allowed (the
# support holds finite points only, but candidates' NaN normals are tested explicitly)
_FASTMATH = {"contract", "nsz", "arcp"}


@nb.njit(cache=True, nogil=True, error_model="numpy", fastmath=_FASTMATH)
def _plane_fit_rows(v0, v1, z, n, fx, fy, cx, cy, rc, rs, out):
    h, w = z.shape
    ns = (2 * rs + 1) * (2 * rs + 1)
    px = np.empty(ns)
    py = np.empty(ns)
    pz = np.empty(ns)
    sc = np.empty(ns)
    wt = np.empty(ns)
    for v in range(v0, v1):
        for u in range(w):
            zq = z[v, u]
            if not (zq == zq):
                store_nan(out, v, u)
                continue
            # the support: valid points of the window (missing ones cost every candidate alike)
            m = 0
            for ev in range(-rs, rs + 1):
                a = v + ev
                if a < 0 or a >= h:
                    continue
                for eu in range(-rs, rs + 1):
                    b = u + eu
                    if b < 0 or b >= w:
                        continue
                    za = np.float64(z[a, b])
                    if not (za == za):
                        continue
                    px[m] = (b - cx) * za / fx
                    py[m] = (a - cy) * za / fy
                    pz[m] = za
                    sc[m] = fx / za
                    wt[m] = _SELF_WEIGHT if (ev == 0 and eu == 0) else 1.0
                    m += 1
            best = np.inf
            bx = np.nan
            by = np.nan
            bz = np.nan
            for k in range(-1, (2 * rc + 1) * (2 * rc + 1)):
                # k = -1 is q itself, scored first so that it wins ties
                if k < 0:
                    r = v
                    c = u
                else:
                    r = v + k // (2 * rc + 1) - rc
                    c = u + k % (2 * rc + 1) - rc
                    if (r == v and c == u) or r < 0 or r >= h or c < 0 or c >= w:
                        continue
                zr = np.float64(z[r, c])
                nx = np.float64(n[r, c, 0])
                ny = np.float64(n[r, c, 1])
                nz = np.float64(n[r, c, 2])
                norm = math.sqrt(nx * nx + ny * ny + nz * nz)
                if not (zr == zr) or not (norm > 0.0 and norm < np.inf):
                    continue
                nx /= norm
                ny /= norm
                nz /= norm
                d0 = nx * (c - cx) * zr / fx + ny * (r - cy) * zr / fy + nz * zr
                score = 0.0
                for i in range(m):
                    res = abs(nx * px[i] + ny * py[i] + nz * pz[i] - d0) * sc[i]
                    score += wt[i] * (res if res < _CAP else _CAP)
                if score < best * (1.0 - 1e-12) - 1e-300:
                    best = score
                    bx = nx
                    by = ny
                    bz = nz
            store_normal(out, v, u, bx, by, bz, (u - cx) * zq / fx, (v - cy) * zq / fy, zq)


def plane_fit_select(z: np.ndarray, normals: np.ndarray, fx: float, fy: float, cx: float, cy: float,
                     radius: int, support: int, out: np.ndarray) -> None:
    """Fill ``out`` (H, W, 3) float32 with the plane-fit selection (see the module doc).

    ``z`` is depth with NaN at invalid pixels; ``normals`` any (H, W, 3) float normals (NaN
    where none). Writes every pixel: NaN at invalid depth and where no candidate is finite.
    """
    run_rows(_plane_fit_rows, z.shape[0], z, normals, float(fx), float(fy), float(cx), float(cy),
             int(radius), int(support), out, min_rows=8)
