"""The 3F2N row kernels, shared by the 3F2N estimator and the fused 3F2N+ pass.

:func:`row_normals` computes one row of 3F2N normals: the vectorised FD pass
(:func:`_fd_row`) over the interior and, for the pixels it flags, the general per-pixel path
(:func:`generic_normal`, the readable reference). :func:`row_setup` builds the arrays it reads.
"""

from __future__ import annotations

from collections import namedtuple

import numba as nb
import numpy as np

from .depth import C_FX, C_FY, C_HALF, C_INF, C_NINF, C_ONE, C_TIE2, C_ZERO, row_arrays
from .orient import faces_away, oriented_unit
from .stencils import roberts_gradient, stencil_derivative

__all__ = ["NEIGHBOURS8", "Filters", "RowInputs", "RowScratch", "central_tendency", "generic_normal",
           "median8_pair", "nz_candidates", "row_normals", "row_setup"]

#: What :func:`row_normals` reads: the depth ``z`` (H, W; NaN invalid), ``D`` (what the general
#: path differentiates: ``z`` itself with the FD pass, ``1 / z`` otherwise), ``R = 1 / z``, the
#: constants row ``c`` and ``acol[u] = u - cx``, ``bcol[v] = v - cy``
#: (:func:`depthnormals.kernels.depth.row_arrays`). :func:`row_setup` builds it.
RowInputs = namedtuple("RowInputs", ["z", "D", "R", "c", "acol", "bcol"])
#: How 3F2N differentiates and aggregates: derivative and smoothing taps
#: (:func:`depthnormals.kernels.stencils.gradient_kernels`), the Roberts cross, the
#: aggregate (0 median, 1 mean, 2 trimean, 3 trimmed mean), the vectorised FD pass, the
#: neighbour offsets (:data:`NEIGHBOURS8`).
Filters = namedtuple("Filters", ["deriv", "smooth", "roberts", "mode", "fast_fd", "nb_off"])
#: Scratch of :func:`row_normals`: ``steps`` (7, W) reciprocal depth steps
#: (two sets of down steps, one of right steps), ``flag`` (W) bool, ``cand`` (8) float64.
RowScratch = namedtuple("RowScratch", ["steps", "flag", "cand"])

#: Offsets (dv, du) of the 8-neighbourhood, row by row.
NEIGHBOURS8 = np.array([[-1, -1], [-1, 0], [-1, 1], [0, -1], [0, 1], [1, -1], [1, 0], [1, 1]],
                       dtype=np.int64)

# no-NaN/no-inf assumptions are never allowed: NaN marks invalid depth
_FASTMATH = {"nsz", "contract", "arcp"}
# The small helpers of the FD pass are compiled once each and called, not inlined by numba
# (``inline="always"`` copies and re-types their body at every call: 8 + 19 copies cost about
# 3 s of the first run); LLVM inlines them, with the same flags, into the same vector loop.
_FD_HELPER = {"cache": True, "error_model": "numpy", "fastmath": _FASTMATH}


@nb.njit(cache=True, error_model="numpy")
def nz_candidates(z, v, u, nx, ny, fx, fy, cx, cy, nb_off, cand):
    """3F2N's candidates ``nz_i = -(nx dx_i + ny dy_i) / dz_i`` of the neighbours of (v, u).

    Neighbours outside the image, with invalid depth (NaN) or with ``dz = 0`` give none.
    Fills ``cand[:n]`` in the order of ``nb_off`` and returns ``n``.
    """
    h, w = z.shape
    zq = z[v, u]
    xq = (u - cx) * zq / fx
    yq = (v - cy) * zq / fy
    n = 0
    for k in range(nb_off.shape[0]):
        r = v + nb_off[k, 0]
        c = u + nb_off[k, 1]
        if r < 0 or r >= h or c < 0 or c >= w:
            continue
        zn = z[r, c]
        if not (zn == zn):
            continue
        dz = zn - zq
        if dz == 0.0:
            continue
        dx = (c - cx) * zn / fx - xq
        dy = (r - cy) * zn / fy - yq
        cand[n] = -(nx * dx + ny * dy) / dz
        n += 1
    return n


@nb.njit(cache=True, error_model="numpy", inline="always")
def _quantile_sorted(c, n, q):
    pos = q * (n - 1)
    lo = int(pos)
    hi = lo + 1 if lo + 1 < n else lo
    f = pos - lo
    return c[lo] * (1.0 - f) + c[hi] * f


