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
from ..estimators._common import row_arrays, store_normal
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

__all__ = ["CROSS", "SQUARE", "clamp_key", "crf_step", "cross_select_row", "inconsistency",
           "inconsistency_pq", "select_min", "select_ring_row"]

# candidate offsets (dv, du), self first (self wins ties). CROSS is the public code's order:
# self, up, left, right, down.
CROSS = np.array([[0, 0], [-1, 0], [0, -1], [0, 1], [1, 0]], dtype=np.int64)
SQUARE = np.array([[0, 0], [-1, -1], [-1, 0], [-1, 1], [0, -1], [0, 1], [1, -1], [1, 0],
                   [1, 1]], dtype=np.int64)
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
def _side(r, d, step, one, zero):
    """(|N|, |D|) with ``rho = fx |N| / |D|``: the residual of a neighbour at ``z_p = r z_q``
    to the plane through q's point, which predicts ``z_q d / (d + step)`` on its ray. An
    invalid neighbour (NaN ``r``) reads as (1, 0): an infinite residual."""
    den = d + step
    num = r * den - d
    ok = num == num
    return (abs(num) if ok else one), (abs(den) if ok else zero)


@nb.njit(**_INL)
def _axis(rm, rp, d, step, one, zero):
    """(N, D) of the smaller residual of the two neighbours along one axis (division-free)."""
    nm, dm = _side(rm, d, -step, one, zero)
    np_, dp = _side(rp, d, step, one, zero)
    take_m = nm * dp < np_ * dm
    return (nm if take_m else np_), (dm if take_m else dp)


@nb.njit(**_INL)
def inconsistency_pq(a, b, t, rl, rr, rt, rb, A, B, ifx, ify, fx, one, zero):
    """One-sided tangent inconsistency of the candidate normal (a, b, t) at pixel q, as a
    fraction ``S = P / Q`` (``Q = 0``: infinite), free of divisions.

    ``S = min(rho_left, rho_right)^2 + min(rho_up, rho_down)^2`` with ``rho_p`` the residual
    of the neighbour point ``X_p`` to the plane with this normal through ``X_q``, along p's
    ray, in footprints ``z_q / fx``. With ``d = n . ray_q`` (ray ``((u - cx) / fx,
    (v - cy) / fy, 1)``) the plane predicts ``z_q d / (d -+ a / fx)`` left / right (likewise
    with ``b / fy`` up / down), so ``rho_p = fx |z_p / z_q - d / (d + step)|``. ``rl .. rb``:
    the neighbours' ``z_p / z_q`` (NaN when invalid); ``A, B``: ``u - cx``, ``v - cy``.
    Small when the normal is tangent to the depth on at least one side along each axis
    (right at creases and occlusions); infinite when an axis has no valid side. ``one``,
    ``zero``: 1 and 0 in the working dtype.
    """
    sa = a * ifx
    sb = b * ify
    d = sa * A + sb * B + t
    nu, du = _axis(rl, rr, d, sa, one, zero)
    nv, dv = _axis(rt, rb, d, sb, one, zero)
    du2 = du * du
    dv2 = dv * dv
    return fx * fx * (nu * nu * dv2 + nv * nv * du2), du2 * dv2


@nb.njit(**_INL)
def inconsistency(a, b, t, rl, rr, rt, rb, A, B, ifx, ify, fx, inf):
    """:func:`inconsistency_pq` as a number (``inf`` where undefined)."""
    p, q = inconsistency_pq(a, b, t, rl, rr, rt, rb, A, B, ifx, ify, fx, 1.0, 0.0)
    s = p / q
    return s if s < inf else inf


@nb.njit(**_INL)
def _ratios(z, v, u):
    h, w = z.shape
    zq = np.float64(z[v, u])
    rl = np.float64(z[v, u - 1]) / zq if u > 0 else np.nan
    rr = np.float64(z[v, u + 1]) / zq if u + 1 < w else np.nan
    rt = np.float64(z[v - 1, u]) / zq if v > 0 else np.nan
    rb = np.float64(z[v + 1, u]) / zq if v + 1 < h else np.nan
    return rl, rr, rt, rb


