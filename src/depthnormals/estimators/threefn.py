"""Three-filters-to-normal (3F2N)."""

from __future__ import annotations

from typing import Any

import numba as nb
import numpy as np

from .._parallel import run_rows
from .._validate import check_choice
from ..registry import register
from ._common import NEIGHBOURS8, nz_candidates, oriented_unit, prepare, row_arrays, row_dtype
from ._stencils import KERNELS, gradient_kernels, roberts_gradient, stencil_derivative

__all__ = ["AGGREGATES", "three_filters_to_normal"]

AGGREGATES = ("median", "mean", "trimean", "trimmed-mean")

# neighbour offsets (dv, du), the 8-neighbourhood


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


@nb.njit(cache=True, error_model="numpy", inline="always")
def _cx(a, b):
    return (a if a < b else b), (b if a < b else a)


@nb.njit(cache=True, error_model="numpy", inline="always")
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
        gu = stencil_derivative(D, v, u, 0, 1, deriv, smooth, recip)
        gv = stencil_derivative(D, v, u, 1, 0, deriv, smooth, recip)
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


# no-NaN/no-inf assumptions are never allowed: NaN marks invalid depth
_FASTMATH = {"nsz", "contract", "arcp"}


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


@nb.njit(cache=True, error_model="numpy", inline="always")
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
def _fd_row(zp, zc, zn, Rp, Rc, Rn, pl, pc, pr, cl, cc, cr, eh, acol, b, c, mode, bx, by, bz,
            flag):
    """Branch-free (vectorisable) FD 3F2N over the interior of one row, in the dtype of z.

    ``nz_i = -(gu a + gv b) - (gu du_i + gv dv_i) z_i / (z_i - z_q)`` with a = u - cx,
    b = v - cy: the 3F2N candidate rewritten without X and Y. The divisions come
    precomputed: ``R = 1 / z`` (so ``gu = (z[u-1] - z[u+1]) R[u-1] R[u+1] / 2``, free of the
    cancellation of ``D[u+1] - D[u-1]``), the reciprocal steps ``pl, pc, pr`` from the row
    above, ``cl, cc, cr`` to the row below and ``eh`` along the row. ``c`` holds the
    constants (0.5, 1, inf, -inf, 0, fx, fy) in the dtype of z. ``flag[u]`` is set where the
    result is not finite (an invalid centre or 4-neighbour): those take the general path.
    """
    half = c[0]
    one = c[1]
    pinf = c[2]
    ninf = c[3]
    zero = c[4]
    fx = c[5]
    fy = c[6]
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
        p = 0
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
        nrm = np.sqrt(nx * nx + ny * ny + nz * nz)
        inv = one / nrm
        dot = gu * a + gv * b + nz if has else -one  # dot(n, X) / z
        inv = -inv if dot > zero else inv
        bx[u] = nx * inv
        by[u] = ny * inv
        bz[u] = nz * inv
        chk = nrm * zq * gu * zero + nrm * zq * gv * zero + nrm
        flag[u] = not (chk == chk and nrm > zero and nrm < pinf and zq == zq)


@nb.njit(cache=True, error_model="numpy")
def row_normals(v, z, D, R, c, acol, bcol, fx, fy, cx, cy, deriv, smooth, roberts, mode, fast_fd,
                nb_off, steps, prev, bx, by, bz, flag, cand):
    """The 3F2N normals of row ``v`` into ``bx, by, bz`` (every column; NaN where none).

    With ``fast_fd`` the interior goes through :func:`_fd_row` and only flagged pixels take
    :func:`generic_normal`, which then samples ``1 / D`` (``D`` is the depth itself, see
    :func:`row_setup`). ``steps`` (7, W) holds the reciprocal depth steps, ``prev`` which
    of its down-step sets belongs to row ``v - 1`` (-1: none yet; rows must then come in
    order). Returns the new ``prev``.
    """
    h, w = z.shape
    flag[:] = True
    if fast_fd and 0 < v < h - 1 and w > 2:
        one = c[1]
        if prev < 0:
            prev = 0
            _down_edges(z[v - 1], z[v], steps[0], steps[1], steps[2], one)
        cur = 3 - prev
        _down_edges(z[v], z[v + 1], steps[cur], steps[cur + 1], steps[cur + 2], one)
        _right_edges(z[v], steps[6], one)
        _fd_row(z[v - 1], z[v], z[v + 1], R[v - 1], R[v], R[v + 1], steps[prev],
                steps[prev + 1], steps[prev + 2], steps[cur], steps[cur + 1], steps[cur + 2],
                steps[6], acol, bcol[v], c, mode, bx, by, bz, flag)
        prev = cur
    for u in range(w):
        if flag[u]:
            x, y, t = generic_normal(z, D, fast_fd, v, u, fx, fy, cx, cy, deriv, smooth,
                                     roberts, mode, nb_off, cand)
            bx[u] = x
            by[u] = y
            bz[u] = t
    return prev


