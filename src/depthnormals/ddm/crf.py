"""Stage 3 of 3F2N+: the CRF (section III-C), one synchronous pass per call of :func:`crf_step`.

Cross candidates with Kendall or no correlation run the row kernels of
:mod:`depthnormals.ddm.crf_ring` (which the fused 3F2N+ pass shares); the square
neighbourhood and Pearson run the per-pixel float64 kernel :func:`_crf_pixel`, which is also
the readable reference of the energy.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .._parallel import run_rows
from ..kernels.depth import Pinhole
from ..kernels.orient import store_nan, store_normal
from .correlation import pearson_pair
from .crf_ring import (
    _BIG,
    crf_flush,
    crf_ring_row,
    ring_slots,
    scratch,
    sim_coefficients,
    similarity_ring_row,
)
from .selection import CROSS, _ok

__all__ = ["crf_step"]

_JIT = {"cache": True, "nogil": True, "error_model": "numpy"}
_INL = {"cache": True, "error_model": "numpy", "inline": "always"}


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
def _crf_pixel(z, cur, anchor, kq, sim_mode, tau, sigma, lam, offs, cam, v, u, wi, nb, out):
    """Per-pixel minimisation of the CRF energy at (v, u) (see :func:`crf_step`).

    ``wi`` (8,) and ``nb`` (8, 3) are scratch: the weights and normals of the valid
    neighbours. A candidate's sum stops as soon as it cannot beat the best (terms >= 0).
    ``cam``: :class:`depthnormals.kernels.depth.Pinhole`. Writes ``out[v, u]``.
    """
    fx, fy, cx, cy = cam
    zq = z[v, u]
    if not (zq == zq):
        store_nan(out, v, u)
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
        store_nan(out, v, u)


@nb.njit(**_JIT)
def _crf_rows(v0, v1, z, cur, anchor, anchored, kq, sim_mode, tau, sigma, lam, offs, cam, out):
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
            _crf_pixel(z, cur, anchor, kq, sim_mode, tau, sigma, lam, offs, cam, v, u, wi, nb,
                       out)


@nb.njit(**_JIT)
def _crf_ring_rows(v0, v1, z, cur, anchor, anchored, kq, a, b, sigma, lam, cam, out):
    """The cross-candidate CRF of rows [v0, v1) through the ring kernels of
    :mod:`depthnormals.ddm.crf_ring` (the fused 3F2N+ pipeline calls the same ones)."""
    h, w = z.shape
    zb = np.full((4, w + 2), np.nan, dtype=z.dtype)  # slot r % 3; slot 3: outside
    sel = np.full((5, 3, w + 2), np.nan, dtype=np.float32)  # slot r % 4; slot 4: outside
    sim = np.zeros((5, w + 2), dtype=np.float32)
    hsum = np.zeros((5, w), dtype=np.float32)
    anc = np.full((3, w + 2), np.nan, dtype=np.float32)
    work = scratch(w)
    pend = 0
    for r in range(max(v0 - 2, 0), min(v1 + 2, h + 2)):
        if r < h:
            zr = zb[r % 3]
            sr = sel[r % 4]
            for u in range(w):
                zr[u + 1] = z[r, u]
            for j in range(3):  # NaN at invalid depth, as the kernels expect
                for u in range(w):
                    zz = z[r, u]
                    sr[j, u + 1] = cur[r, u, j] if zz == zz else np.nan
        t = r - 1
        if max(v0 - 1, 0) <= t < h:
            similarity_ring_row(t, h, zb, a, b, sim, hsum)
        q = r - 2
        if v0 <= q < v1:
            slots = ring_slots(q, h)
            if not anchored:
                for j in range(3):
                    for u in range(w):
                        anc[j, u + 1] = anchor[q, u, j]
            pend = crf_ring_row(q, slots, z, kq[q], (sel, sim, hsum),
                                sel[slots[1]] if anchored else anc, anchored, (sigma, lam), work,
                                pend, cam, out)
    crf_flush(z, work, pend, sigma, cam, out)


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
    Writes every pixel of ``out``. Cross candidates with Kendall or no correlation run the
    row kernels of :mod:`depthnormals.ddm.crf_ring` (``tau`` is then recomputed from ``z``,
    row by row, and the energies are evaluated in float32: docs/3f2n-plus.md, "How the CRF
    is computed"); the square neighbourhood and Pearson run the per-pixel float64 kernel
    here.
    """
    if int(sim_mode) != 3 and offs.shape == CROSS.shape and bool((offs == CROSS).all()):
        a, b = sim_coefficients(int(sim_mode))  # Kendall's tau recomputed from z, row by row
        run_rows(_crf_ring_rows, z.shape[0], z, cur, anchor, cur is anchor,
                 np.ascontiguousarray(kq, dtype=np.float64), a, b, float(sigma), float(lam),
                 Pinhole(float(fx), float(fy), float(cx), float(cy)), out)
        return
    run_rows(_crf_rows, z.shape[0], z, cur, anchor, cur is anchor, kq, int(sim_mode), tau,
             float(sigma), float(lam), offs, Pinhole(float(fx), float(fy), float(cx), float(cy)),
             out)