@nb.njit(**_INL)
def _select_pixel(z, normals, key, offs, fx, fy, cx, cy, v, u, selfw, eps, out):
    """The selection at one pixel, any neighbourhood (``offs[0]`` is the pixel itself).

    A candidate that beats the best key is taken when it passes the consistency test
    (``eps`` >= 0; :func:`inconsistency`): ``S_candidate < S_own + eps``. The test is off with
    ``eps < 0``, and skipped where the pixel has no normal or ``S_own`` is infinite.
    """
    zq = z[v, u]
    if not (zq == zq):
        _nan3(out, v, u)
        return
    rl, rr, rt, rb = _ratios(z, v, u)
    A = u - cx
    B = v - cy
    ifx = 1.0 / fx
    ify = 1.0 / fy
    s_own = np.inf
    if eps >= 0.0 and normals[v, u, 0] == normals[v, u, 0]:
        s_own = inconsistency(np.float64(normals[v, u, 0]), np.float64(normals[v, u, 1]),
                              np.float64(normals[v, u, 2]), rl, rr, rt, rb, A, B, ifx, ify, fx,
                              np.inf)
    best = np.inf
    bv = np.int64(v)
    bu = np.int64(u)
    for k in range(offs.shape[0]):
        r = v + offs[k, 0]
        c = u + offs[k, 1]
        if not _ok(z, normals, r, c):
            continue
        kk = clamp_key(key[r, c], _KEY_MAX)
        kk = kk * selfw if k == 0 else kk
        if not (kk < best):
            continue
        if k > 0 and s_own < np.inf:
            s = inconsistency(np.float64(normals[r, c, 0]), np.float64(normals[r, c, 1]),
                              np.float64(normals[r, c, 2]), rl, rr, rt, rb, A, B, ifx, ify,
                              fx, np.inf)
            if not (s < s_own + eps):
                continue
        best = kk
        bv = r
        bu = c
    if best < np.inf:
        store_normal(out, v, u, np.float64(normals[bv, bu, 0]), np.float64(normals[bv, bu, 1]),
                     np.float64(normals[bv, bu, 2]), A * zq / fx, B * zq / fy, zq)
    else:
        _nan3(out, v, u)


@nb.njit(**_INL)
def clamp_key(k, big):
    """A valid candidate's key: ``inf`` and NaN read as ``big`` (any valid candidate beats
    none; among keys >= ``big`` the first wins)."""
    return k if k < big else big


@nb.njit(**_INL)
def _key(kr, xr, big, inf):
    return clamp_key(kr, big) if xr == xr else inf


@nb.njit(**_INL)
def _pick(kr, k, ok, xr, yr, tr, x, y, t):
    """(key, normal) of the candidate if its key is strictly smaller and it passes ``ok``."""
    kr = np.float64(kr)
    tk = (kr < k) & ok
    return (kr if tk else k), (xr if tk else x), (yr if tk else y), (tr if tk else t)


@nb.njit(cache=True, error_model="numpy", fastmath={"nsz", "contract", "arcp"},
         inline="always")
def _cross_select(zp, zc, zn, px, py, pz, qx, qy, qz, nx, ny, nz, kp, kq, kn, acol, b, c, selfw,
                  eps, bx, by, bz, test):
    """Body of :func:`cross_select_row`; ``test`` (a constant in each caller): consistency."""
    one = c[1]
    inf = c[2]
    zero = c[4]
    fx = c[5]
    big = c[7]
    nan = zero * inf
    ifx = one / fx
    ify = one / c[6]
    bfy = b * ify
    for u in range(bx.size):
        i = u + 1
        zq = zc[i]
        A = acol[u]
        x = qx[i]
        y = qy[i]
        t = qz[i]
        ok1 = True
        ok2 = True
        ok3 = True
        ok4 = True
        if test:  # a constant in each of the two compiled versions below
            iz = one / zq
            rl = zc[i - 1] * iz
            rr = zc[i + 1] * iz
            rt = zp[i] * iz
            rb = zn[i] * iz
            # S_candidate < S_own + eps, cross-multiplied: one division per pixel
            p0, q0 = inconsistency_pq(x, y, t, rl, rr, rt, rb, A, b, ifx, ify, fx, one, zero)
            lim = p0 / q0 + eps
            free = not ((x == x) & (lim < inf))
            p1, q1 = inconsistency_pq(px[i], py[i], pz[i], rl, rr, rt, rb, A, b, ifx, ify, fx, one, zero)
            ok1 = free | (p1 < lim * q1)
            p2, q2 = inconsistency_pq(qx[i - 1], qy[i - 1], qz[i - 1], rl, rr, rt, rb, A, b, ifx,
                                      ify, fx, one, zero)
            ok2 = free | (p2 < lim * q2)
            p3, q3 = inconsistency_pq(qx[i + 1], qy[i + 1], qz[i + 1], rl, rr, rt, rb, A, b, ifx,
                                      ify, fx, one, zero)
            ok3 = free | (p3 < lim * q3)
            p4, q4 = inconsistency_pq(nx[i], ny[i], nz[i], rl, rr, rt, rb, A, b, ifx, ify, fx, one, zero)
            ok4 = free | (p4 < lim * q4)
        k = np.float64(_key(kq[i], x if zq == zq else nan, big, inf)) * selfw
        xr = px[i]
        k, x, y, t = _pick(_key(kp[i], xr if zp[i] == zp[i] else nan, big, inf), k, ok1, xr,
                           py[i], pz[i], x, y, t)
        xr = qx[i - 1]
        k, x, y, t = _pick(_key(kq[i - 1], xr if zc[i - 1] == zc[i - 1] else nan, big, inf),
                           k, ok2, xr, qy[i - 1], qz[i - 1], x, y, t)
        xr = qx[i + 1]
        k, x, y, t = _pick(_key(kq[i + 1], xr if zc[i + 1] == zc[i + 1] else nan, big, inf),
                           k, ok3, xr, qy[i + 1], qz[i + 1], x, y, t)
        xr = nx[i]
        k, x, y, t = _pick(_key(kn[i], xr if zn[i] == zn[i] else nan, big, inf), k, ok4, xr,
                           ny[i], nz[i], x, y, t)
        nrm = np.sqrt(x * x + y * y + t * t)
        inv = one / nrm
        inv = -inv if x * (A * ifx) + y * bfy + t > zero else inv
        inv = inv if (zq == zq) & (k < inf) else nan
        bx[u] = x * inv
        by[u] = y * inv
        bz[u] = t * inv