@nb.njit(cache=True, error_model="numpy")
def central_tendency(c, n, mode):
    """Central tendency of c[:n]: 0 median, 1 mean, 2 trimean, 3 trimmed mean (AGGREGATES order).

    Sorts c[:n] in place.
    """
    if mode == 1:
        s = 0.0
        for i in range(n):
            s += c[i]
        return s / n
    for i in range(1, n):  # insertion sort, n <= 8
        x = c[i]
        j = i - 1
        while j >= 0 and c[j] > x:
            c[j + 1] = c[j]
            j -= 1
        c[j + 1] = x
    if mode == 0:
        return _quantile_sorted(c, n, 0.5)
    if mode == 2:
        return 0.25 * (_quantile_sorted(c, n, 0.25) + 2.0 * _quantile_sorted(c, n, 0.5)
                       + _quantile_sorted(c, n, 0.75))
    lo = 1 if n >= 3 else 0
    hi = n - 1 if n >= 3 else n
    s = 0.0
    for i in range(lo, hi):
        s += c[i]
    return s / (hi - lo)


@nb.njit(**_FD_HELPER)
def _cx(a, b):
    return (a if a < b else b), (b if a < b else a)


@nb.njit(**_FD_HELPER)
def median8_pair(a0, a1, a2, a3, a4, a5, a6, a7):
    """The 4th and 5th smallest of 8 values, by a branch-free sorting network."""
    a0, a2 = _cx(a0, a2)
    a1, a3 = _cx(a1, a3)
    a4, a6 = _cx(a4, a6)
    a5, a7 = _cx(a5, a7)
    a0, a4 = _cx(a0, a4)
    a1, a5 = _cx(a1, a5)
    a2, a6 = _cx(a2, a6)
    a3, a7 = _cx(a3, a7)
    a0, a1 = _cx(a0, a1)
    a2, a3 = _cx(a2, a3)
    a4, a5 = _cx(a4, a5)
    a6, a7 = _cx(a6, a7)
    a2, a4 = _cx(a2, a4)
    a3, a5 = _cx(a3, a5)
    a1, a4 = _cx(a1, a4)
    a3, a6 = _cx(a3, a6)
    a3, a4 = _cx(a3, a4)
    return a3, a4


@nb.njit(cache=True, error_model="numpy")
def generic_normal(z, D, recip, v, u, fx, fy, cx, cy, deriv, smooth, roberts, mode, nb_off,
                   cand):
    """The 3F2N normal of one pixel by the general (validity-aware, any kernel) path.

    ``D`` is inverse depth (or depth with ``recip``); returns a unit, camera-facing float64
    normal, or NaNs where no estimate is possible.
    """
    zq = np.float64(z[v, u])
    if not (zq == zq):
        return np.nan, np.nan, np.nan
    if roberts:
        gu, gv = roberts_gradient(D, v, u)
    else:
        zero = np.int64(0)  # not literals: one compiled stencil_derivative, not two
        one = np.int64(1)
        gu = stencil_derivative(D, v, u, zero, one, deriv, smooth, recip)
        gv = stencil_derivative(D, v, u, one, zero, deriv, smooth, recip)
    if not (gu == gu and gv == gv):
        return np.nan, np.nan, np.nan
    nx = fx * gu
    ny = fy * gv
    n = nz_candidates(z, v, u, nx, ny, fx, fy, cx, cy, nb_off, cand)
    if n == 0 or (nx == 0.0 and ny == 0.0):
        nx = 0.0
        ny = 0.0
        nz = -1.0
    else:
        nz = central_tendency(cand, n, mode)
    return oriented_unit(nx, ny, nz, (u - cx) * zq / fx, (v - cy) * zq / fy, zq)



@nb.njit(cache=True, error_model="numpy", fastmath=_FASTMATH)
def _down_edges(za, zb, el, ec, er, one):
    """Reciprocal depth steps from row ``za`` to the next row ``zb``: down-left, down, down-right.

    ``el[u] = 1 / (zb[u-1] - za[u])``, ``ec[u] = 1 / (zb[u] - za[u])``,
    ``er[u] = 1 / (zb[u+1] - za[u])``; a step is shared by the two pixels it joins, so each
    3F2N division is done once for both (with opposite signs).
    """
    w = za.size
    for u in range(w):
        ec[u] = one / (zb[u] - za[u])
    for u in range(1, w):
        el[u] = one / (zb[u - 1] - za[u])
    for u in range(w - 1):
        er[u] = one / (zb[u + 1] - za[u])


