"""Box-fit: least-squares planes in inverse depth over box windows, at box-filter cost.

Ours, not the paper's: the noisy branch of the default selection.

A plane ``n . X = d`` seen by a pinhole camera makes inverse depth exactly linear in the
pixel coordinates (NOTES section 2, 3F2N):

    w = 1 / z = a (u - u_c) + b (v - v_c) + c,   n ~ (fx a, fy b, c - a (u_c - cx) - b (v_c - cy))

(``(u_c, v_c)`` any reference pixel, here the window centre; the sign is then turned toward
the camera). So an ordinary least-squares fit of ``(a, b, c)`` to the valid pixels of a
``(2 r + 1)^2`` window gives the plane's normal from ten sums - ``1, du, dv, du^2, du dv,
dv^2, w, du w, dv w, w^2`` with ``du, dv`` window-local - and the residual sum of squares
``RSS = sum w^2 - (a sum du w + b sum dv w + c sum w)`` from the same sums. The sums are
separable: a row pass (six sums over ``du``) and a column pass (ten over ``dv``) per pixel,
like a box filter; nothing loops over candidate normals.

Edge awareness (Kuwahara-like): every pixel ``q`` then chooses among the windows that contain
it - the window centred on ``q`` and the eight centred at ``q + s (i, j)``, ``i, j`` in
``{-1, 0, 1}``, ``s <= r``, which hold ``q`` at an edge or corner. The centred window
(unbiased on curved surfaces) is kept outright while its residual variance ``RSS / (N - 3)``
(footprints^2, ``(z / fx)^2``) is within ``gate``. Otherwise, without a noise level, the
window of least residual variance wins (the centred one's multiplied by ``self_weight``);
with a noise level ``sigma`` (footprints), the window whose plane best explains the pixel's
own 3x3 neighbourhood wins: the sum over its valid pixels of the squared residual of ``1/z``
in units of ``sigma^2`` (footprints), each capped at :data:`LOCAL_CAP` (the plane-fit
selection's criterion, over nine precomputed planes). Optionally a large centred window
(``big_radius``) is taken first wherever its residual variance is within ``big_gate``: one
plane within the noise, where the larger support wins. The normal of the chosen window is
the pixel's normal.

This is FALS's estimate in another parametrisation (FALS fits ``1 / r`` over unit rays) with
the window choice of the plane-fit selection (:mod:`depthnormals.ddm.planefit`) reduced to
nine precomputed windows. Ours (issue 13); measured in docs/3f2n-plus.md.
"""

from __future__ import annotations

import math
from typing import Any

import numba as nb
import numpy as np

from .._parallel import run_rows
from .._validate import check_int, check_real
from ..kernels.depth import prepare
from ..kernels.eig3 import sym3_adjugate_apply
from ..kernels.orient import store_nan, store_normal

__all__ = ["LOCAL_CAP", "SHIFTS", "box_fit_normals", "box_fit_windows", "choose_windows"]

_JIT = {"cache": True, "nogil": True, "error_model": "numpy"}
# no reassociation: with it, code compiled in the process and the same code loaded from
# numba's cache rounded the windows' sums differently (session 39: the residual scores of a
# kinect_v2 frame at 80 of 217,088 pixels, 1 ulp; without it the default's time did not
# move, one thread: tests/test_numba_cache.py); no-NaN flags are never allowed
_FASTMATH = {"contract", "nsz", "arcp"}
#: The fewest valid pixels a window needs (three parameters, a residual of >= 3 degrees).
MIN_POINTS = 6

#: Local choice: the squared residual of one pixel of the 3x3, in noise variances, counts at
#: most this much (5 sigma: another surface costs the same whatever its distance).
LOCAL_CAP = 25.0

#: Window-centre offsets (dv, du) in units of the shift ``s``, the centred window first
#: (it wins ties).
SHIFTS = np.array([[0, 0], [-1, 0], [0, -1], [0, 1], [1, 0], [-1, -1], [-1, 1], [1, -1],
                   [1, 1]], dtype=np.int64)

#: The column running sums of :func:`_fit_rows` restart with direct sums at every row that
#: is a multiple of this, so their rounding is the same however the rows are split into bands.
RESTART = 64