@nb.njit(cache=True, error_model="numpy", fastmath={"nsz", "contract", "arcp"})
def _cross_plain(zp, zc, zn, px, py, pz, qx, qy, qz, nx, ny, nz, kp, kq, kn, acol, b, c, selfw,
                 eps, bx, by, bz):
    _cross_select(zp, zc, zn, px, py, pz, qx, qy, qz, nx, ny, nz, kp, kq, kn, acol, b, c, selfw,
                  eps, bx, by, bz, False)


@nb.njit(cache=True, error_model="numpy", fastmath={"nsz", "contract", "arcp"})
def _cross_consistent(zp, zc, zn, px, py, pz, qx, qy, qz, nx, ny, nz, kp, kq, kn, acol, b, c,
                      selfw, eps, bx, by, bz):
    _cross_select(zp, zc, zn, px, py, pz, qx, qy, qz, nx, ny, nz, kp, kq, kn, acol, b, c, selfw,
                  eps, bx, by, bz, True)


@nb.njit(cache=True, error_model="numpy")
def cross_select_row(zp, zc, zn, px, py, pz, qx, qy, qz, nx, ny, nz, kp, kq, kn, acol, b, c,
                     selfw, eps, bx, by, bz):
    """The cross selection (self, up, left, right, down) of one row from padded planar rows.

    ``zp, zc, zn``: depth of the rows above, at and below; ``px, py, pz`` / ``qx, qy, qz`` /
    ``nx, ny, nz``: their normal components; ``kp, kq, kn``: their keys; all indexed
    ``u + 1`` (columns 0 and W + 1 are padding: NaN). A candidate is valid where its depth
    and normal are. Rule (as :func:`_select_pixel`): keys clamped (:func:`clamp_key`) and
    compared in float64, self first with its key times ``selfw``, a candidate taken when its
    key is strictly smaller and (``eps >= 0``) it passes the consistency test against the
    pixel's own normal. The winner is renormalised and turned toward the camera; NaN where
    none or where the pixel's depth is invalid. ``c``: constants (.., 1 at [1], inf at [2],
    0 at [4], fx at [5], fy at [6], the dtype's largest float at [7]).
    """
    if eps >= 0.0:
        _cross_consistent(zp, zc, zn, px, py, pz, qx, qy, qz, nx, ny, nz, kp, kq, kn, acol, b,
                          c, selfw, eps, bx, by, bz)
    else:
        _cross_plain(zp, zc, zn, px, py, pz, qx, qy, qz, nx, ny, nz, kp, kq, kn, acol, b, c,
                     selfw, eps, bx, by, bz)


@nb.njit(cache=True, error_model="numpy")
def fill_padded(zrow, nrow, krow, zb, nb3, kb):
    """Copy one row of depth, (interleaved) normals and keys into padded planar buffers."""
    w = zrow.size
    for u in range(w):
        zb[u + 1] = zrow[u]
        kb[u + 1] = krow[u]
    for j in range(3):
        for u in range(w):
            nb3[j, u + 1] = nrow[u, j]


