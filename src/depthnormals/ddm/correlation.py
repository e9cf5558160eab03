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

__all__ = ["CORRELATIONS", "kendall_map"]

CORRELATIONS = ("kendall", "kendall-prose", "pearson", "none")


@nb.njit(cache=True, parallel=True)
def kendall_map(z):
    """Kendall's tau of the paper at every pixel (NaN where the pixel is invalid)."""
    h, w = z.shape
    out = np.empty((h, w))
    for v in nb.prange(h):
        for u in range(w):
            z0 = z[v, u]
            if not (z0 == z0):
                out[v, u] = np.nan
                continue
            mc = 0
            md = 0
            for dv in range(-1, 2):
                r = v + dv
                if r < 0 or r >= h:
                    continue
                for du in range(-1, 2):
                    c = u + du
                    if c < 0 or c >= w or (dv == 0 and du == 0):
                        continue
                    zn = z[r, c]
                    if zn > z0:
                        mc += 1
                    elif zn < z0:
                        md += 1
            if mc + md == 0:
                out[v, u] = 0.0
            else:
                out[v, u] = abs(mc - md) / (mc + md)
    return out


@nb.njit(cache=True)
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