@nb.njit(cache=True, error_model="numpy", nogil=True)
def _threefn_rows(v0, v1, z, D, R, c, acol, bcol, fx, fy, cx, cy, deriv, smooth, roberts, mode,
                  fast_fd, nb_off, out):
    w = z.shape[1]
    cand = np.empty(8)
    flag = np.empty(w, dtype=np.bool_)
    bx = np.empty(w, dtype=z.dtype)
    by = np.empty(w, dtype=z.dtype)
    bz = np.empty(w, dtype=z.dtype)
    steps = np.empty((7, w), dtype=z.dtype)  # two sets of down steps, one of right steps
    prev = -1
    for v in range(v0, v1):
        prev = row_normals(v, z, D, R, c, acol, bcol, fx, fy, cx, cy, deriv, smooth, roberts,
                           mode, fast_fd, nb_off, steps, prev, bx, by, bz, flag, cand)
        for u in range(w):
            out[v, u, 0] = bx[u]
            out[v, u, 1] = by[u]
            out[v, u, 2] = bz[u]


def row_setup(z: np.ndarray, fx: float, fy: float, cx: float, cy: float, fast_fd: bool):
    """Arrays the row kernels need: (D, R, c, acol, bcol) for :func:`row_normals`.

    ``z`` as :func:`row_dtype` gives it: the FD row pass runs in its dtype (float32 sensor
    depth: 8 lanes per vector). The general path (borders, invalid neighbours) samples 1 / z
    in float64: from ``D = z`` itself with the FD pass, from ``D = 1 / z`` otherwise.
    """
    c, acol, bcol = row_arrays(z, fx, fy, cx, cy)
    if fast_fd:
        return z, np.divide(1, z, dtype=z.dtype), c, acol, bcol
    return np.divide(1.0, z, dtype=np.float64), z[:1, :1], c, acol, bcol