@nb.njit(**_JIT)
def _select_rows(v0, v1, z, normals, key, offs, cross, fx, fy, cx, cy, c, acol, bcol, selfw,
                 eps, out):
    h, w = z.shape
    if not cross:
        for v in range(v0, v1):
            for u in range(w):
                _select_pixel(z, normals, key, offs, fx, fy, cx, cy, v, u, selfw, eps, out)
        return
    # ring of padded planar rows (slot r % 3; slot 3 stays NaN: rows outside the image)
    zb = np.full((4, w + 2), np.nan, dtype=z.dtype)
    nb3 = np.full((4, 3, w + 2), np.nan, dtype=normals.dtype)
    kb = np.full((4, w + 2), np.inf, dtype=key.dtype)
    bx = np.empty(w, dtype=normals.dtype)
    by = np.empty(w, dtype=normals.dtype)
    bz = np.empty(w, dtype=normals.dtype)
    for r in range(max(v0 - 1, 0), min(v1 + 1, h)):
        fill_padded(z[r], normals[r], key[r], zb[r % 3], nb3[r % 3], kb[r % 3])
        for q in range(r - 1, r + 1 if r == h - 1 else r):  # the last row has none below
            if v0 <= q < v1:
                select_ring_row(q, h, zb, nb3, kb, acol, bcol, c, selfw, eps, bx, by, bz, out)


@nb.njit(cache=True, error_model="numpy")
def select_ring_row(q, h, zb, nb3, kb, acol, bcol, c, selfw, eps, bx, by, bz, out):
    """:func:`cross_select_row` for row ``q`` from ring buffers (slot ``row % 3``, slot 3:
    outside the image) of padded depth ``zb``, planar normals ``nb3`` and keys ``kb``, once
    rows q - 1 .. q + 1 are in them; the result goes into ``bx, by, bz`` and (unless
    ``out`` is None) ``out[q]``."""
    a = (q - 1) % 3 if q > 0 else 3
    s = (q + 1) % 3 if q + 1 < h else 3
    m = q % 3
    cross_select_row(zb[a], zb[m], zb[s], nb3[a, 0], nb3[a, 1], nb3[a, 2], nb3[m, 0], nb3[m, 1],
                     nb3[m, 2], nb3[s, 0], nb3[s, 1], nb3[s, 2], kb[a], kb[m], kb[s], acol,
                     bcol[q], c, selfw, eps, bx, by, bz)
    if out is None:
        return
    for u in range(bx.size):
        out[q, u, 0] = bx[u]
        out[q, u, 1] = by[u]
        out[q, u, 2] = bz[u]


def select_min(z, normals, key, offs, fx, fy, cx, cy, out, self_weight=1.0, consistency=None):
    """Each valid pixel takes the normal of the candidate with the least ``key`` (self first).

    The pixel's own key is multiplied by ``self_weight`` first (1: plain arg-min, the pixel
    winning ties; < 1: a neighbour must be clearly better). ``consistency`` (footprints^2,
    None: off): a neighbour is taken only if its normal fits the pixel's depth about as well
    as the pixel's own (:func:`inconsistency`). Writes every pixel of ``out`` (NaN at
    invalid depth and where no candidate exists). ``z`` as
    :func:`depthnormals.estimators._common.row_dtype` gives it.
    """
    cross = offs.shape == CROSS.shape and bool((offs == CROSS).all())
    c, acol, bcol = row_arrays(z, fx, fy, cx, cy)
    eps = -1.0 if consistency is None else float(consistency)
    run_rows(_select_rows, z.shape[0], z, normals, key, offs, cross, float(fx), float(fy), float(cx),
             float(cy), c, acol, bcol, float(self_weight), eps, out)


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


@nb.njit(**_JIT)
def _crf_ring_rows(v0, v1, z, cur, anchor, anchored, kq, a, b, sigma, lam, fx, fy, cx, cy, out):
    """The cross-candidate CRF of rows [v0, v1) through the ring kernels of
    :mod:`depthnormals.ddm.crf_ring` (the fused 3F2N+ pipeline calls the same ones)."""
    h, w = z.shape
    zb = np.full((4, w + 2), np.nan, dtype=z.dtype)  # slot r % 3; slot 3: outside
    sel = np.full((5, 3, w + 2), np.nan, dtype=np.float32)  # slot r % 4; slot 4: outside
    sim = np.zeros((5, w + 2), dtype=np.float32)
    hsum = np.zeros((5, w), dtype=np.float32)
    anc = np.full((3, w + 2), np.nan, dtype=np.float32)
    idx, g, pos = scratch(w)
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
            sa, sm, sn = ring_slots(q, h)
            if not anchored:
                for j in range(3):
                    for u in range(w):
                        anc[j, u + 1] = anchor[q, u, j]
            pend = crf_ring_row(q, sa, sm, sn, z, kq[q], sel, sim, hsum,
                                sel[sm] if anchored else anc, anchored, sigma, lam, idx, g, pos,
                                pend, fx, fy, cx, cy, out)
    crf_flush(z, g, pos, pend, sigma, fx, fy, cx, cy, out)


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
                 float(fx), float(fy), float(cx), float(cy), out)
        return
    run_rows(_crf_rows, z.shape[0], z, cur, anchor, cur is anchor, kq, int(sim_mode), tau,
             float(sigma), float(lam), offs, float(fx), float(fy), float(cx), float(cy), out)
