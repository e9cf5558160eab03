"""Three-filters-to-normal (3F2N)."""

from __future__ import annotations

import math
from typing import Any

import numba as nb
import numpy as np

from .._parallel import run_rows
from .._validate import check_choice
from ..registry import register
from ._common import NEIGHBOURS8, nz_candidates, prepare, store_normal
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
def _generic_pixel(z, D, v, u, fx, fy, cx, cy, deriv, smooth, roberts, mode, nb_off, cand, out):
    zq = z[v, u]
    if roberts:
        gu, gv = roberts_gradient(D, v, u)
    else:
        gu = stencil_derivative(D, v, u, 0, 1, deriv, smooth)
        gv = stencil_derivative(D, v, u, 1, 0, deriv, smooth)
    xq = (u - cx) * zq / fx
    yq = (v - cy) * zq / fy
    if not (gu == gu and gv == gv):
        out[v, u, 0] = np.nan
        out[v, u, 1] = np.nan
        out[v, u, 2] = np.nan
        return
    nx = fx * gu
    ny = fy * gv
    n = nz_candidates(z, v, u, nx, ny, fx, fy, cx, cy, nb_off, cand)
    if n == 0 or (nx == 0.0 and ny == 0.0):
        nx = 0.0
        ny = 0.0
        nz = -1.0
    else:
        nz = central_tendency(cand, n, mode)
    store_normal(out, v, u, nx, ny, nz, xq, yq, zq)


# no-NaN/no-inf assumptions are never allowed: NaN marks invalid depth
_FASTMATH = {"nsz", "contract", "arcp"}


@nb.njit(cache=True, error_model="numpy", inline="always")
def _slot(t, d, z, parity):
    """A candidate, or +-inf (alternating) when it is dropped (dz = 0 or invalid neighbour).

    Dropped candidates placed alternately at +inf and -inf leave the middle of the sorted 8
    where the median of the kept ones is; returns (value, kept, new parity).
    """
    kept = d != 0.0 and d == d and z == z
    fill = np.inf if parity == 0 else -np.inf
    return (t if kept else fill), (1.0 if kept else 0.0), (parity if kept else 1 - parity)


