"""Correlation coefficients of 3F2N+ (section III-B of the paper), compiled with numba.

Kendall
    In the 3x3 patch of a pixel ``r``, ``mu_c`` neighbours are deeper and ``mu_d`` shallower
    than ``r`` (ties and invalid neighbours ignored); ``tau_r = |mu_c - mu_d| / (mu_c + mu_d)``.
    On any plane the neighbours pair up symmetrically around ``r`` (inverse depth is linear),
    so ``tau = 0``; at a crest, a valley or beside an occlusion edge it rises toward 1.
    ``tau`` is 0 when every valid neighbour ties (a fronto-parallel patch is a plane).
    The paper's prose calls a *larger* tau "more likely the same plane" and selects the
    arg-max, while its CRF weight ``1 - tau`` (and the formula itself) treats large tau as a
    discontinuity. Both readings are available (``kendall`` = discontinuity reading,
    ``kendall-prose`` = the prose's arg-max); see ``docs/3f2n-plus.md`` for the measurement.
Pearson
    The paper correlates ``psi = (z_p1..z_p8)`` with ``psi+ = (z_q, z_p1..z_p8)``, vectors of
    different lengths. Our reading: the Pearson correlation between the 3x3 depth patch of the
    candidate ``r`` and the 3x3 depth patch of the centre ``q`` (pairs at equal offsets, both
    valid), ``eps_r = |corr|`` in [0, 1]; 1 when both patches are constant, 0 when one is.

Both are returned as a *similarity* ``s`` in [0, 1] (1 = same smooth surface) by
:func:`similarity`, which is what the selection and the CRF consume.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .._parallel import run_rows

__all__ = ["CORRELATIONS", "kendall_map"]

CORRELATIONS = ("kendall", "kendall-prose", "pearson", "none")


@nb.njit(cache=True, error_model="numpy")
def _sign_counts(z0, a, b, c, d, e, f, g, k):
    """(|mu_c - mu_d| / (mu_c + mu_d), 0 when all tie) of a centre and its 8 neighbours."""
    mc = (np.float64(a > z0) + np.float64(b > z0) + np.float64(c > z0) + np.float64(d > z0)
          + np.float64(e > z0) + np.float64(f > z0) + np.float64(g > z0) + np.float64(k > z0))
    md = (np.float64(a < z0) + np.float64(b < z0) + np.float64(c < z0) + np.float64(d < z0)
          + np.float64(e < z0) + np.float64(f < z0) + np.float64(g < z0) + np.float64(k < z0))
    s = mc + md
    t = abs(mc - md) / (s if s > 0.0 else 1.0)
    return t if z0 == z0 else np.nan


@nb.njit(cache=True, error_model="numpy", inline="always")
def _smp(z, v, u):
    h, w = z.shape
    if v < 0 or v >= h or u < 0 or u >= w:
        return np.nan
    return np.float64(z[v, u])


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _kendall_rows(v0, v1, z, out):
    h, w = z.shape
    for v in range(v0, v1):
        if 0 < v < h - 1 and w > 2:
            zp = z[v - 1]
            zc = z[v]
            zn = z[v + 1]
            o = out[v]
            for u in range(1, w - 1):  # branch-free interior (NaN compares false: ignored)
                o[u] = _sign_counts(np.float64(zc[u]), np.float64(zp[u - 1]),
                                    np.float64(zp[u]), np.float64(zp[u + 1]),
                                    np.float64(zc[u - 1]), np.float64(zc[u + 1]),
                                    np.float64(zn[u - 1]), np.float64(zn[u]),
                                    np.float64(zn[u + 1]))
            cols = (0, w - 1)
        else:
            cols = (-1, -1)
        for u in range(w):
            if cols[0] >= 0 and u != cols[0] and u != cols[1]:
                continue
            out[v, u] = _sign_counts(_smp(z, v, u), _smp(z, v - 1, u - 1), _smp(z, v - 1, u),
                                     _smp(z, v - 1, u + 1), _smp(z, v, u - 1),
                                     _smp(z, v, u + 1), _smp(z, v + 1, u - 1),
                                     _smp(z, v + 1, u), _smp(z, v + 1, u + 1))


def kendall_map(z: np.ndarray) -> np.ndarray:
    """Kendall's tau of the paper at every pixel of depth ``z`` (NaN where z is invalid).

    ``z``: float array (H, W) with NaN at invalid pixels (as prepared by the estimators).
    """
    z = np.ascontiguousarray(z)
    if z.dtype.kind != "f":
        z = z.astype(np.float64)
    out = np.empty(z.shape)
    run_rows(_kendall_rows, z.shape[0], z, out)
    return out


@nb.njit(cache=True, error_model="numpy", inline="always")
def pearson_pair(z, v1, u1, v2, u2):
    """|Pearson correlation| between the 3x3 depth patches centred at (v1, u1) and (v2, u2)."""
    h, w = z.shape
    a0 = z[v1, u1]  # shift by the centres: Pearson is shift-invariant, sums stay small
    b0 = z[v2, u2]
    n = 0
    sa = 0.0
    sb = 0.0
    saa = 0.0
    sbb = 0.0
    sab = 0.0
    for dv in range(-1, 2):
        for du in range(-1, 2):
            r1 = v1 + dv
            c1 = u1 + du
            r2 = v2 + dv
            c2 = u2 + du
            if r1 < 0 or r1 >= h or c1 < 0 or c1 >= w or r2 < 0 or r2 >= h or c2 < 0 or c2 >= w:
                continue
            a = z[r1, c1] - a0
            b = z[r2, c2] - b0
            if not (a == a and b == b):
                continue
            n += 1
            sa += a
            sb += b
            saa += a * a
            sbb += b * b
            sab += a * b
    if n < 2:
        return 0.0
    va = saa - sa * sa / n
    vb = sbb - sb * sb / n
    scale = 1e-20 * (a0 * a0 + b0 * b0)
    if va <= scale and vb <= scale:
        return 1.0
    if va <= scale or vb <= scale:
        return 0.0
    return min(1.0, abs(sab - sa * sb / n) / math.sqrt(va * vb))
