"""Candidate selection and the CRF of 3F2N+ (sections III-A to III-C), compiled with numba.

Every kernel is parallel over rows; candidates are the pixels of a neighbourhood whose depth
is valid and whose input normal is finite, so invalid pixels never give a normal. The chosen
normal is re-oriented toward the camera at the receiving pixel.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..estimators._common import store_normal
from .correlation import pearson_pair

__all__ = ["CROSS", "SQUARE", "crf_step", "select_min"]

# candidate offsets (dv, du), self first (self wins ties). CROSS is the public code's order:
# self, up, left, right, down.
CROSS = np.array([[0, 0], [-1, 0], [0, -1], [0, 1], [1, 0]], dtype=np.int64)
SQUARE = np.array([[0, 0], [-1, -1], [-1, 0], [-1, 1], [0, -1], [0, 1], [1, -1], [1, 0],
                   [1, 1]], dtype=np.int64)
_BIG = 1e6


@nb.njit(cache=True, inline="always")
def _ok(z, n, r, c):
    h, w = z.shape
    if r < 0 or r >= h or c < 0 or c >= w:
        return False
    return z[r, c] == z[r, c] and n[r, c, 0] == n[r, c, 0]


@nb.njit(cache=True, parallel=True)
def select_min(z, normals, key, offs, fx, fy, cx, cy, out):
    """Each valid pixel takes the normal of the candidate with the least ``key`` (self first)."""
    h, w = z.shape
    m = offs.shape[0]
    for v in nb.prange(h):
        for u in range(w):
            zq = z[v, u]
            if not (zq == zq):
                continue
            found = False
            best = 0.0
            bv = np.int64(v)
            bu = np.int64(u)
            for k in range(m):
                r = v + offs[k, 0]
                c = u + offs[k, 1]
                if not _ok(z, normals, r, c):
                    continue
                kk = key[r, c]
                if not found or kk < best:
                    found = True
                    best = kk
                    bv = r
                    bu = c
            if found:
                store_normal(out, v, u, normals[bv, bu, 0], normals[bv, bu, 1],
                             normals[bv, bu, 2], (u - cx) * zq / fx, (v - cy) * zq / fy, zq)


@nb.njit(cache=True, inline="always")
def _dist(a, r1, c1, b, r2, c2):
    d0 = a[r1, c1, 0] - b[r2, c2, 0]
    d1 = a[r1, c1, 1] - b[r2, c2, 1]
    d2 = a[r1, c1, 2] - b[r2, c2, 2]
    return math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)


@nb.njit(cache=True, parallel=True)
def crf_step(z, cur, anchor, kq, sim_mode, tau, sigma, lam, offs, fx, fy, cx, cy, out):
    """One synchronous pass of per-pixel minimisation of the 3F2N+ CRF energy.

    For pixel q and each candidate normal c (the current normals of the valid pixels in
    ``offs`` around q, self first),
    ``E(c) = sigma |c - anchor_q| + lam k_q sum_i w_i |cur_{p_i} - c|`` over the valid
    8-neighbours p_i, with ``w_i`` the similarity of p_i: 1 (``sim_mode`` 0),
    ``1 - tau`` (1, the discontinuity reading of Kendall), ``tau`` (2, the prose reading) or
    the |Pearson| correlation of the depth patches of p_i and q (3). The least energy wins.
    Exact shortcut: when the current label is the anchor and ``sigma >= lam k_q sum_i w_i``,
    the triangle inequality proves no candidate beats it, so the pixel is skipped.
    """
    h, w = z.shape
    m = offs.shape[0]
    for v in nb.prange(h):
        wi = np.empty(8)
        ri = np.empty(8, dtype=np.int64)
        ci = np.empty(8, dtype=np.int64)
        for u in range(w):
            zq = z[v, u]
            if not (zq == zq):
                continue
            px = (u - cx) * zq / fx
            py = (v - cy) * zq / fy
            k = kq[v, u]
            if not (k < _BIG):
                k = _BIG
            n_nb = 0
            wsum = 0.0
            for dv in range(-1, 2):
                for du in range(-1, 2):
                    if dv == 0 and du == 0:
                        continue
                    r = v + dv
                    c = u + du
                    if not _ok(z, cur, r, c):
                        continue
                    if sim_mode == 0:
                        s = 1.0
                    elif sim_mode == 1:
                        s = 1.0 - tau[r, c]
                    elif sim_mode == 2:
                        s = tau[r, c]
                    else:
                        s = pearson_pair(z, r, c, v, u)
                    wi[n_nb] = s
                    ri[n_nb] = r
                    ci[n_nb] = c
                    wsum += s
                    n_nb += 1
            has_anchor = anchor[v, u, 0] == anchor[v, u, 0]
            same = (has_anchor and cur[v, u, 0] == anchor[v, u, 0]
                    and cur[v, u, 1] == anchor[v, u, 1] and cur[v, u, 2] == anchor[v, u, 2])
            if same and sigma >= lam * k * wsum:
                store_normal(out, v, u, cur[v, u, 0], cur[v, u, 1], cur[v, u, 2], px, py, zq)
                continue
            found = False
            best = 0.0
            bv = np.int64(v)
            bu = np.int64(u)
            for j in range(m):
                r = v + offs[j, 0]
                c = u + offs[j, 1]
                if not _ok(z, cur, r, c):
                    continue
                e = 0.0
                if has_anchor:
                    e = sigma * _dist(cur, r, c, anchor, v, u)
                acc = 0.0
                for i in range(n_nb):
                    acc += wi[i] * _dist(cur, ri[i], ci[i], cur, r, c)
                e += lam * k * acc
                if not found or e < best:
                    found = True
                    best = e
                    bv = r
                    bu = c
            if found:
                store_normal(out, v, u, cur[bv, bu, 0], cur[bv, bu, 1], cur[bv, bu, 2],
                             px, py, zq)