# Row sums (index of the first axis of a ring slot), over the valid pixels of the row
# segment u - r .. u + r: count, sum du, sum du^2, sum w, sum du w, sum w^2.
_R_N, _R_U, _R_UU, _R_W, _R_UW, _R_WW = range(6)


#: The row sums run in this many interleaved segments (independent recurrences side by side).
SEGMENTS = 4


@nb.njit(cache=True, error_model="numpy", inline="always", fastmath=_FASTMATH)
def _seg_start(xm, xw, s, r, o):
    """Direct row sums of the window centred at pixel ``s`` (the start of a segment)."""
    t0m = 0.0
    t1m = 0.0
    t2m = 0.0
    t0w = 0.0
    t1w = 0.0
    t0q = 0.0
    for k in range(-r, r + 1):
        m = xm[s + k + o]
        x = xw[s + k + o]
        t0m += m
        t1m += k * m
        t2m += k * k * m
        t0w += x
        t1w += k * x
        t0q += x * x
    return t0m, t1m, t2m, t0w, t1w, t0q


@nb.njit(cache=True, error_model="numpy", inline="always", fastmath=_FASTMATH)
def _seg_step(st, xm, xw, u, r):
    """The six row sums at pixel ``u`` from those at ``u - 1`` (recurrences of :func:`_row_sums`)."""
    t0m, t1m, t2m, t0w, t1w, t0q = st
    rf = np.float64(r)
    r1 = rf + 1.0
    em = xm[u + 2 * r + 1]
    lm = xm[u]
    ew = xw[u + 2 * r + 1]
    lw = xw[u]
    n0 = t0m + em - lm
    s1 = t1m + rf * lm + r1 * em
    t2m = t2m - rf * rf * lm + r1 * r1 * em - 2.0 * s1 + n0
    t1m = s1 - n0
    t0m = n0
    n0 = t0w + ew - lw
    t1w = t1w + rf * lw + r1 * ew - n0
    t0w = n0
    t0q = t0q + ew * ew - lw * lw
    return t0m, t1m, t2m, t0w, t1w, t0q


@nb.njit(cache=True, error_model="numpy", inline="always")
def _seg_put(out_rs, u, w, st):
    if u < w:
        out_rs[_R_N, u] = st[0]
        out_rs[_R_U, u] = st[1]
        out_rs[_R_UU, u] = st[2]
        out_rs[_R_W, u] = st[3]
        out_rs[_R_UW, u] = st[4]
        out_rs[_R_WW, u] = st[5]


@nb.njit(cache=True, nogil=True, error_model="numpy", fastmath=_FASTMATH)
def _row_sums(zrow, r, xm, xw, out_rs):
    """The six row sums of one depth row (``zrow``, NaN invalid) for half-width ``r``, as
    running sums: O(1) per pixel whatever ``r``. ``xm``, ``xw`` scratch of at least
    ``SEGMENTS ceil(W / SEGMENTS) + 2 r + 2`` (pixel u at index u + r + 1; the rest is zeroed
    here); writes ``out_rs`` (6, W).

    Moving the window from u to u + 1 (entering value e, leaving value l, sums over the
    local offsets k of ``x``, ``k x``, ``k^2 x``): ``T0' = T0 + e - l``,
    ``T1' = T1 + r l + (r + 1) e - T0'``,
    ``T2' = T2 - r^2 l + (r + 1)^2 e - 2 (T1 + r l + (r + 1) e) + T0'``.
    The row runs as :data:`SEGMENTS` segments side by side, each started by direct sums, so
    the recurrences do not wait on each other (the rounding depends only on the column).
    """
    w = zrow.size
    o = r + 1
    for u in range(w):
        zz = np.float64(zrow[u])
        ok = zz == zz
        xw[u + o] = 1.0 / zz if ok else 0.0
        xm[u + o] = 1.0 if ok else 0.0
    for u in range(w + o, xm.size):
        xw[u] = 0.0
        xm[u] = 0.0
    seg = (w + SEGMENTS - 1) // SEGMENTS
    a = _seg_start(xm, xw, 0, r, o)
    b = _seg_start(xm, xw, seg, r, o)
    c = _seg_start(xm, xw, 2 * seg, r, o)
    d = _seg_start(xm, xw, 3 * seg, r, o)
    _seg_put(out_rs, 0, w, a)
    _seg_put(out_rs, seg, w, b)
    _seg_put(out_rs, 2 * seg, w, c)
    _seg_put(out_rs, 3 * seg, w, d)
    for t in range(1, seg):
        a = _seg_step(a, xm, xw, t, r)
        b = _seg_step(b, xm, xw, seg + t, r)
        c = _seg_step(c, xm, xw, 2 * seg + t, r)
        d = _seg_step(d, xm, xw, 3 * seg + t, r)
        _seg_put(out_rs, t, w, a)
        _seg_put(out_rs, seg + t, w, b)
        _seg_put(out_rs, 2 * seg + t, w, c)
        _seg_put(out_rs, 3 * seg + t, w, d)


