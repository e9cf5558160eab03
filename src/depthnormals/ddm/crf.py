"""Candidate selection and the CRF of 3F2N+ (sections III-A to III-C), compiled with numba.

Every kernel is a serial numba function over a band of rows, run on threads by
:func:`depthnormals._parallel.run_rows`; candidates are the pixels of a neighbourhood whose depth
is valid and whose input normal is finite, so invalid pixels never give a normal. The chosen
normal is re-oriented toward the camera at the receiving pixel.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .._parallel import run_rows
from ..estimators._common import store_normal
from .correlation import pearson_pair

__all__ = ["CROSS", "SQUARE", "clamp_key", "crf_step", "select_min", "take_smaller"]

# candidate offsets (dv, du), self first (self wins ties). CROSS is the public code's order:
# self, up, left, right, down.
CROSS = np.array([[0, 0], [-1, 0], [0, -1], [0, 1], [1, 0]], dtype=np.int64)
SQUARE = np.array([[0, 0], [-1, -1], [-1, 0], [-1, 1], [0, -1], [0, 1], [1, -1], [1, 0],
                   [1, 1]], dtype=np.int64)
_BIG = 1e6
_KEY_MAX = np.finfo(np.float64).max  # keys at or above it tie (first wins)


_JIT = {"cache": True, "nogil": True, "error_model": "numpy"}
_INL = {"cache": True, "error_model": "numpy", "inline": "always"}


@nb.njit(**_INL)
def _ok(z, n, r, c):
    h, w = z.shape
    if r < 0 or r >= h or c < 0 or c >= w:
        return False
    return z[r, c] == z[r, c] and n[r, c, 0] == n[r, c, 0]


@nb.njit(**_INL)
def _nan3(out, v, u):
    out[v, u, 0] = np.nan
    out[v, u, 1] = np.nan
    out[v, u, 2] = np.nan


@nb.njit(**_INL)
def _select_pixel(z, normals, key, offs, fx, fy, cx, cy, v, u, selfw, out):
    zq = z[v, u]
    if not (zq == zq):
        _nan3(out, v, u)
        return
    found = False
    best = 0.0
    bv = np.int64(v)
    bu = np.int64(u)
    for k in range(offs.shape[0]):
        r = v + offs[k, 0]
        c = u + offs[k, 1]
        if not _ok(z, normals, r, c):
            continue
        kk = clamp_key(key[r, c], _KEY_MAX)
        kk = kk * selfw if k == 0 else kk  # offs[0] is the pixel itself
        if not found or kk < best:
            found = True
            best = kk
            bv = r
            bu = c
    if found:
        store_normal(out, v, u, np.float64(normals[bv, bu, 0]), np.float64(normals[bv, bu, 1]),
                     np.float64(normals[bv, bu, 2]), (u - cx) * zq / fx, (v - cy) * zq / fy, zq)
    else:
        _nan3(out, v, u)


@nb.njit(**_INL)
def clamp_key(k, big):
    """A valid candidate's key: ``inf`` and NaN read as ``big`` (any valid candidate beats
    none; among keys >= ``big`` the first wins)."""
    return k if k < big else big


@nb.njit(**_INL)
def take_smaller(kr, k, xr, yr, tr, x, y, t):
    """(key, normal) of the candidate if its key is strictly smaller, else the current ones."""
    kr = np.float64(kr)
    tk = kr < k
    return (kr if tk else k), (xr if tk else x), (yr if tk else y), (tr if tk else t)


@nb.njit(**_INL)
def _cand(zr, kr, xr):
    return clamp_key(np.float64(kr), _KEY_MAX) if (zr == zr) & (xr == xr) else np.inf


@nb.njit(cache=True, error_model="numpy", fastmath={"nsz", "contract", "arcp"})
def _cross_row(zp, zc, zn, kp, kc, kn, np_, nc, nn, a0, b, fx, fy, selfw, bx, by, bz):
    """Branch-free cross selection (self, up, left, right, down) over the interior columns.

    Keys of valid candidates are clamped (:func:`clamp_key`), invalid ones are ``inf``; the
    first strictly smallest wins (self first, its key times ``selfw``). Writes the
    normalised, camera-facing normal (NaN where none) into bx, by, bz.
    """
    ifx = 1.0 / fx
    by_ = b / fy
    for u in range(1, zc.size - 1):  # constant start: no index wrap-around checks
        zq = zc[u]
        x = np.float64(nc[u, 0])
        y = np.float64(nc[u, 1])
        t = np.float64(nc[u, 2])
        k = _cand(zq, kc[u], x) * selfw
        xr = np.float64(np_[u, 0])
        k, x, y, t = take_smaller(_cand(zp[u], kp[u], xr), k, xr, np.float64(np_[u, 1]),
                                  np.float64(np_[u, 2]), x, y, t)
        xr = np.float64(nc[u - 1, 0])
        k, x, y, t = take_smaller(_cand(zc[u - 1], kc[u - 1], xr), k, xr,
                                  np.float64(nc[u - 1, 1]), np.float64(nc[u - 1, 2]), x, y, t)
        xr = np.float64(nc[u + 1, 0])
        k, x, y, t = take_smaller(_cand(zc[u + 1], kc[u + 1], xr), k, xr,
                                  np.float64(nc[u + 1, 1]), np.float64(nc[u + 1, 2]), x, y, t)
        xr = np.float64(nn[u, 0])
        k, x, y, t = take_smaller(_cand(zn[u], kn[u], xr), k, xr, np.float64(nn[u, 1]),
                                  np.float64(nn[u, 2]), x, y, t)
        nrm = math.sqrt(x * x + y * y + t * t)
        good = (k < np.inf) & (zq == zq) & (nrm > 0.0) & (nrm < np.inf)
        inv = 1.0 / nrm
        # orientation: sign of dot(n, X) = z_q (n_x (u - cx) / fx + n_y (v - cy) / fy + n_z)
        inv = -inv if x * ((u - a0) * ifx) + y * by_ + t > 0.0 else inv
        bx[u] = x * inv if good else np.nan
        by[u] = y * inv if good else np.nan
        bz[u] = t * inv if good else np.nan


@nb.njit(**_JIT)
def _select_rows(v0, v1, z, normals, key, offs, cross, fx, fy, cx, cy, selfw, out):
    h, w = z.shape
    bx = np.empty(w)
    by = np.empty(w)
    bz = np.empty(w)
    for v in range(v0, v1):
        if cross and 0 < v < h - 1 and w > 2:
            _cross_row(z[v - 1], z[v], z[v + 1], key[v - 1], key[v], key[v + 1],
                       normals[v - 1], normals[v], normals[v + 1], cx, v - cy,
                       fx, fy, selfw, bx, by, bz)
            for u in range(1, w - 1):
                out[v, u, 0] = bx[u]
                out[v, u, 1] = by[u]
                out[v, u, 2] = bz[u]
            _select_pixel(z, normals, key, offs, fx, fy, cx, cy, v, 0, selfw, out)
            _select_pixel(z, normals, key, offs, fx, fy, cx, cy, v, w - 1, selfw, out)
        else:
            for u in range(w):
                _select_pixel(z, normals, key, offs, fx, fy, cx, cy, v, u, selfw, out)


def select_min(z, normals, key, offs, fx, fy, cx, cy, out, self_weight=1.0):
    """Each valid pixel takes the normal of the candidate with the least ``key`` (self first).

    The pixel's own key is multiplied by ``self_weight`` first (1: plain arg-min, the pixel
    winning ties; < 1: a neighbour must be clearly better). Writes every pixel of ``out``
    (NaN at invalid depth and where no candidate exists).
    """
    cross = offs.shape == CROSS.shape and bool((offs == CROSS).all())
    run_rows(_select_rows, z.shape[0], z, normals, key, offs, cross, float(fx), float(fy),
             float(cx), float(cy), float(self_weight), out)


@nb.njit(**_INL)
def _dist(a, r1, c1, b, r2, c2):
    d0 = np.float64(a[r1, c1, 0]) - np.float64(b[r2, c2, 0])
    d1 = np.float64(a[r1, c1, 1]) - np.float64(b[r2, c2, 1])
    d2 = np.float64(a[r1, c1, 2]) - np.float64(b[r2, c2, 2])
    return math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)


@nb.njit(cache=True, error_model="numpy", fastmath={"nsz", "contract", "arcp"})
def _sim_row(zr, tr, a, b, srow, hrow):
    """Similarity bound ``a + b tau`` of every pixel of a row (0 at invalid depth) and its
    horizontal 3-sums (the row's share of the 8-neighbour sums)."""
    w = zr.size
    for u in range(w):
        t = a + b * np.float64(tr[u])
        srow[u] = t if (zr[u] == zr[u]) & (t == t) else 0.0
    for u in range(1, w - 1):
        hrow[u] = srow[u - 1] + srow[u] + srow[u + 1]


@nb.njit(cache=True, error_model="numpy", fastmath={"nsz", "contract", "arcp"})
def _crf_skip_row(hp, hc, hn, sc, kq, sigma, lam, skip):
    """``skip[u]``: the exact shortcut's test ``sigma >= lam k_q sum_i s_i`` holds with the sum
    bounded from above (every neighbour of valid depth counted, Pearson's |corr| by 1, a
    relative margin of 1e-9 for rounding), so pixel u keeps its anchor. Interior columns."""
    for u in range(1, sc.size - 1):
        wsum = (hp[u] + hc[u] + hn[u] - sc[u]) * (1.0 + 1e-9)
        k = kq[u]
        k = k if k < _BIG else _BIG
        skip[u] = sigma >= lam * k * wsum


@nb.njit(**_INL)
def _norm3(a, b, c):
    return math.sqrt(a * a + b * b + c * c)


@nb.njit(**_INL)
def _crf_pixel(z, cur, anchor, kq, sim_mode, tau, sigma, lam, offs, fx, fy, cx, cy, v, u, wi,
               nb, out):
    """Per-pixel minimisation of the CRF energy at (v, u) (see :func:`crf_step`).

    ``wi`` (8,) and ``nb`` (8, 3) are scratch: the weights and normals of the valid
    neighbours. A candidate's sum stops as soon as it cannot beat the best (terms >= 0).
    """
    zq = z[v, u]
    if not (zq == zq):
        _nan3(out, v, u)
        return
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
            nb[n_nb, 0] = cur[r, c, 0]
            nb[n_nb, 1] = cur[r, c, 1]
            nb[n_nb, 2] = cur[r, c, 2]
            wsum += s
            n_nb += 1
    ax = np.float64(anchor[v, u, 0])
    ay = np.float64(anchor[v, u, 1])
    az = np.float64(anchor[v, u, 2])
    has_anchor = ax == ax
    same = (has_anchor and cur[v, u, 0] == anchor[v, u, 0]
            and cur[v, u, 1] == anchor[v, u, 1] and cur[v, u, 2] == anchor[v, u, 2])
    if same and sigma >= lam * k * wsum:
        store_normal(out, v, u, ax, ay, az, px, py, zq)
        return
    found = False
    best = 0.0
    bx = np.nan
    by = np.nan
    bz = np.nan
    lk = lam * k
    for j in range(offs.shape[0]):
        r = v + offs[j, 0]
        c = u + offs[j, 1]
        if not _ok(z, cur, r, c):
            continue
        qx = np.float64(cur[r, c, 0])
        qy = np.float64(cur[r, c, 1])
        qz = np.float64(cur[r, c, 2])
        e = sigma * _norm3(qx - ax, qy - ay, qz - az) if has_anchor else 0.0
        acc = 0.0
        for i in range(n_nb):
            acc += wi[i] * _norm3(nb[i, 0] - qx, nb[i, 1] - qy, nb[i, 2] - qz)
            if found and e + lk * acc >= best:
                break
        e += lk * acc
        if not found or e < best:
            found = True
            best = e
            bx = qx
            by = qy
            bz = qz
    if found:
        store_normal(out, v, u, bx, by, bz, px, py, zq)
    else:
        _nan3(out, v, u)


@nb.njit(**_JIT)
def _crf_rows(v0, v1, z, cur, anchor, anchored, kq, sim_mode, tau, sigma, lam, offs, fx, fy, cx,
              cy, out):
    h, w = z.shape
    wi = np.empty(8)
    nb = np.empty((8, 3))
    skip = np.zeros(w, dtype=np.bool_)
    # similarity a + b tau of a neighbour (its bound 1 for Pearson), for the skip test
    a = 1.0 if sim_mode != 2 else 0.0
    b = -1.0 if sim_mode == 1 else (1.0 if sim_mode == 2 else 0.0)
    zero = np.zeros(w)
    full = tau.shape == z.shape
    srows = np.zeros((3, w))  # ring (row % 3) of similarity bounds and their 3-sums
    hrows = np.zeros((3, w))
    test = w > 2 and (b == 0.0 or full)
    if test:
        for r in range(max(v0 - 1, 0), min(v0 + 1, h)):
            _sim_row(z[r], tau[r] if full else zero, a, b, srows[r % 3], hrows[r % 3])
    for v in range(v0, v1):
        skip[:] = False
        if test and v + 1 < h:
            _sim_row(z[v + 1], tau[v + 1] if full else zero, a, b, srows[(v + 1) % 3],
                     hrows[(v + 1) % 3])
        if test and 0 < v < h - 1:
            _crf_skip_row(hrows[(v - 1) % 3], hrows[v % 3], hrows[(v + 1) % 3], srows[v % 3],
                          kq[v], sigma, lam, skip)
        # the shortcut keeps the anchor (a unit, camera-facing normal, NaN at invalid depth)
        out[v] = cur[v]
        for u in range(w):
            if skip[u] and anchor[v, u, 0] == anchor[v, u, 0] and (
                    anchored or (cur[v, u, 0] == anchor[v, u, 0]
                                 and cur[v, u, 1] == anchor[v, u, 1]
                                 and cur[v, u, 2] == anchor[v, u, 2])):
                continue
            _crf_pixel(z, cur, anchor, kq, sim_mode, tau, sigma, lam, offs, fx, fy, cx, cy, v,
                       u, wi, nb, out)


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
    Writes every pixel of ``out``.
    """
    run_rows(_crf_rows, z.shape[0], z, cur, anchor, cur is anchor, kq, int(sim_mode), tau,
             float(sigma), float(lam), offs, float(fx), float(fy), float(cx), float(cy), out)
