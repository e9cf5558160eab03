"""Range-image estimators: FALS and SRI (Badino et al. 2011) and LINE-MOD's depth normals."""

from __future__ import annotations

import math
from typing import Any

import numba as nb
import numpy as np

from .._parallel import run_rows
from .._validate import check_positive
from ..kernels.depth import new_output, prepare
from ..kernels.eig3 import sym3_adjugate_apply
from ..kernels.orient import faces_away, store_normal
from ..kernels.stencils import gradient_kernels, stencil_derivative
from .pointcloud import check_window

__all__ = ["fals", "line_mod", "sri"]


# ----------------------------------------------------------------------------------- FALS

_NUMPY = "numpy"  # error_model: float division by zero gives inf/NaN, never raises


@nb.njit(cache=True, error_model=_NUMPY)
def _fals_pixel(z, v, u, fx, fy, cx, cy, r, out):
    """FALS at one pixel from the valid pixels of its (clipped) window, with M solved by its
    adjugate; NaN when the valid pixel positions are collinear (M singular)."""
    h, w = z.shape
    zq = z[v, u]
    out[v, u, 0] = np.nan
    out[v, u, 1] = np.nan
    out[v, u, 2] = np.nan
    if not (zq == zq):
        return
    m00 = m01 = m02 = m11 = m12 = m22 = 0.0
    s0 = s1 = s2 = 0.0
    n = 0
    su = sv = suu = suv = svv = 0.0
    for rr in range(max(v - r, 0), min(v + r + 1, h)):
        y = (rr - cy) / fy
        for cc in range(max(u - r, 0), min(u + r + 1, w)):
            zz = z[rr, cc]
            if not (zz == zz):
                continue
            x = (cc - cx) / fx
            s = 1.0 / (x * x + y * y + 1.0)
            m00 += x * x * s
            m01 += x * y * s
            m02 += x * s
            m11 += y * y * s
            m12 += y * s
            m22 += s
            k = s / zz  # v / range = (x, y, 1) / (s^-1 z)
            s0 += x * k
            s1 += y * k
            s2 += k
            du = cc - u
            dv = rr - v
            n += 1
            su += du
            sv += dv
            suu += du * du
            suv += du * dv
            svv += dv * dv
    # pixel positions collinear <=> rays coplanar with the centre <=> M singular
    if n < 3 or (n * suu - su * su) * (n * svv - sv * sv) - (n * suv - su * sv) ** 2 <= 0:
        return
    # adj(M) b: det(M) > 0 only scales
    nx, ny, nz, _ = sym3_adjugate_apply(m00, m01, m02, m11, m12, m22, s0, s1, s2)
    store_normal(out, v, u, nx, ny, nz, (u - cx) * zq / fx, (v - cy) * zq / fy, zq)


# Vectorisable loops: every loop index starts at 0 on a view, so LLVM sees non-negative,
# affine indices (a runtime offset such as ``a[u + i]`` keeps numba's negative-index
# wraparound and blocks vectorisation), and each loop writes one array. These row helpers
# are called once per row, so they are not inlined (numba-level inlining of every call
# site multiplies the compile time).

@nb.njit(cache=True, error_model=_NUMPY)
def _box(src, dst, r):
    """dst[r + k] = sum of src[k .. k + 2r] for k in 0 .. w-2r-1."""
    m = src.size - 2 * r
    if m <= 0:
        return
    d = dst[r:r + m]
    s0 = src[0:m]
    s1 = src[1:1 + m]
    s2 = src[2:2 + m]
    if r == 1:  # the common windows in one pass (taps in registers)
        for k in range(m):
            d[k] = s0[k] + s1[k] + s2[k]
        return
    s3 = src[3:3 + m]
    s4 = src[4:4 + m]
    if r == 2:
        for k in range(m):
            d[k] = s0[k] + s1[k] + s2[k] + s3[k] + s4[k]
        return
    for k in range(m):
        d[k] = s0[k] + s1[k] + s2[k] + s3[k] + s4[k]
    for i in range(5, 2 * r + 1):
        si = src[i:i + m]
        for k in range(m):
            d[k] += si[k]