@nb.njit(cache=True, error_model="numpy", inline="always")
def solve_window(n, su, sv, suu, suv, svv, sw, suw, svw, sww):
    """Least squares ``w = a du + b dv + c`` from the ten sums: (a, b, c, RSS, ok), ``ok``
    False where the window has fewer than :data:`MIN_POINTS` points or is degenerate
    (collinear); branch-free (the values are then meaningless)."""
    # normal equations: [[suu suv su] [suv svv sv] [su sv n]] (a, b, c) = (suw, svw, sw)
    x, y, t, det = sym3_adjugate_apply(suu, suv, su, svv, sv, n, suw, svw, sw)
    ok = (n >= MIN_POINTS) & (det > 1e-9 * n * n * n)
    inv = 1.0 / (det if ok else 1.0)
    a = x * inv
    b = y * inv
    c = t * inv
    rss = sww - (a * suw + b * svw + c * sw)
    return a, b, c, (rss if rss > 0.0 else 0.0), ok


@nb.njit(cache=True, nogil=True, error_model="numpy", fastmath=_FASTMATH)
def _solve_row(t0, t1m0, t1m1, t1w, t2m0, fx, fy, acol, bv, out_x, out_y, out_z, out_s, out_a,
               out_b, out_c):
    """Fits of one row from its window sums (``t0`` (6, W): the column sums of the six row
    sums; ``t1*``: the dv-weighted ones; ``t2m0``: sum dv^2): unit normals facing the camera
    into ``out_x, out_y, out_z`` (NaN: no fit), residual variances in footprints^2 into
    ``out_s`` (inf: no fit), the plane ``(a, b, c)`` into ``out_a, out_b, out_c``.
    Branch-free, so it vectorises."""
    nan = np.nan
    inf = np.inf
    ifx = 1.0 / fx
    ify = 1.0 / fy
    for u in range(acol.size):
        n = t0[_R_N, u]
        a, b, c, rss, ok = solve_window(n, t0[_R_U, u], t1m0[u], t0[_R_UU, u], t1m1[u], t2m0[u],
                                        t0[_R_W, u], t0[_R_UW, u], t1w[u], t0[_R_WW, u])
        au = acol[u]
        nx = fx * a
        ny = fy * b
        nz = c - a * au - b * bv
        n2 = nx * nx + ny * ny + nz * nz
        # (no fit where the normal's length under- or overflows: depths near float64's limits)
        good = ok & (c > 0.0) & (n2 > 0.0) & (n2 < inf)
        s = 1.0 / np.sqrt(n2)
        # n . ray = c, the plane's inverse depth at the pixel (> 0 where ``good``): never the
        # orientation's tie (kernels.orient.TIE_COS), so its sign decides
        s = -s if nx * au * ifx + ny * bv * ify + nz > 0.0 else s
        out_x[u] = nx * s if good else nan
        out_y[u] = ny * s if good else nan
        out_z[u] = nz * s if good else nan
        out_s[u] = rss * (fx * fx) / ((n - 3.0) * c * c) if good else inf
        out_a[u] = a
        out_b[u] = b
        out_c[u] = c


@nb.njit(cache=True, nogil=True, error_model="numpy", fastmath=_FASTMATH)
def _solve_row_planes(t0, t1m0, t1m1, t1w, t2m0, fx, out_s, out_a, out_b, out_c):
    """:func:`_solve_row` without the normals (residual variances and planes only)."""
    inf = np.inf
    for u in range(out_s.size):
        n = t0[_R_N, u]
        a, b, c, rss, ok = solve_window(n, t0[_R_U, u], t1m0[u], t0[_R_UU, u], t1m1[u], t2m0[u],
                                        t0[_R_W, u], t0[_R_UW, u], t1w[u], t0[_R_WW, u])
        good = ok & (c > 0.0)
        out_s[u] = rss * (fx * fx) / ((n - 3.0) * c * c) if good else inf
        out_a[u] = a
        out_b[u] = b
        out_c[u] = c