@register("3f2n")
def three_filters_to_normal(depth: Any, K: Any, *, kernel: str = "fd", kernel_size: int = 3,
                            aggregate: str = "median",
                            depth_scale: float | None = None) -> np.ndarray:
    """Three-filters-to-normal (3F2N): normals from inverse-depth gradients.

    A plane ``n . p + d = 0`` makes inverse depth linear in the pixel position, so
    ``nx = fx * d(1/z)/du`` and ``ny = fy * d(1/z)/dv`` (two image filters); each of the 8
    neighbours ``p_i`` of ``q`` then gives ``nz_i = -(nx dx_i + ny dy_i) / dz_i`` with
    ``(dx, dy, dz) = p_i - q``, and the third filter takes their central tendency.

    Parameters
    ----------
    depth : array_like, shape (H, W)
        Planar depth z (any length unit). float32/float64; integers need ``depth_scale``.
        Invalid depth (0, negative, NaN, inf) gives NaN.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Intrinsics in pixels, 0-based pixel centres.
    kernel : {"fd", "sobel", "scharr", "prewitt", "roberts"}, default "fd"
        Gradient filter. ``fd`` is the central difference (a least-squares slope for larger
        sizes); ``sobel``, ``scharr`` (smoothing 3, 10, 3) and ``prewitt`` (1, 1, 1) are
        correctly named (the public MATLAB swaps the last two); ``roberts`` is the 2x2 cross,
        its diagonal derivatives rotated back into u, v derivatives.
    kernel_size : {3, 5, 7, 9, 11}, default 3
        Size of the gradient kernel (ignored by ``roberts``, which is 2x2).
    aggregate : {"median", "mean", "trimean", "trimmed-mean"}, default "median"
        The third filter over the valid ``nz_i`` candidates. ``trimean`` is
        (Q1 + 2 Q2 + Q3) / 4 with linearly interpolated quartiles; ``trimmed-mean`` drops
        the smallest and the largest candidate (when at least 3 remain).
    depth_scale : float, optional
        Metres per unit of integer depth.

    Returns
    -------
    normals : ndarray, shape (H, W, 3), float32
        Unit normals facing the camera; NaN at invalid depth and where no gradient exists.

    Notes
    -----
    Conventions: OpenCV camera frame, planar depth, pixel centres on integers. As in the
    public reference, neighbours with ``dz = 0`` are dropped, and when none is left the
    normal is ``(0, 0, -1)``; so is it where the inverse-depth gradient is exactly zero (the
    reference returns NaN there when the remaining candidates come from another surface).
    Interpretation (ours): invalid pixels never enter a stencil;
    a stencil row that would touch one falls back to a central, then one-sided difference,
    and neighbours that are invalid give no candidate. The normal is then oriented per pixel
    toward the camera, which the reference achieves with a global sign.

    Speed: the default FD kernel (size 3, median or mean) runs a vectorised row pass in the
    dtype of the depth, so float32 sensor depth is processed 8 pixels per AVX2 vector. Each
    division ``1 / (z_i - z_q)`` is shared by the two pixels it joins, and the gradient is
    formed as ``(z[u-1] - z[u+1]) / (2 z[u-1] z[u+1])``, which has no cancellation. Against
    the float64 general path, float32 depth moves the normals by < 5e-3 deg (99.9 % of
    pixels < 5e-4 deg); pixels at the border or next to invalid depth take the general path.

    References
    ----------
    R. Fan, H. Wang, B. Xue, H. Huang, Y. Wang, M. Liu and I. Pitas, "Three-Filters-to-Normal:
    An Accurate and Ultrafast Surface Normal Estimator," IEEE Robotics and Automation Letters,
    vol. 6, no. 3, pp. 5405-5412, 2021. doi:10.1109/LRA.2021.3067308

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals import three_filters_to_normal
    >>> v, u = np.mgrid[0:6, 0:8]
    >>> z = 1.0 / (0.5 + 0.001 * u)          # a plane: inverse depth linear in u
    >>> n = three_filters_to_normal(z, (500.0, 500.0, 3.5, 2.5))
    >>> bool(np.allclose(np.linalg.norm(n, axis=-1), 1.0))
    True
    """
    check_choice(kernel, "kernel", tuple(KERNELS))
    mode = AGGREGATES.index(check_choice(aggregate, "aggregate", AGGREGATES))
    z, cam = prepare(depth, K, depth_scale)
    if kernel == "roberts":
        deriv, smooth = np.zeros(1), np.ones(1)
    else:
        deriv, smooth = gradient_kernels(kernel, kernel_size)
    out = np.empty((*z.shape, 3), dtype=np.float32)
    fast_fd = kernel == "fd" and kernel_size == 3 and mode in (0, 1)
    if fast_fd:
        z = row_dtype(z, cam.fx, cam.fy, cam.cx, cam.cy)
    D, R, c, acol, bcol = row_setup(z, cam.fx, cam.fy, cam.cx, cam.cy, fast_fd)
    run_rows(_threefn_rows, z.shape[0], z, D, R, c, acol, bcol, cam.fx, cam.fy, cam.cx, cam.cy,
             deriv, smooth, kernel == "roberts", mode, fast_fd, NEIGHBOURS8, out)
    return out