@nb.njit(cache=True, error_model="numpy", fastmath=_FASTMATH)
def _fd_row(zp, zc, zn, Dp, Dc, Dn, v, fx, fy, cx, cy, mode, bx, by, bz, flag):
    """Branch-free (vectorisable) FD 3F2N over the interior of one row.

    ``nz_i = -(gu a + gv b) - (gu du_i + gv dv_i) z_i / (z_i - z_q)`` with a = u - cx,
    b = v - cy: the 3F2N candidate rewritten without X and Y. Candidates with dz = 0 or an
    invalid neighbour are dropped; ``flag[u]`` is set where the centre or a 4-neighbour is
    invalid (those pixels take the general path).
    """
    w = zc.size
    b = v - cy
    for u in range(1, w - 1):
        zq = np.float64(zc[u])
        z0 = np.float64(zp[u - 1])
        z1 = np.float64(zp[u])
        z2 = np.float64(zp[u + 1])
        z3 = np.float64(zc[u - 1])
        z4 = np.float64(zc[u + 1])
        z5 = np.float64(zn[u - 1])
        z6 = np.float64(zn[u])
        z7 = np.float64(zn[u + 1])
        gu = 0.5 * (Dc[u + 1] - Dc[u - 1])
        gv = 0.5 * (Dn[u] - Dp[u])
        d0 = z0 - zq
        d1 = z1 - zq
        d2 = z2 - zq
        d3 = z3 - zq
        d4 = z4 - zq
        d5 = z5 - zq
        d6 = z6 - zq
        d7 = z7 - zq
        p = 0
        t0, k0, p = _slot((-gu - gv) * z0 / d0, d0, z0, p)
        t1, k1, p = _slot(-gv * z1 / d1, d1, z1, p)
        t2, k2, p = _slot((gu - gv) * z2 / d2, d2, z2, p)
        t3, k3, p = _slot(-gu * z3 / d3, d3, z3, p)
        t4, k4, p = _slot(gu * z4 / d4, d4, z4, p)
        t5, k5, p = _slot((gv - gu) * z5 / d5, d5, z5, p)
        t6, k6, p = _slot(gv * z6 / d6, d6, z6, p)
        t7, k7, p = _slot((gu + gv) * z7 / d7, d7, z7, p)
        n = k0 + k1 + k2 + k3 + k4 + k5 + k6 + k7
        if mode == 0:
            lo, hi = median8_pair(t0, t1, t2, t3, t4, t5, t6, t7)
            m = 0.5 * (lo + hi) if p == 0 else lo
        else:
            s = (k0 * t0 if k0 > 0.0 else 0.0) + (k1 * t1 if k1 > 0.0 else 0.0) \
                + (k2 * t2 if k2 > 0.0 else 0.0) + (k3 * t3 if k3 > 0.0 else 0.0) \
                + (k4 * t4 if k4 > 0.0 else 0.0) + (k5 * t5 if k5 > 0.0 else 0.0) \
                + (k6 * t6 if k6 > 0.0 else 0.0) + (k7 * t7 if k7 > 0.0 else 0.0)
            m = s / n
        a = u - cx
        nx = fx * gu
        ny = fy * gv
        nz = -(gu * a + gv * b) - m
        # no candidate left (a flat fronto-parallel patch): (0, 0, -1) as the reference;
        # a zero gradient means a fronto-parallel plane whatever the candidates say
        has = n > 0.0 and (gu != 0.0 or gv != 0.0)
        nx = nx if has else 0.0
        ny = ny if has else 0.0
        nz = nz if has else -1.0
        nrm = math.sqrt(nx * nx + ny * ny + nz * nz)
        inv = 1.0 / nrm
        dot = gu * a + gv * b + nz if has else -1.0  # dot(n, X) / z
        inv = -inv if dot > 0.0 else inv
        bx[u] = nx * inv
        by[u] = ny * inv
        bz[u] = nz * inv
        chk = nrm * zq * gu * 0.0 + nrm * zq * gv * 0.0 + nrm
        flag[u] = not (chk == chk and nrm > 0.0 and nrm < np.inf and zq == zq)


@nb.njit(cache=True, error_model="numpy", nogil=True)
def _threefn_rows(v0, v1, z, D, fx, fy, cx, cy, deriv, smooth, roberts, mode, fast_fd, nb_off, out):
    h, w = z.shape
    cand = np.empty(8)
    flag = np.empty(w, dtype=np.bool_)
    bx = np.empty(w)
    by = np.empty(w)
    bz = np.empty(w)
    for v in range(v0, v1):
        flag[:] = True
        if fast_fd and 0 < v < h - 1 and w > 2:
            _fd_row(z[v - 1], z[v], z[v + 1], D[v - 1], D[v], D[v + 1], v, fx, fy, cx, cy, mode,
                    bx, by, bz, flag)
            for u in range(1, w - 1):
                out[v, u, 0] = bx[u]
                out[v, u, 1] = by[u]
                out[v, u, 2] = bz[u]
        for u in range(w):
            if not flag[u]:
                continue
            if not (z[v, u] == z[v, u]):
                out[v, u, 0] = np.nan
                out[v, u, 1] = np.nan
                out[v, u, 2] = np.nan
                continue
            _generic_pixel(z, D, v, u, fx, fy, cx, cy, deriv, smooth, roberts, mode, nb_off, cand, out)


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
    D = np.divide(1.0, z, dtype=np.float64)
    run_rows(_threefn_rows, z.shape[0], z, D, cam.fx, cam.fy, cam.cx, cam.cy, deriv, smooth,
             kernel == "roberts", mode, fast_fd, NEIGHBOURS8, out)
    return out