@nb.njit(cache=True, error_model="numpy")
def _run_moments(t0, t1, t2, e, lv, rf, r1):
    """Running column sums of a count: ``sum 1``, ``sum dv``, ``sum dv^2`` when row
    ``v + r`` (``e``) enters and ``v - r - 1`` (``lv``) leaves (:func:`_row_sums`'s
    recurrences)."""
    for u in range(t0.size):
        em = e[u]
        lm = lv[u]
        n0 = t0[u] + em - lm
        s1 = t1[u] + rf * lm + r1 * em
        t2[u] = t2[u] - rf * rf * lm + r1 * r1 * em - 2.0 * s1 + n0
        t1[u] = s1 - n0
        t0[u] = n0


@nb.njit(cache=True, error_model="numpy")
def _run_first(t0, t1, e, lv, rf, r1):
    """Running column sums ``sum x``, ``sum dv x`` (as :func:`_run_moments`)."""
    for u in range(t0.size):
        eu = e[u]
        lu = lv[u]
        n0 = t0[u] + eu - lu
        t1[u] = t1[u] + rf * lu + r1 * eu - n0
        t0[u] = n0


@nb.njit(cache=True, error_model="numpy")
def _run_plain(t0, e, lv):
    """Running column sum ``sum x``."""
    for u in range(t0.size):
        t0[u] += e[u] - lv[u]