@nb.njit(cache=True, error_model="numpy", fastmath=_FASTMATH)
def _right_edges(za, eh, one):
    """``eh[u] = 1 / (za[u+1] - za[u])``: reciprocal depth steps to the right along a row."""
    for u in range(za.size - 1):
        eh[u] = one / (za[u + 1] - za[u])


@nb.njit(**_FD_HELPER)
def _slot(t, r, pinf, ninf, one, zero, parity):
    """A candidate, or +-inf (alternating) when it is dropped.

    ``r`` is the reciprocal depth step to the neighbour: infinite (dz = 0) or NaN (invalid
    neighbour) drops the candidate. Dropped candidates placed alternately at +inf and -inf
    leave the middle of the sorted 8 where the median of the kept ones is; returns
    (value, kept as 1 or 0, new parity).
    """
    kept = abs(r) < pinf
    fill = pinf if parity == 0 else ninf
    return (t if kept else fill), (one if kept else zero), (parity if kept else 1 - parity)


@nb.njit(cache=True, error_model="numpy", fastmath=_FASTMATH)
def _fd_row(z3, r3, up, down, eh, acol, b, c, mode, out_row, out_flag):
    """Branch-free (vectorisable) FD 3F2N over the interior of one row, in the dtype of z.

    ``nz_i = -(gu a + gv b) - (gu du_i + gv dv_i) z_i / (z_i - z_q)`` with a = u - cx,
    b = v - cy: the 3F2N candidate rewritten without X and Y. The divisions come
    precomputed: ``r3 = 1 / z`` of the rows (so ``gu = (z[u-1] - z[u+1]) R[u-1] R[u+1] / 2``,
    free of the cancellation of ``D[u+1] - D[u-1]``), the reciprocal steps ``up = (pl, pc,
    pr)`` from the row above, ``down = (cl, cc, cr)`` to the row below and ``eh`` along the
    row. ``z3``: the rows above, at and below; ``c``: the constants row of
    :func:`depthnormals.kernels.depth.row_arrays`.

    Writes ``out_row = (bx, by, bz)`` (the unit normal) and ``out_flag[u]``, set where the
    result is not finite (an invalid centre or 4-neighbour): those take the general path.
    """
    zp, zc, zn = z3
    Rp, Rc, Rn = r3
    pl, pc, pr = up
    cl, cc, cr = down
    bx, by, bz = out_row
    flag = out_flag
    half = c[C_HALF]
    one = c[C_ONE]
    pinf = c[C_INF]
    ninf = c[C_NINF]
    zero = c[C_ZERO]
    fx = c[C_FX]
    fy = c[C_FY]
    tie2 = c[C_TIE2]
    iby = b / fy  # the ray (a / fx, b / fy, 1), for the orientation's tie
    p2y = one + iby * iby
    w = zc.size
    for u in range(1, w - 1):
        zq = zc[u]
        z0 = zp[u - 1]
        z1 = zp[u]
        z2 = zp[u + 1]
        z3 = zc[u - 1]
        z4 = zc[u + 1]
        z5 = zn[u - 1]
        z6 = zn[u]
        z7 = zn[u + 1]
        gu = half * (z3 - z4) * Rc[u - 1] * Rc[u + 1]
        gv = half * (z1 - z6) * Rp[u] * Rn[u]
        r0 = -pr[u - 1]
        r1 = -pc[u]
        r2 = -pl[u + 1]
        r3 = -eh[u - 1]
        r4 = eh[u]
        r5 = cl[u]
        r6 = cc[u]
        r7 = cr[u]
        p = np.int64(0)  # not the literal 0: one compiled _slot, not two
        t0, k0, p = _slot((-gu - gv) * z0 * r0, r0, pinf, ninf, one, zero, p)
        t1, k1, p = _slot(-gv * z1 * r1, r1, pinf, ninf, one, zero, p)
        t2, k2, p = _slot((gu - gv) * z2 * r2, r2, pinf, ninf, one, zero, p)
        t3, k3, p = _slot(-gu * z3 * r3, r3, pinf, ninf, one, zero, p)
        t4, k4, p = _slot(gu * z4 * r4, r4, pinf, ninf, one, zero, p)
        t5, k5, p = _slot((gv - gu) * z5 * r5, r5, pinf, ninf, one, zero, p)
        t6, k6, p = _slot(gv * z6 * r6, r6, pinf, ninf, one, zero, p)
        t7, k7, p = _slot((gu + gv) * z7 * r7, r7, pinf, ninf, one, zero, p)
        n = k0 + k1 + k2 + k3 + k4 + k5 + k6 + k7
        if mode == 0:
            lo, hi = median8_pair(t0, t1, t2, t3, t4, t5, t6, t7)
            m = half * (lo + hi) if p == 0 else lo
        else:
            s = (t0 if k0 > zero else zero) + (t1 if k1 > zero else zero) \
                + (t2 if k2 > zero else zero) + (t3 if k3 > zero else zero) \
                + (t4 if k4 > zero else zero) + (t5 if k5 > zero else zero) \
                + (t6 if k6 > zero else zero) + (t7 if k7 > zero else zero)
            m = s / n
        a = acol[u]
        nx = fx * gu
        ny = fy * gv
        nz = -(gu * a + gv * b) - m
        # no candidate left (a flat fronto-parallel patch): (0, 0, -1) as the reference;
        # a zero gradient means a fronto-parallel plane whatever the candidates say
        has = n > zero and (gu != zero or gv != zero)
        nx = nx if has else zero
        ny = ny if has else zero
        nz = nz if has else -one
        nrm2 = nx * nx + ny * ny + nz * nz
        nrm = np.sqrt(nrm2)
        inv = one / nrm
        dot = gu * a + gv * b + nz if has else -one  # dot(n, X) / z
        iax = a / fx
        inv = -inv if faces_away(dot, nrm2, p2y + iax * iax, nx, ny, nz, tie2) else inv
        bx[u] = nx * inv
        by[u] = ny * inv
        bz[u] = nz * inv
        chk = nrm * zq * gu * zero + nrm * zq * gv * zero + nrm
        flag[u] = not (chk == chk and nrm > zero and nrm < pinf and zq == zq)