@nb.njit(cache=True, error_model=_NUMPY)
def _box_clipped(src, dst, r):
    """As :func:`_box`, and the window clipped at the ends for the first and last r columns."""
    w = src.size
    _box(src, dst, r)
    left = min(r, w)
    for u in range(left):
        _box_at(src, dst, r, u)
    for u in range(max(w - r, left), w):
        _box_at(src, dst, r, u)


@nb.njit(cache=True, error_model=_NUMPY)
def _box_at(src, dst, r, u):
    w = src.size
    t = 0.0
    for c in range(max(u - r, 0), min(u + r + 1, w)):
        t += src[c]
    dst[u] = t


@nb.njit(cache=True, error_model=_NUMPY)
def _axpy2(dst, a, x, b, y):
    """dst += a x + b y (same length)."""
    for k in range(dst.size):
        dst[k] += a * x[k] + b * y[k]


# the horizontal window sums of one row, H[q] (ring slot): q = 0 k, 1 x k, 2 invalid count
# (k = s / z, 0 where z is invalid), 3 s, 4 x s, 5 x^2 s (geometry), s = 1 / (x^2 + y^2 + 1)
_FALS_KMAX = 1e12  # larger k (depth < 1e-12) is left to the exact per-pixel path


@nb.njit(cache=True, error_model=_NUMPY)
def _fals_hrow(z, rr, xs, cy, fy, r, H, krow, srow, crow):
    """Horizontal window sums (clipped at the image border) of row rr into H (6, w).

    Invalid pixels contribute 0 to every sum and 1 to the invalid count."""
    w = xs.size
    y = (rr - cy) / fy
    y2 = y * y + 1.0
    zr = z[rr]
    for c in range(w):
        zz = np.float64(zr[c])
        t = 1.0 / ((xs[c] * xs[c] + y2) * zz)  # k = s / z: one division
        ok = t < _FALS_KMAX  # False for NaN (invalid depth)
        krow[c] = t if ok else 0.0
        srow[c] = t * zz if ok else 0.0
        crow[c] = 0.0 if ok else 1.0
    _box_clipped(krow, H[0], r)
    _box_clipped(crow, H[2], r)
    _box_clipped(srow, H[3], r)
    for c in range(w):
        krow[c] *= xs[c]
    for c in range(w):
        srow[c] *= xs[c]
    _box_clipped(krow, H[1], r)
    _box_clipped(srow, H[4], r)
    for c in range(w):
        srow[c] *= xs[c]
    _box_clipped(srow, H[5], r)


@nb.njit(cache=True, error_model=_NUMPY)
def _fals_add(acc, H, y, a, G, yg, b, lo, hi):
    """acc += a * (the 10 window sums of ring row H at y) + b * (those of G at yg), columns
    lo .. hi-1 (1-D contiguous views: the loops vectorise)."""
    _axpy2(acc[0, lo:hi], a, H[1, lo:hi], b, G[1, lo:hi])              # b: x k
    _axpy2(acc[1, lo:hi], a * y, H[0, lo:hi], b * yg, G[0, lo:hi])     # y k
    _axpy2(acc[2, lo:hi], a, H[0, lo:hi], b, G[0, lo:hi])              # k
    _axpy2(acc[3, lo:hi], a, H[2, lo:hi], b, G[2, lo:hi])              # invalid pixels
    _axpy2(acc[4, lo:hi], a, H[5, lo:hi], b, G[5, lo:hi])              # M: x^2 s
    _axpy2(acc[5, lo:hi], a * y, H[4, lo:hi], b * yg, G[4, lo:hi])     # x y s
    _axpy2(acc[6, lo:hi], a, H[4, lo:hi], b, G[4, lo:hi])              # x s
    _axpy2(acc[7, lo:hi], a * y * y, H[3, lo:hi], b * yg * yg, G[3, lo:hi])  # y^2 s
    _axpy2(acc[8, lo:hi], a * y, H[3, lo:hi], b * yg, G[3, lo:hi])     # y s
    _axpy2(acc[9, lo:hi], a, H[3, lo:hi], b, G[3, lo:hi])              # s