@nb.njit(**_JIT)
def _fit_rows(v0, v1, z, fx, fy, cx, cy, r, out_n, out_score, out_plane, want_plane, want_n):
    """Rows ``[v0, v1)`` of the centred-window fits: ``out_n`` (3, H, W) float32 planar unit
    normals facing the camera (NaN: no fit), ``out_score`` (H, W) float32 residual variance
    ``RSS / (N - 3)`` in footprints^2 ``(fx / c)^2`` (inf: no fit).

    Row sums (:func:`_row_sums`) go into a ring of ``2 r + 2`` rows; the column sums are
    running sums down the band with the recurrences of :func:`_row_sums` (``dv`` for ``du``),
    started by direct sums at every row that is a multiple of :data:`RESTART` (a band
    starting between two begins at the one before it): O(1) per pixel whatever ``r``, and
    the rounding of the running sums does not depend on how the rows are split into bands
    (a batch frame and a single call give the same bits).
    """
    h, w = z.shape
    span = 2 * r + 2
    ring = np.zeros((span, 6, w))
    zero = np.zeros((6, w))
    xm = np.zeros(SEGMENTS * ((w + SEGMENTS - 1) // SEGMENTS) + 2 * r + 2)
    xw = np.zeros_like(xm)
    t0 = np.zeros((6, w))
    t1m0 = np.zeros(w)
    t1m1 = np.zeros(w)
    t1w = np.zeros(w)
    t2m0 = np.zeros(w)
    acol = np.arange(w) - cx
    pl = out_plane if want_plane else np.empty((3, 1, w), dtype=np.float32)  # scratch
    only_c = want_plane and out_plane.shape[0] == 1
    ab = np.empty((2, w if only_c else 1), dtype=np.float32)  # the slopes: only centres wanted
    nn = out_n if want_n else np.empty((3, 1, w), dtype=np.float32)
    rf = np.float64(r)
    r1 = rf + 1.0
    start = (v0 // RESTART) * RESTART
    nxt = max(start - r, 0)
    for v in range(start, v1):
        while nxt <= min(v + r, h - 1):
            _row_sums(z[nxt], r, xm, xw, ring[nxt % span])
            nxt += 1
        if v % RESTART == 0:  # direct sums over dv = -r .. r
            t0[:] = 0.0
            t1m0[:] = 0.0
            t1m1[:] = 0.0
            t1w[:] = 0.0
            t2m0[:] = 0.0
            for dv in range(-r, r + 1):
                row = v + dv
                if row < 0 or row >= h:
                    continue
                rs = ring[row % span]
                k = np.float64(dv)
                for u in range(w):
                    for j in range(6):
                        t0[j, u] += rs[j, u]
                    t1m0[u] += k * rs[_R_N, u]
                    t1m1[u] += k * rs[_R_U, u]
                    t1w[u] += k * rs[_R_W, u]
                    t2m0[u] += k * k * rs[_R_N, u]
        else:  # running: row v + r enters, row v - r - 1 leaves
            e = ring[(v + r) % span] if v + r < h else zero
            lv = ring[(v - r - 1) % span] if v - r - 1 >= 0 else zero
            # one quantity per loop: few arrays per loop, so LLVM's runtime alias checks stay
            # within its limit and every loop vectorises (one loop over all was scalar)
            _run_moments(t0[_R_N], t1m0, t2m0, e[_R_N], lv[_R_N], rf, r1)
            _run_first(t0[_R_U], t1m1, e[_R_U], lv[_R_U], rf, r1)
            _run_first(t0[_R_W], t1w, e[_R_W], lv[_R_W], rf, r1)
            _run_plain(t0[_R_UU], e[_R_UU], lv[_R_UU])
            _run_plain(t0[_R_UW], e[_R_UW], lv[_R_UW])
            _run_plain(t0[_R_WW], e[_R_WW], lv[_R_WW])
        if v < v0:  # rows before the band: only to carry the running sums to v0
            continue
        vp = v if want_plane else 0
        pa = ab[0] if only_c else pl[0, vp]
        pb = ab[1] if only_c else pl[1, vp]
        pc = pl[0, vp] if only_c else pl[2, vp]
        if want_n:
            _solve_row(t0, t1m0, t1m1, t1w, t2m0, fx, fy, acol, v - cy, nn[0, v], nn[1, v], nn[2, v],
                       out_score[v], pa, pb, pc)
        else:
            _solve_row_planes(t0, t1m0, t1m1, t1w, t2m0, fx, out_score[v], pa, pb, pc)


def box_fit_windows(z: np.ndarray, fx: float, fy: float, cx: float, cy: float,
                    radius: int, *, planes: bool = False, centres: bool = False,
                    normals: bool = True) -> tuple[np.ndarray, ...]:
    """Centred-window fits of prepared depth ``z`` (NaN invalid): planar normals (3, H, W)
    float32 (NaN where a window has no fit) and residual variances (H, W) float32 in
    footprints^2 (inf there). A window needs :data:`MIN_POINTS` valid pixels, not the
    centre's. With ``planes``, also the fitted ``(a, b, c)`` of every window, (3, H, W)
    float32 (``w = a du + b dv + c`` around its centre); with ``centres`` (and not
    ``planes``), only ``c``, the fitted ``1 / z`` at each window's centre, (H, W) float32.
    ``normals=False`` leaves the normals out (an empty (3, 1, W) array is returned in their
    place)."""
    h, w = z.shape
    out_n = np.empty((3, h, w) if normals else (3, 1, w), dtype=np.float32)
    out_s = np.empty((h, w), dtype=np.float32)
    shape = (3, h, w) if planes else ((1, h, w) if centres else (3, 1, w))
    out_p = np.empty(shape, dtype=np.float32)
    run_rows(_fit_rows, h, z, float(fx), float(fy), float(cx), float(cy), int(radius), out_n,
             out_s, out_p, planes or centres, normals, min_rows=16)
    if planes:
        return out_n, out_s, out_p
    return (out_n, out_s, out_p[0]) if centres else (out_n, out_s)


@nb.njit(**_JIT)
def _choose_rows(v0, v1, z, fit_n, score, big_n, big_score, shift, gate, big_gate, self_weight,
                 fx, fy, cx, cy, out):
    """Rows ``[v0, v1)`` of the window choice (see :func:`choose_windows`)."""
    h, w = z.shape
    use_big = big_score.shape[0] == h
    for v in range(v0, v1):
        for u in range(w):
            zq = z[v, u]
            if not (zq == zq):
                store_nan(out, v, u)
                continue
            if use_big and np.float64(big_score[v, u]) <= big_gate:
                store_normal(out, v, u, np.float64(big_n[0, v, u]), np.float64(big_n[1, v, u]),
                             np.float64(big_n[2, v, u]), (u - cx) / fx, (v - cy) / fy, 1.0)
                continue
            s0 = np.float64(score[v, u])
            bv = v
            bu = u
            best = s0 * self_weight
            if not (s0 <= gate):
                for k in range(1, SHIFTS.shape[0]):
                    r = v + shift * SHIFTS[k, 0]
                    c = u + shift * SHIFTS[k, 1]
                    if r < 0 or r >= h or c < 0 or c >= w:
                        continue
                    sk = np.float64(score[r, c])
                    if sk < best:
                        best = sk
                        bv = r
                        bu = c
            if not (best < np.inf):
                store_nan(out, v, u)
                continue
            store_normal(out, v, u, np.float64(fit_n[0, bv, bu]), np.float64(fit_n[1, bv, bu]),
                         np.float64(fit_n[2, bv, bu]), (u - cx) / fx, (v - cy) / fy, 1.0)


@nb.njit(**_JIT, fastmath=_FASTMATH)
def _choose_local_rows(v0, v1, z, score, plane, big_n, big_score, shift, gates, tiles, cap, cam,
                       out):
    """Rows of :func:`choose_windows` with ``plane``: among the nine windows the one whose plane
    explains the pixel's own 3x3 best (truncated squared residuals in noise units).
    ``gates`` is ``(gate, big_gate, inv_var)`` at the reference noise; ``tiles`` is
    ``(scale, tile)``: the variance of each ``tile x tile`` tile over the reference (a (1, 1)
    map of 1 with a tile over the image: one level), scaling the three per pixel.
    ``cam`` is ``(fx, fy, cx, cy)``; writes ``out`` rows ``v0 .. v1 - 1``."""
    fx, fy, cx, cy = cam
    gate0, big_gate0, inv_var = gates
    scale, tile = tiles
    h, w = z.shape
    fsd0 = fx * math.sqrt(inv_var)
    tcol = np.empty(w, dtype=np.int64)
    for u in range(w):
        tcol[u] = u // tile
    pz = np.empty(9)
    ka = np.empty(9)
    kb = np.empty(9)
    kc = np.empty(9)
    sk = np.empty(9)
    kv = np.empty(9, dtype=np.int64)
    ku = np.empty(9, dtype=np.int64)
    pu = np.empty(9)
    pv = np.empty(9)
    nan = np.nan
    for v in range(v0, v1):
        for u in range(w):  # the large windows' normals (already facing the camera)
            ok = z[v, u] == z[v, u]
            out[v, u, 0] = big_n[0, v, u] if ok else nan
            out[v, u, 1] = big_n[1, v, u] if ok else nan
            out[v, u, 2] = big_n[2, v, u] if ok else nan
        trow = scale[v // tile]
        for u in range(w):
            zq = z[v, u]
            f = trow[tcol[u]]
            if not (zq == zq) or np.float64(big_score[v, u]) <= big_gate0 * f:
                continue
            bv = v
            bu = u
            if not (np.float64(score[v, u]) <= gate0 * f):
                fsd = fsd0 / math.sqrt(f)
                m = 0  # the valid pixels of the 3x3: depth and position
                for dv in range(-1, 2):
                    a = v + dv
                    if a < 0 or a >= h:
                        continue
                    for du in range(-1, 2):
                        b = u + du
                        if b < 0 or b >= w:
                            continue
                        zp = np.float64(z[a, b])
                        if zp == zp:
                            pz[m] = zp
                            pu[m] = b
                            pv[m] = a
                            m += 1
                nk = 0  # the nine windows' planes, then their scores side by side
                for k in range(SHIFTS.shape[0]):
                    r = v + shift * SHIFTS[k, 0]
                    c = u + shift * SHIFTS[k, 1]
                    if r < 0 or r >= h or c < 0 or c >= w or not (score[r, c] < np.inf):
                        continue
                    pa = np.float64(plane[0, r, c])
                    pb = np.float64(plane[1, r, c])
                    ka[nk] = pa
                    kb[nk] = pb
                    kc[nk] = np.float64(plane[2, r, c]) - pa * c - pb * r
                    kv[nk] = r
                    ku[nk] = c
                    sk[nk] = 0.0
                    nk += 1
                for i in range(m):  # (1/z - plane) (fx z / sigma) = fx / sigma - z plane fx / sigma
                    zi = pz[i] * fsd
                    ui = pu[i]
                    vi = pv[i]
                    for j in range(nk):  # independent sums: no serial chain
                        res = fsd - zi * (ka[j] * ui + kb[j] * vi + kc[j])
                        e = res * res
                        sk[j] += e if e < cap else cap
                best = np.inf
                for j in range(nk):  # the first of equal scores wins (the centred window)
                    if sk[j] < best:
                        best = sk[j]
                        bv = kv[j]
                        bu = ku[j]
                if not (best < np.inf):
                    store_nan(out, v, u)
                    continue
            if not (score[bv, bu] < np.inf):
                store_nan(out, v, u)
                continue
            pa = np.float64(plane[0, bv, bu])
            pb = np.float64(plane[1, bv, bu])
            store_normal(out, v, u, fx * pa, fy * pb,
                         np.float64(plane[2, bv, bu]) - pa * (bu - cx) - pb * (bv - cy),
                         (u - cx) / fx, (v - cy) / fy, 1.0)


def choose_windows(z: np.ndarray, fit_n: np.ndarray, score: np.ndarray, fx: float, fy: float,
                   cx: float, cy: float, *, shift: int, gate: float, self_weight: float,
                   out: np.ndarray, big: tuple[np.ndarray, np.ndarray] | None = None,
                   big_gate: float | None = None) -> None:
    """Every valid pixel takes the normal of the best of its nine windows (module doc).

    ``fit_n`` (3, H, W) and ``score`` (H, W) are the centred-window fits of
    :func:`box_fit_windows`.

    With ``big`` (the normals and scores of larger centred windows), a pixel whose large
    window has a residual variance ``<= big_gate`` (default ``gate``) takes the large
    window's normal first.

    The centred window is kept when its residual variance ``score`` is ``<= gate``; otherwise
    the window of least score among the nine wins, the centred one's score multiplied by
    ``self_weight`` first (it wins ties). Writes every pixel of ``out`` (H, W, 3) float32:
    NaN at invalid depth and where no window has a fit.
    """
    # none: no rows (a single row would read as present on an image of one row)
    big_n, big_s = big if big is not None else (fit_n[:, :0], score[:0])
    bg = gate if big_gate is None else big_gate
    run_rows(_choose_rows, z.shape[0], z, fit_n, score, big_n, big_s, int(shift), float(gate),
             float(bg), float(self_weight), float(fx), float(fy), float(cx), float(cy), out, min_rows=16)


def box_fit_from_prepared(z: np.ndarray, fx: float, fy: float, cx: float, cy: float, *,
                          radius: int, shift: int, gate: float, self_weight: float,
                          big_radius: int = 0, big_gate: float | None = None,
                          sigma: float | None = None,
                          sigma_tiles: tuple[np.ndarray, int] | None = None,
                          out_scores: list | None = None) -> np.ndarray:
    """:func:`box_fit_normals` on prepared depth. ``sigma_tiles`` ``(levels, tile)``: the noise
    of every ``tile x tile`` tile (footprints, NaN: ``sigma``;
    :func:`depthnormals.ddm.noise.noise_tiles`), with ``sigma`` given: ``gate``, ``big_gate``
    and the local choice's noise unit then scale per pixel with the tile's variance over
    ``sigma^2``. ``out_scores``: a list that receives the residual variances (H, W) of the
    ``radius`` windows and of the ``big_radius`` ones (all inf without them), for the
    uncertainty map (:mod:`depthnormals.ddm.uncertainty`); the normals do not change."""
    out = np.empty((z.shape[0], z.shape[1], 3), dtype=np.float32)
    if sigma is not None and sigma > 0.0:  # the local choice (needs the planes)
        _, score, plane = box_fit_windows(z, fx, fy, cx, cy, radius, planes=True, normals=False)
        if big_radius > radius:
            big_n, big_s = box_fit_windows(z, fx, fy, cx, cy, big_radius)
        else:
            big_n = np.empty((3, z.shape[0], z.shape[1]), dtype=np.float32)
            big_s = np.full_like(score, np.inf)
        bg = gate if big_gate is None else big_gate
        if sigma_tiles is None:
            tiles = (np.ones((1, 1)), max(z.shape) + 1)
        else:
            t, size = sigma_tiles
            tiles = (np.where(np.isfinite(t), (np.asarray(t, dtype=np.float64) / sigma) ** 2, 1.0),
                     int(size))
        run_rows(_choose_local_rows, z.shape[0], z, score, plane, big_n, big_s, int(shift),
                 (float(gate), float(bg), 1.0 / (sigma * sigma)), tiles, LOCAL_CAP,
                 (float(fx), float(fy), float(cx), float(cy)), out, min_rows=16)
        if out_scores is not None:
            out_scores.extend((score, big_s))
        return out
    fit_n, score = box_fit_windows(z, fx, fy, cx, cy, radius)
    big = box_fit_windows(z, fx, fy, cx, cy, big_radius) if big_radius > radius else None
    if out_scores is not None:
        out_scores.extend((score, big[1] if big is not None else np.full_like(score, np.inf)))
    choose_windows(z, fit_n, score, fx, fy, cx, cy, shift=shift, gate=gate,
                   self_weight=self_weight, out=out, big=big, big_gate=big_gate)
    return out


def box_fit_normals(depth: Any, K: Any, *, radius: int = 2, shift: int | None = None,
                    gate: float = 0.0, self_weight: float = 1.0, big_radius: int = 0,
                    sigma: float | None = None, depth_scale: float | None = None) -> np.ndarray:
    """Normals from least-squares planes in inverse depth over box windows (module doc).

    Parameters
    ----------
    depth : array_like, shape (H, W)
        Planar depth. float32/float64; integers need ``depth_scale``. Invalid depth (0,
        negative, NaN, inf) gives NaN and never enters a fit.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Intrinsics in pixels, 0-based pixel centres.
    radius : int in 1..8, default 2
        Windows of ``(2 radius + 1)^2`` pixels.
    shift : int in 0..radius, optional
        Offset of the eight shifted windows (default ``radius``: the pixel at their edge or
        corner). 0 keeps the centred window (a plain box fit, FALS-like).
    gate : float >= 0, default 0
        Residual variance (footprints^2) up to which the centred window is kept outright.
    self_weight : float in (0, 1], default 1
        The centred window's residual is multiplied by it before the comparison.
    big_radius : int in 0..16, default 0
        With ``big_radius > radius``: a pixel whose centred ``(2 big_radius + 1)^2`` window
        has a residual variance ``<= gate`` takes that window's normal (one plane within the
        noise: the larger support wins); 0: off.
    sigma : float > 0, optional
        Noise in footprints (:func:`depthnormals.estimate_noise`). Given, the nine windows
        are ranked by how well their planes explain the pixel's own 3x3 neighbourhood (the
        sum of squared residuals in units of ``sigma^2``, each capped at
        :data:`LOCAL_CAP`) instead of by their own residual variance; ``self_weight`` is then
        not used.
    depth_scale : float, optional
        Metres per unit of integer depth.

    Returns
    -------
    normals : ndarray, shape (H, W, 3), float32
        Unit normals facing the camera; NaN at invalid depth and where no window holds
        :data:`MIN_POINTS` valid pixels.

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals.analytic import tilted_plane
    >>> r = tilted_plane().render(shape=(40, 50), K=(60.0, 60.0, 24.5, 19.5))
    >>> n = box_fit_normals(r.depth, r.K)
    >>> bool(np.abs(n - r.normals).max() < 1e-5)
    True
    """
    rad = check_int(radius, "radius", minimum=1, maximum=8)
    sh = rad if shift is None else check_int(shift, "shift", minimum=0, maximum=rad)
    g = check_real(gate, "gate", minimum=0.0, finite=False)
    sw = check_real(self_weight, "self_weight", minimum=0.0, maximum=1.0)
    big = check_int(big_radius, "big_radius", minimum=0, maximum=16)
    sg = None if sigma is None else check_real(sigma, "sigma", minimum=0.0, finite=False)
    if sg == 0.0:
        raise ValueError("sigma must be > 0 (or None)")
    if sw == 0.0:
        raise ValueError("self_weight must be > 0")
    z, cam = prepare(depth, K, depth_scale)
    return box_fit_from_prepared(z, cam.fx, cam.fy, cam.cx, cam.cy, radius=rad, shift=sh,
                                 gate=g, self_weight=sw, big_radius=big, sigma=sg)