@nb.njit(cache=True, error_model="numpy")
def row_normals(v, rows, cam, filters, scratch, prev, out_row):
    """The 3F2N normals of row ``v`` into ``out_row = (bx, by, bz)`` (every column; NaN where
    none).

    ``rows``: :data:`RowInputs`; ``cam``: :class:`depthnormals.kernels.depth.Pinhole`;
    ``filters``: :data:`Filters`; ``scratch``: :data:`RowScratch`. With ``filters.fast_fd``
    the interior goes through :func:`_fd_row` and only flagged pixels take
    :func:`generic_normal` (the per-pixel reference), which then samples ``1 / D`` (``D`` is
    the depth itself, see :func:`row_setup`). ``prev`` says which of the down-step sets of
    ``scratch.steps`` belongs to row ``v - 1`` (-1: none yet; rows must then come in
    order). Returns the new ``prev``.
    """
    z, D, R, c, acol, bcol = rows
    fx, fy, cx, cy = cam
    deriv, smooth, roberts, mode, fast_fd, nb_off = filters
    steps, flag, cand = scratch
    bx, by, bz = out_row
    h, w = z.shape
    flag[:] = True
    if fast_fd and 0 < v < h - 1 and w > 2:
        one = c[C_ONE]
        if prev < 0:
            prev = 0
            _down_edges(z[v - 1], z[v], steps[0], steps[1], steps[2], one)
        cur = 3 - prev
        _down_edges(z[v], z[v + 1], steps[cur], steps[cur + 1], steps[cur + 2], one)
        _right_edges(z[v], steps[6], one)
        _fd_row((z[v - 1], z[v], z[v + 1]), (R[v - 1], R[v], R[v + 1]),
                (steps[prev], steps[prev + 1], steps[prev + 2]),
                (steps[cur], steps[cur + 1], steps[cur + 2]), steps[6], acol, bcol[v], c, mode,
                (bx, by, bz), flag)
        prev = cur
    for u in range(w):
        if flag[u]:
            x, y, t = generic_normal(z, D, fast_fd, v, u, fx, fy, cx, cy, deriv, smooth,
                                     roberts, mode, nb_off, cand)
            bx[u] = x
            by[u] = y
            bz[u] = t
    return prev


def row_setup(z: np.ndarray, fx: float, fy: float, cx: float, cy: float,
              fast_fd: bool) -> RowInputs:
    """The :data:`RowInputs` of :func:`row_normals`.

    ``z`` as :func:`row_dtype` gives it: the FD row pass runs in its dtype (float32 sensor
    depth: 8 lanes per vector). The general path (borders, invalid neighbours) samples 1 / z
    in float64: from ``D = z`` itself with the FD pass, from ``D = 1 / z`` otherwise.
    """
    c, acol, bcol = row_arrays(z, fx, fy, cx, cy)
    if fast_fd:
        return RowInputs(z, z, np.divide(1, z, dtype=z.dtype), c, acol, bcol)
    return RowInputs(z, np.divide(1.0, z, dtype=np.float64), z[:1, :1], c, acol, bcol)