@nb.njit(cache=True, error_model=_NUMPY)
def _fals_solve_row(yq, acc, xs_, bx_, by_, bz_, flag_, lo, hi):
    """n ~ adj(M) b from the window sums, oriented and normalised into bx, by, bz;
    flagged where the window has an invalid pixel or the solve fails (columns lo .. hi-1).
    Returns the number of flagged pixels."""
    a0 = acc[0, lo:hi]
    a1 = acc[1, lo:hi]
    a2 = acc[2, lo:hi]
    a3 = acc[3, lo:hi]
    a4 = acc[4, lo:hi]
    a5 = acc[5, lo:hi]
    a6 = acc[6, lo:hi]
    a7 = acc[7, lo:hi]
    a8 = acc[8, lo:hi]
    a9 = acc[9, lo:hi]
    xs = xs_[lo:hi]
    bx = bx_[lo:hi]
    by = by_[lo:hi]
    bz = bz_[lo:hi]
    flag = flag_[lo:hi]
    nflag = 0
    for k in range(xs.size):
        s0 = a0[k]
        s1 = a1[k]
        s2 = a2[k]
        m00 = a4[k]
        m01 = a5[k]
        m02 = a6[k]
        m11 = a7[k]
        m12 = a8[k]
        m22 = a9[k]
        nx, ny, nz, _ = sym3_adjugate_apply(m00, m01, m02, m11, m12, m22, s0, s1, s2)
        n2 = nx * nx + ny * ny + nz * nz
        nrm = math.sqrt(n2)
        inv = 1.0 / nrm
        dot = nx * xs[k] + ny * yq + nz  # dot(n, X) / z
        inv = -inv if faces_away(dot, n2, xs[k] * xs[k] + yq * yq + 1.0, nx, ny, nz) else inv
        bx[k] = nx * inv
        by[k] = ny * inv
        bz[k] = nz * inv
        f = not (nrm > 0.0 and nrm < np.inf and a3[k] < 0.5)
        flag[k] = f
        nflag += f
    return nflag


@nb.njit(cache=True, error_model=_NUMPY)
def _copy_row(o, bx, by, bz):
    for k in range(bx.size):
        o[k, 0] = bx[k]
        o[k, 1] = by[k]
        o[k, 2] = bz[k]


@nb.njit(cache=True, nogil=True, error_model=_NUMPY)
def _fals_rows(v0, v1, z, fx, fy, cx, cy, r, out):
    """FALS over rows [v0, v1): separable box sums over the (clipped) window, horizontal
    sums per row in a ring, vertical running sums refreshed every 16 rows; pixels whose
    window holds an invalid pixel take :func:`_fals_pixel`."""
    h, w = z.shape
    ns = 2 * r + 2  # ring: the window's rows and the one leaving it
    xs = np.empty(w)
    for c in range(w):
        xs[c] = (c - cx) / fx
    H = np.zeros((ns, 6, w))
    krow = np.empty(w)
    srow = np.empty(w)
    crow = np.empty(w)
    acc = np.zeros((10, w))
    bx = np.empty(w)
    by = np.empty(w)
    bz = np.empty(w)
    flag = np.empty(w, dtype=np.bool_)
    fast = h > 1 and w > 1  # a single row or column: collinear windows, general path
    nxt = 0  # first row not yet in the ring
    cur = -2  # the output row acc holds
    # running sums restart on rows that are multiples of 16: a band starts at the restart
    # before it (warming the sums up without output), so any banding gives the same result
    vw = (v0 // 16) * 16 if fast else v0
    for v in range(vw, v1):
        nflag = w
        if fast:
            top = max(v - r, 0)
            bot = min(v + r, h - 1)
            for rr in range(max(nxt, top), bot + 1):
                _fals_hrow(z, rr, xs, cy, fy, r, H[rr % ns], krow, srow, crow)
            nxt = max(nxt, bot + 1)
            ri = v + r
            ro = v - r - 1
            if cur == v - 1 and v % 16 != 0 and ri < h and ro >= 0:
                _fals_add(acc, H[ri % ns], (ri - cy) / fy, 1.0, H[ro % ns], (ro - cy) / fy, -1.0,
                          0, w)
            else:
                acc[:, :] = 0.0
                for rr in range(top, bot + 1):
                    Hr = H[rr % ns]
                    _fals_add(acc, Hr, (rr - cy) / fy, 1.0, Hr, 0.0, 0.0, 0, w)
            cur = v
            if v < v0:
                continue
            nflag = _fals_solve_row((v - cy) / fy, acc, xs, bx, by, bz, flag, 0, w)
            _copy_row(out[v], bx, by, bz)
        else:
            flag[:] = True
        if nflag == 0:
            continue
        for u in range(w):
            if flag[u]:
                _fals_pixel(z, v, u, fx, fy, cx, cy, r, out)


def fals(depth: Any, K: Any, *, window: int = 5, depth_scale: float | None = None) -> np.ndarray:
    """Fast approximate least squares (FALS): a plane fit in the range image.

    A plane ``n . p = d`` seen along the unit ray ``v`` at range ``r`` satisfies
    ``n . v / d = 1 / r``. Least squares over the window gives ``n ~ M^-1 b`` with
    ``M = sum v v^T`` and ``b = sum v / r``, both as separable box sums (solved by the
    adjugate of ``M``: its determinant only scales ``n``).

    Parameters
    ----------
    depth : array_like, shape (H, W)
        Planar depth z (any length unit). float32/float64; integers need ``depth_scale``.
        Invalid depth (0, negative, NaN, inf) gives NaN.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Intrinsics in pixels, 0-based pixel centres.
    window : int, default 5
        Odd side of the square window (OpenCV's ``window_size``, default 5 there too).
    depth_scale : float, optional
        Metres per unit of integer depth.

    Returns
    -------
    normals : ndarray, shape (H, W, 3), float32
        Unit normals facing the camera; NaN at invalid depth and where the valid pixels of
        the window are collinear.

    Notes
    -----
    Interpretation (ours): both sums run over the valid pixels of the window only, and the
    window is clipped at the image border. OpenCV's ``RgbdNormals`` (FALS) instead sums
    ``M`` over the whole window whatever the validity (``b`` gets zeros from invalid
    pixels) and reflects the window at the border, which bends its normals next to holes
    and at the image edge; on fully valid windows the two agree (see docs/estimators.md).
    The orientation is per pixel toward the camera (OpenCV flips to ``n_z < 0``).

    References
    ----------
    H. Badino, D. Huber, Y. Park and T. Kanade, "Fast and Accurate Computation of Surface
    Normals from Range Images," IEEE International Conference on Robotics and Automation
    (ICRA), 2011, pp. 3084-3091. doi:10.1109/ICRA.2011.5980275

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals import fals
    >>> n = fals(np.full((7, 8), 2.0), (500.0, 500.0, 3.5, 3.0))
    >>> bool(np.allclose(n[3, 4], [0.0, 0.0, -1.0], atol=1e-6))
    True
    """
    r = check_window(window) // 2
    z, cam = prepare(depth, K, depth_scale)
    out = np.empty((*z.shape, 3), dtype=np.float32)
    run_rows(_fals_rows, z.shape[0], z, cam.fx, cam.fy, cam.cx, cam.cy, r, out)
    return out


# ------------------------------------------------------------------------------------ SRI

@nb.njit(cache=True, nogil=True, error_model=_NUMPY)
def _range_rows(v0, v1, z, fx, fy, cx, cy, R):
    """Range image r(u, v) = z sqrt(x'^2 + y'^2 + 1) (NaN at invalid depth)."""
    w = z.shape[1]
    for v in range(v0, v1):
        y = (v - cy) / fy
        for u in range(w):
            x = (u - cx) / fx
            R[v, u] = z[v, u] * math.sqrt(x * x + y * y + 1.0)


@nb.njit(cache=True, error_model=_NUMPY, inline="always")
def _sri_normal(ru, rv, rq, x, y, fx, fy):
    """Normal (not normalised) from the image derivatives of range at (x, y) = normalised
    image coordinates, range rq."""
    rho2 = x * x + y * y + 1.0
    sx = math.sqrt(1.0 + x * x)
    sr = math.sqrt(rho2)
    # azimuth theta = atan(x), elevation phi = asin(y / sqrt(rho2))
    ct = 1.0 / sx
    st = x * ct
    sp = y / sr
    cp = sx / sr
    # Jacobian of (theta, phi) w.r.t. (u, v): theta_v = 0
    th_u = 1.0 / (fx * (1.0 + x * x))
    ph_u = -x * y / (fx * rho2 * sx)
    ph_v = sx / (fy * rho2)
    r_phi = rv / ph_v
    r_theta = (ru - r_phi * ph_u) / th_u
    a = r_theta / (rq * cp)
    b = r_phi / rq
    # n ~ s - a e_theta - b e_phi (spherical frame: s radial)
    return st * cp - a * ct + b * st * sp, sp - b * cp, ct * cp + a * st + b * ct * sp


@nb.njit(cache=True, error_model=_NUMPY)
def _sri_pixel(z, R, v, u, fx, fy, cx, cy, deriv, smooth, out):
    """SRI at one pixel with the validity-aware stencil (fallbacks next to invalid pixels)."""
    zq = z[v, u]
    out[v, u, 0] = np.nan
    out[v, u, 1] = np.nan
    out[v, u, 2] = np.nan
    if not (zq == zq):
        return
    ru = stencil_derivative(R, v, u, 0, 1, deriv, smooth)
    rv = stencil_derivative(R, v, u, 1, 0, deriv, smooth)
    if not (ru == ru and rv == rv):
        return
    x = (u - cx) / fx
    y = (v - cy) / fy
    nx, ny, nz = _sri_normal(ru, rv, R[v, u], x, y, fx, fy)
    store_normal(out, v, u, nx, ny, nz, x * zq, y * zq, zq)


@nb.njit(cache=True, error_model=_NUMPY)
def _sri_hrow(Rr, deriv, md, hd):
    """Horizontal derivative taps of the range row Rr into hd (columns md .. w-md-1)."""
    mm = Rr.size - 2 * md
    d = hd[md:md + mm]
    for k in range(mm):
        d[k] = 0.0
    for i in range(2 * md + 1):
        c = deriv[i]
        if c == 0.0:
            continue
        si = Rr[i:i + mm]
        for k in range(mm):
            d[k] += c * si[k]


@nb.njit(cache=True, error_model=_NUMPY)
def _sri_fast_row(v, R, hd, deriv, smooth, iws, cam, work, out_row, out_flag):
    """Separable Sobel derivatives and the SRI normal over the interior of row v (views
    starting at 0, so the loops vectorise); a NaN in the window gives NaN and a flag.

    ``cam = (fx, fy, cx, cy)``; ``work = (vd, ru, rv)``: scratch rows (W); writes the normals
    into ``out_row = (bx, by, bz)`` and ``out_flag`` (W, True where the per-pixel path
    :func:`_sri_pixel` must redo the pixel).
    """
    fx, fy, cx, cy = cam
    vd, ru_, rv_ = work
    bx_, by_, bz_ = out_row
    flag_ = out_flag
    w = R.shape[1]
    m = deriv.size // 2
    n = 2 * m + 1
    mm = w - 2 * m
    ru = ru_[m:m + mm]
    rv = rv_[m:m + mm]
    # d/du: smoothing across (along v) of the per-row derivatives
    for k in range(mm):
        ru[k] = 0.0
    for j in range(n):
        s = smooth[j]
        if s == 0.0:
            continue
        hj = hd[(v - m + j) % n, m:m + mm]
        for k in range(mm):
            ru[k] += s * hj[k]
    # d/dv: derivative along v per column, then smoothing across (along u)
    for k in range(w):
        vd[k] = 0.0
    for i in range(n):
        c = deriv[i]
        if c == 0.0:
            continue
        Ri = R[v - m + i]
        for k in range(w):
            vd[k] += c * Ri[k]
    for k in range(mm):
        rv[k] = 0.0
    for j in range(n):
        s = smooth[j]
        if s == 0.0:
            continue
        vj = vd[j:j + mm]
        for k in range(mm):
            rv[k] += s * vj[k]
    Rv = R[v, m:m + mm]
    bx = bx_[m:m + mm]
    by = by_[m:m + mm]
    bz = bz_[m:m + mm]
    flag = flag_[m:m + mm]
    y = (v - cy) / fy
    for k in range(mm):
        x = (k + m - cx) / fx
        rq = Rv[k]
        nx, ny, nz = _sri_normal(ru[k] * iws, rv[k] * iws, rq, x, y, fx, fy)
        n2 = nx * nx + ny * ny + nz * nz
        nrm = math.sqrt(n2)
        inv = 1.0 / nrm
        inv = -inv if faces_away(nx * x + ny * y + nz, n2, x * x + y * y + 1.0, nx, ny, nz) else inv
        bx[k] = nx * inv
        by[k] = ny * inv
        bz[k] = nz * inv
        chk = nrm * rq * 0.0 + nrm
        flag[k] = not (chk == chk and nrm > 0.0 and nrm < np.inf)


@nb.njit(cache=True, nogil=True, error_model=_NUMPY)
def _sri_rows(v0, v1, z, R, fx, fy, cx, cy, deriv, smooth, out):
    """Separable Sobel stencil on fully valid windows (a vectorisable row pass), the
    validity-aware per-pixel stencil elsewhere (flagged pixels)."""
    h, w = z.shape
    m = deriv.size // 2
    n = 2 * m + 1
    wsum = 0.0
    for j in range(n):
        if smooth[j] != 0.0:
            wsum += smooth[j]
    iws = 1.0 / wsum
    hd = np.empty((n, w))
    vd = np.empty(w)
    ru = np.empty(w)
    rv = np.empty(w)
    bx = np.empty(w)
    by = np.empty(w)
    bz = np.empty(w)
    flag = np.empty(w, dtype=np.bool_)
    nxt = -1
    for v in range(v0, v1):
        flag[:] = True
        if m <= v < h - m and w > 2 * m:
            for rr in range(max(nxt, v - m), v + m + 1):
                _sri_hrow(R[rr], deriv, m, hd[rr % n])
            nxt = v + m + 1
            _sri_fast_row(v, R, hd, deriv, smooth, iws, (fx, fy, cx, cy), (vd, ru, rv),
                          (bx, by, bz), flag)
            _copy_row(out[v, m:w - m], bx[m:w - m], by[m:w - m], bz[m:w - m])
        for u in range(w):
            if flag[u]:
                _sri_pixel(z, R, v, u, fx, fy, cx, cy, deriv, smooth, out)


def sri(depth: Any, K: Any, *, window: int = 5, depth_scale: float | None = None) -> np.ndarray:
    """Spherical range image (SRI): normals from derivatives of range in azimuth/elevation.

    With ``p = r s(theta, phi)``, ``s = (sin theta cos phi, sin phi, cos theta cos phi)``,
    azimuth ``theta`` (from z to x) and elevation ``phi`` (toward y), the normal is
    ``n ~ s - (dr/dtheta) / (r cos phi) e_theta - (dr/dphi) / r e_phi`` in the local
    spherical frame, rotated back to the camera frame.

    Parameters
    ----------
    depth : array_like, shape (H, W)
        Planar depth z (any length unit). float32/float64; integers need ``depth_scale``.
        Invalid depth (0, negative, NaN, inf) gives NaN.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Intrinsics in pixels, 0-based pixel centres.
    window : {3, 5, 7, 9, 11}, default 5
        Size of the Sobel derivative kernel (OpenCV's ``window_size``, default 5 there too).
    depth_scale : float, optional
        Metres per unit of integer depth.

    Returns
    -------
    normals : ndarray, shape (H, W, 3), float32
        Unit normals facing the camera; NaN at invalid depth and where no derivative exists.

    Notes
    -----
    Interpretation (ours): the derivatives ``dr/dtheta`` and ``dr/dphi`` are taken on the
    image grid and converted by the exact chain rule (``theta`` depends on u only, ``phi``
    on u and v), instead of resampling the range image onto a regular (theta, phi) grid and
    back with bilinear interpolation as OpenCV does; the two agree on smooth surfaces, but
    ours never interpolates across invalid pixels or resamples. The Sobel stencil falls back
    to central, then one-sided differences next to invalid pixels.

    References
    ----------
    H. Badino, D. Huber, Y. Park and T. Kanade, "Fast and Accurate Computation of Surface
    Normals from Range Images," IEEE International Conference on Robotics and Automation
    (ICRA), 2011, pp. 3084-3091. doi:10.1109/ICRA.2011.5980275

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals import sri
    >>> n = sri(np.full((7, 8), 2.0), (500.0, 500.0, 3.5, 3.0))
    >>> bool(np.allclose(n[3, 4], [0.0, 0.0, -1.0], atol=1e-6))
    True
    """
    window = check_window(window)
    if window > 11:
        raise ValueError(f"window must be one of 3, 5, 7, 9, 11 for sri; got {window}")
    z, cam = prepare(depth, K, depth_scale)
    deriv, smooth = gradient_kernels("sobel", window)
    h = z.shape[0]
    R = np.empty(z.shape)
    run_rows(_range_rows, h, z, cam.fx, cam.fy, cam.cx, cam.cy, R)
    out = np.empty((*z.shape, 3), dtype=np.float32)
    run_rows(_sri_rows, h, z, R, cam.fx, cam.fy, cam.cx, cam.cy, deriv, smooth, out)
    return out


# ------------------------------------------------------------------------------- LINE-MOD

@nb.njit(cache=True, error_model=_NUMPY)
def _linemod_direction(zs, zr, thr, b0, b1, ok, di, dj):
    """One of the eight samples for a row's pixels (``zr`` the row, ``zs`` the row of the
    sample, shifted to line up; both slices of equal length, from 0): where it passes
    (valid, within ``thr`` of the centre) add its terms to ``b0``, ``b1`` as the general
    path does (``di``, ``dj`` its offsets ``i r``, ``j r``), and clear ``ok`` where it does
    not (that pixel takes the general path, which searches nearer samples). Branch-free."""
    for k in range(zr.size):
        zq = zr[k]
        zn = zs[k]
        dz = zn - zq
        good = (zn == zn) & (abs(dz) <= thr)
        b0[k] += di * dz if good else 0.0
        b1[k] += dj * dz if good else 0.0
        ok[k] &= good


@nb.njit(cache=True, nogil=True, error_model=_NUMPY)
def _linemod_rows(v0, v1, z, fx, fy, cx, cy, r, thr, out):
    """Rows ``[v0, v1)``: a vectorised pass over the row for the pixels whose eight samples at
    distance ``r`` all pass (most of a smooth surface; the same sums in the same order as the
    general path, so the same bits), then the general per-pixel search for the others."""
    h, w = z.shape
    b0s = np.empty(w)
    b1s = np.empty(w)
    oks = np.empty(w, dtype=np.bool_)
    a = 6.0 * r * r  # sum of du^2 (and of dv^2) over the eight samples at distance r
    for v in range(v0, v1):
        zr = z[v]
        for u in range(w):
            b0s[u] = 0.0
            b1s[u] = 0.0
            oks[u] = zr[u] == zr[u]
        for j in range(-1, 2):  # the general path's order of the samples
            rr = v + j * r
            for i in range(-1, 2):
                if i == 0 and j == 0:
                    continue
                if rr < 0 or rr >= h:
                    oks[:] = False
                    continue
                sh = i * r
                lo = max(0, -sh)
                hi = min(w, w - sh)
                oks[:lo] = False
                oks[hi:] = False
                if hi > lo:
                    _linemod_direction(z[rr, lo + sh:hi + sh], zr[lo:hi], thr, b0s[lo:hi],
                                       b1s[lo:hi], oks[lo:hi], float(i * r), float(j * r))
        for u in range(w):
            if oks[u]:  # (sum du dv over the eight samples: 0)
                _linemod_store(out, v, u, zr[u], a, 0.0, a, b0s[u], b1s[u], fx, fy, cx, cy)
            else:
                _linemod_pixel(z, v, u, fx, fy, cx, cy, r, thr, out)


@nb.njit(cache=True, error_model=_NUMPY, inline="always")
def _linemod_store(out, v, u, zq, a00, a01, a11, b0, b1, fx, fy, cx, cy):
    """Solve the pixel's normal equations for the depth gradient and store the normal of the
    tangents at q along u and v with it (their cross product, D2NT form); nothing where the
    samples do not determine a gradient."""
    det = a00 * a11 - a01 * a01
    if not (det > 0.0):
        return
    zu = (a11 * b0 - a01 * b1) / det
    zv = (a00 * b1 - a01 * b0) / det
    store_normal(out, v, u, fx * zu, fy * zv, -(zq + (u - cx) * zu + (v - cy) * zv),
                 (u - cx) * zq / fx, (v - cy) * zq / fy, zq)


@nb.njit(cache=True, error_model=_NUMPY)
def _linemod_pixel(z, v, u, fx, fy, cx, cy, r, thr, out):
    """The general path of one pixel (:func:`line_mod`): each sample at distance ``r`` or,
    where it fails, the farthest nearer one that passes."""
    h, w = z.shape
    zq = z[v, u]
    if not (zq == zq):
        return
    a00 = a01 = a11 = 0.0
    b0 = b1 = 0.0
    for j in range(-1, 2):
        for i in range(-1, 2):
            if i == 0 and j == 0:
                continue
            # the sample at distance r along (i, j); where it is invalid, outside or
            # beyond the threshold, the farthest nearer one that is not
            dz = np.nan
            s = r
            while s >= 1:
                rr = v + j * s
                cc = u + i * s
                if 0 <= rr < h and 0 <= cc < w:
                    zn = z[rr, cc]
                    if zn == zn and abs(zn - zq) <= thr:
                        dz = zn - zq
                        break
                s -= 1
            if not (dz == dz):
                continue
            du = i * s
            dv = j * s
            a00 += du * du
            a01 += du * dv
            a11 += dv * dv
            b0 += du * dz
            b1 += dv * dz
    _linemod_store(out, v, u, zq, a00, a01, a11, b0, b1, fx, fy, cx, cy)


def line_mod(depth: Any, K: Any, *, window: int = 11, threshold: float = 0.05,
             depth_scale: float | None = None) -> np.ndarray:
    """LINE-MOD's depth normals: a least-squares depth gradient from thresholded neighbours.

    The first-order Taylor expansion ``z(q + d) - z(q) = d . grad z`` is solved in the least
    squares sense over the samples ``d`` of the window whose depth differs from the centre's
    by at most ``threshold``; the plane through ``q`` and the two points one pixel along u
    and v with that gradient gives the normal.

    Parameters
    ----------
    depth : array_like, shape (H, W)
        Planar depth z. float32/float64; integers need ``depth_scale``. Invalid depth
        (0, negative, NaN, inf) gives NaN.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Intrinsics in pixels, 0-based pixel centres.
    window : int, default 11
        Odd side of the window; the samples are its 8 corner and edge-midpoint pixels,
        at offsets ``{-r, 0, r}^2`` with ``r = window // 2`` (OpenCV: r = 5, i.e. 11).
        Where such a sample is invalid, outside the image or beyond ``threshold``, the
        farthest nearer pixel in the same direction that is not takes its place.
    threshold : float, default 0.05
        Largest accepted depth difference to the centre, in the unit of the depth after
        ``depth_scale`` (metres for depth in metres: 0.05 m is OpenCV's 50 on millimetre
        input).
    depth_scale : float, optional
        Metres per unit of integer depth.

    Returns
    -------
    normals : ndarray, shape (H, W, 3), float32
        Unit normals facing the camera; NaN at invalid depth and where the accepted samples
        do not determine a gradient (all on one line through q, or none).

    Notes
    -----
    Interpretation (ours): a sample that is invalid, outside the image or beyond the
    threshold is replaced by the farthest nearer pixel in its direction that passes (OpenCV
    drops it), so the estimate reaches the image border, survives holes, keeps the near side
    of a discontinuity and covers steep planes whose depth changes by more than the
    threshold over ``r`` pixels (OpenCV leaves an ``r``-pixel frame as NaN and does not test
    validity, so zero depth enters its fit). Where every sample at distance ``r`` passes,
    the estimate is OpenCV's. The normal is the cross product of the exact
    tangents ``dX/du``, ``dX/dv`` for the fitted gradient, i.e. the limit of the paper's
    three-point plane (OpenCV uses the finite points at ``u + 1`` and ``v + 1``, which
    differs by the curvature of depth over one pixel, ~0.01 deg on a plane). The threshold
    makes the method depend on the depth unit.

    References
    ----------
    S. Hinterstoisser, C. Cagniart, S. Ilic, P. Sturm, N. Navab, P. Fua and V. Lepetit,
    "Gradient Response Maps for Real-Time Detection of Textureless Objects," IEEE
    Transactions on Pattern Analysis and Machine Intelligence, vol. 34, no. 5,
    pp. 876-888, 2012. doi:10.1109/TPAMI.2011.206

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals import line_mod
    >>> n = line_mod(np.full((12, 12), 2.0), (500.0, 500.0, 5.5, 5.5))
    >>> bool(np.allclose(n[6, 6], [0.0, 0.0, -1.0], atol=1e-6))
    True
    """
    r = check_window(window) // 2
    thr = check_positive(threshold, "threshold")
    z, cam = prepare(depth, K, depth_scale)
    out = new_output(z.shape)
    run_rows(_linemod_rows, z.shape[0], z, cam.fx, cam.fy, cam.cx, cam.cy, r, thr, out)
    return out
