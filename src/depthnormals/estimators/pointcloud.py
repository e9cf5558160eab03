"""Point-cloud estimators on the neighbourhood of back-projected points: PlaneSVD, PlanePCA,
VectorSVD, AreaWeighted, AngleWeighted."""

from __future__ import annotations

import math
import numbers
from typing import Any

import numba as nb
import numpy as np

from .._parallel import run_rows
from ..kernels.depth import prepare
from ..kernels.eig3 import smallest_eigenvector, smallest_eigenvector_newton
from ..kernels.orient import faces_away, store_normal

__all__ = ["angle_weighted", "area_weighted", "plane_pca", "plane_svd", "vector_svd"]

# the 8 neighbours in cyclic order around the centre (dv, du)
_RING = np.array([[-1, -1], [-1, 0], [-1, 1], [0, 1], [1, 1], [1, 0], [1, -1], [0, -1]],
                 dtype=np.int64)


def check_window(window: Any, name: str = "window") -> int:
    """An odd integer >= 3, or TypeError/ValueError."""
    if isinstance(window, bool) or not isinstance(window, numbers.Integral):
        raise TypeError(f"{name} must be an odd integer >= 3 (e.g. 3 or 5); got {window!r}")
    if window < 3 or window % 2 == 0:
        raise ValueError(f"{name} must be an odd integer >= 3 (e.g. 3 or 5); got {window}")
    return int(window)


_NUMPY = "numpy"  # error_model: float division by zero gives inf/NaN, never raises


@nb.njit(cache=True, error_model=_NUMPY)
def _scatter_pixel(z, v, u, fx, fy, cx, cy, r, centred, out):
    """Smallest-eigenvalue direction of the (centred or raw) scatter of p_i - q over the
    valid pixels of the (2r+1)^2 window (general path: any window, holes, border)."""
    h, w = z.shape
    out[v, u, 0] = np.nan
    out[v, u, 1] = np.nan
    out[v, u, 2] = np.nan
    zq = z[v, u]
    if not (zq == zq):
        return
    ifx = 1.0 / fx
    ify = 1.0 / fy
    xq = (u - cx) * zq * ifx
    yq = (v - cy) * zq * ify
    n = 0
    sx = sy = sz = 0.0
    sxx = sxy = sxz = syy = syz = szz = 0.0
    for rr in range(max(v - r, 0), min(v + r + 1, h)):
        ry = (rr - cy) * ify
        for cc in range(max(u - r, 0), min(u + r + 1, w)):
            zn = z[rr, cc]
            if not (zn == zn):
                continue
            dx = (cc - cx) * zn * ifx - xq
            dy = ry * zn - yq
            dz = zn - zq
            n += 1
            sx += dx
            sy += dy
            sz += dz
            sxx += dx * dx
            sxy += dx * dy
            sxz += dx * dz
            syy += dy * dy
            syz += dy * dz
            szz += dz * dz
    if n < 3:
        return
    if centred:
        inv = 1.0 / n
        sxx -= sx * sx * inv
        sxy -= sx * sy * inv
        sxz -= sx * sz * inv
        syy -= sy * sy * inv
        syz -= sy * sz * inv
        szz -= sz * sz * inv
    nx, ny, nz = smallest_eigenvector(sxx, sxy, sxz, syy, syz, szz)
    store_normal(out, v, u, nx, ny, nz, xq, yq, zq)


@nb.njit(cache=True, error_model=_NUMPY, inline="always")
def _acc9(dx, dy, dz, sx, sy, sz, sxx, sxy, sxz, syy, syz, szz):
    return (sx + dx, sy + dy, sz + dz, sxx + dx * dx, sxy + dx * dy, sxz + dx * dz,
            syy + dy * dy, syz + dy * dz, szz + dz * dz)


@nb.njit(cache=True, error_model=_NUMPY)
def _scatter3_row(zp, zc, zn, v, fx, fy, cx, cy, centred, bx, by, bz, flag):
    """Branch-free (vectorisable) 3x3 scatter normal over the interior of one row.

    Same sums in the same order as :func:`_scatter_pixel`, the eigenvalue by Newton's method
    (see :func:`smallest_eigenvector_newton`); ``flag[u]`` is set where a neighbour is
    invalid or the solve is not well determined (those pixels take the general path).
    """
    w = zc.size
    ifx = 1.0 / fx
    ify = 1.0 / fy
    ya = (v - 1 - cy) * ify
    yb = (v - cy) * ify
    yc = (v + 1 - cy) * ify
    for u in range(1, w - 1):
        xa = u - 1 - cx
        xb = u - cx
        xc = u + 1 - cx
        zq = np.float64(zc[u])
        xq = xb * zq * ifx
        yq = (v - cy) * zq * ify
        z0 = np.float64(zp[u - 1])
        z1 = np.float64(zp[u])
        z2 = np.float64(zp[u + 1])
        z3 = np.float64(zc[u - 1])
        z5 = np.float64(zc[u + 1])
        z6 = np.float64(zn[u - 1])
        z7 = np.float64(zn[u])
        z8 = np.float64(zn[u + 1])
        sx = sy = sz = sxx = sxy = sxz = syy = syz = szz = 0.0
        sx, sy, sz, sxx, sxy, sxz, syy, syz, szz = _acc9(
            xa * z0 * ifx - xq, ya * z0 - yq, z0 - zq, sx, sy, sz, sxx, sxy, sxz, syy, syz, szz)
        sx, sy, sz, sxx, sxy, sxz, syy, syz, szz = _acc9(
            xb * z1 * ifx - xq, ya * z1 - yq, z1 - zq, sx, sy, sz, sxx, sxy, sxz, syy, syz, szz)
        sx, sy, sz, sxx, sxy, sxz, syy, syz, szz = _acc9(
            xc * z2 * ifx - xq, ya * z2 - yq, z2 - zq, sx, sy, sz, sxx, sxy, sxz, syy, syz, szz)
        sx, sy, sz, sxx, sxy, sxz, syy, syz, szz = _acc9(
            xa * z3 * ifx - xq, yb * z3 - yq, z3 - zq, sx, sy, sz, sxx, sxy, sxz, syy, syz, szz)
        sx, sy, sz, sxx, sxy, sxz, syy, syz, szz = _acc9(
            xb * zq * ifx - xq, yb * zq - yq, zq - zq, sx, sy, sz, sxx, sxy, sxz, syy, syz, szz)
        sx, sy, sz, sxx, sxy, sxz, syy, syz, szz = _acc9(
            xc * z5 * ifx - xq, yb * z5 - yq, z5 - zq, sx, sy, sz, sxx, sxy, sxz, syy, syz, szz)
        sx, sy, sz, sxx, sxy, sxz, syy, syz, szz = _acc9(
            xa * z6 * ifx - xq, yc * z6 - yq, z6 - zq, sx, sy, sz, sxx, sxy, sxz, syy, syz, szz)
        sx, sy, sz, sxx, sxy, sxz, syy, syz, szz = _acc9(
            xb * z7 * ifx - xq, yc * z7 - yq, z7 - zq, sx, sy, sz, sxx, sxy, sxz, syy, syz, szz)
        sx, sy, sz, sxx, sxy, sxz, syy, syz, szz = _acc9(
            xc * z8 * ifx - xq, yc * z8 - yq, z8 - zq, sx, sy, sz, sxx, sxy, sxz, syy, syz, szz)
        if centred:
            inv = 1.0 / 9.0
            sxx -= sx * sx * inv
            sxy -= sx * sy * inv
            sxz -= sx * sz * inv
            syy -= sy * sy * inv
            syz -= sy * sz * inv
            szz -= sz * sz * inv
        nx, ny, nz, ok = smallest_eigenvector_newton(sxx, sxy, sxz, syy, syz, szz)
        n2 = nx * nx + ny * ny + nz * nz
        nrm = math.sqrt(n2)  # as store_normal: renormalise, orient
        inv = 1.0 / nrm
        p2 = xq * xq + yq * yq + zq * zq
        inv = -inv if faces_away(nx * xq + ny * yq + nz * zq, n2, p2, nx, ny, nz) else inv
        bx[u] = nx * inv
        by[u] = ny * inv
        bz[u] = nz * inv
        flag[u] = not (ok and zq == zq and nrm > 0.0 and nrm < np.inf)


@nb.njit(cache=True, nogil=True, error_model=_NUMPY)
def _scatter_rows(v0, v1, z, fx, fy, cx, cy, r, centred, out):
    h, w = z.shape
    bx = np.empty(w)
    by = np.empty(w)
    bz = np.empty(w)
    flag = np.empty(w, dtype=np.bool_)
    for v in range(v0, v1):
        flag[:] = True
        if r == 1 and 0 < v < h - 1 and w > 2:
            _scatter3_row(z[v - 1], z[v], z[v + 1], v, fx, fy, cx, cy, centred, bx, by, bz, flag)
            for u in range(1, w - 1):
                out[v, u, 0] = bx[u]
                out[v, u, 1] = by[u]
                out[v, u, 2] = bz[u]
        for u in range(w):
            if flag[u]:
                _scatter_pixel(z, v, u, fx, fy, cx, cy, r, centred, out)


@nb.njit(cache=True, error_model=_NUMPY)
def _fan_pixel(z, v, u, fx, fy, cx, cy, ring, angle, out):
    """Weighted sum of the unit normals of the triangles (q, p_i, p_i+1) of the 8-ring
    (general path: holes, border)."""
    h, w = z.shape
    out[v, u, 0] = np.nan
    out[v, u, 1] = np.nan
    out[v, u, 2] = np.nan
    zq = z[v, u]
    if not (zq == zq):
        return
    ifx = 1.0 / fx
    ify = 1.0 / fy
    xq = (u - cx) * zq * ifx
    yq = (v - cy) * zq * ify
    d = np.empty((8, 3))
    ok = np.empty(8, np.bool_)
    for k in range(8):
        rr = v + ring[k, 0]
        cc = u + ring[k, 1]
        ok[k] = False
        if rr < 0 or rr >= h or cc < 0 or cc >= w:
            continue
        zn = z[rr, cc]
        if not (zn == zn):
            continue
        ok[k] = True
        d[k, 0] = (cc - cx) * zn * ifx - xq
        d[k, 1] = (rr - cy) * zn * ify - yq
        d[k, 2] = zn - zq
    sx = sy = sz = 0.0
    used = 0
    for k in range(8):
        k2 = (k + 1) % 8
        if not (ok[k] and ok[k2]):
            continue
        ax, ay, az = d[k, 0], d[k, 1], d[k, 2]
        bx, by, bz = d[k2, 0], d[k2, 1], d[k2, 2]
        tx = ay * bz - az * by
        ty = az * bx - ax * bz
        tz = ax * by - ay * bx
        norm = math.sqrt(tx * tx + ty * ty + tz * tz)
        if not (norm > 0.0):
            continue
        if angle:
            wgt = math.atan2(norm, ax * bx + ay * by + az * bz) / norm
        else:
            wgt = 0.5  # unit normal times area = cross / 2
        sx += wgt * tx
        sy += wgt * ty
        sz += wgt * tz
        used += 1
    if used == 0:
        return
    store_normal(out, v, u, sx, sy, sz, xq, yq, zq)


# Cephes atan: atan(x) = x + x^3 P(x^2) / Q(x^2) on [0, 0.66], double precision
_P0 = -8.750608600031904122785e-01
_P1 = -1.615753718733365076637e+01
_P2 = -7.500855792314704667340e+01
_P3 = -1.228866684490136173410e+02
_P4 = -6.485021904942025371773e+01
_Q0 = 2.485846490142306297962e+01
_Q1 = 1.650270098316988542046e+02
_Q2 = 4.328810604912902668951e+02
_Q3 = 4.853903996359136964868e+02
_Q4 = 1.945506571482613964425e+02
_MOREBITS = 6.123233995736765886130e-17


@nb.njit(cache=True, error_model=_NUMPY, inline="always")
def angle_between(s, c):
    """atan2(s, c) for s >= 0 (the angle between two vectors from |cross| and dot), branch-free
    so that loops calling it vectorise (no libm call); within a few ulp of math.atan2."""
    ac = abs(c)
    big = s > ac
    num = ac if big else s
    den = s if big else ac
    t = num / den  # in [0, 1]
    hi = t > 0.66
    x = (t - 1.0) / (t + 1.0) if hi else t
    x2 = x * x
    p = (((_P0 * x2 + _P1) * x2 + _P2) * x2 + _P3) * x2 + _P4
    q = ((((x2 + _Q0) * x2 + _Q1) * x2 + _Q2) * x2 + _Q3) * x2 + _Q4
    a = x + x * (x2 * p / q)
    a = (0.25 * math.pi + (a + 0.5 * _MOREBITS)) if hi else a
    a = (0.5 * math.pi - a) if big else a
    a = (math.pi - a) if c < 0.0 else a
    return a


@nb.njit(cache=True, error_model=_NUMPY, inline="always")
def _tri(ax, ay, az, bx, by, bz, angle, sx, sy, sz, good):
    tx = ay * bz - az * by
    ty = az * bx - ax * bz
    tz = ax * by - ay * bx
    norm = math.sqrt(tx * tx + ty * ty + tz * tz)
    if angle:
        wgt = angle_between(norm, ax * bx + ay * by + az * bz) / norm
    else:
        wgt = 0.5
    return sx + wgt * tx, sy + wgt * ty, sz + wgt * tz, good and norm > 0.0 and norm < np.inf


@nb.njit(cache=True, error_model=_NUMPY)
def _fan_row(zp, zc, zn, v, fx, fy, cx, cy, angle, bx, by, bz, flag):
    """Branch-free (vectorisable) triangle fan over the interior of one row; ``flag[u]`` is
    set where a vertex is invalid or a triangle is degenerate (general path)."""
    w = zc.size
    ifx = 1.0 / fx
    ify = 1.0 / fy
    ya = v - 1 - cy
    yb = v - cy
    yc = v + 1 - cy
    for u in range(1, w - 1):
        xa = u - 1 - cx
        xb = u - cx
        xc = u + 1 - cx
        zq = np.float64(zc[u])
        xq = xb * zq * ifx
        yq = yb * zq * ify
        # ring order: (-1,-1) (-1,0) (-1,1) (0,1) (1,1) (1,0) (1,-1) (0,-1)
        z0 = np.float64(zp[u - 1])
        z1 = np.float64(zp[u])
        z2 = np.float64(zp[u + 1])
        z3 = np.float64(zc[u + 1])
        z4 = np.float64(zn[u + 1])
        z5 = np.float64(zn[u])
        z6 = np.float64(zn[u - 1])
        z7 = np.float64(zc[u - 1])
        d0x, d0y, d0z = xa * z0 * ifx - xq, ya * z0 * ify - yq, z0 - zq
        d1x, d1y, d1z = xb * z1 * ifx - xq, ya * z1 * ify - yq, z1 - zq
        d2x, d2y, d2z = xc * z2 * ifx - xq, ya * z2 * ify - yq, z2 - zq
        d3x, d3y, d3z = xc * z3 * ifx - xq, yb * z3 * ify - yq, z3 - zq
        d4x, d4y, d4z = xc * z4 * ifx - xq, yc * z4 * ify - yq, z4 - zq
        d5x, d5y, d5z = xb * z5 * ifx - xq, yc * z5 * ify - yq, z5 - zq
        d6x, d6y, d6z = xa * z6 * ifx - xq, yc * z6 * ify - yq, z6 - zq
        d7x, d7y, d7z = xa * z7 * ifx - xq, yb * z7 * ify - yq, z7 - zq
        sx = sy = sz = 0.0
        good = zq == zq
        sx, sy, sz, good = _tri(d0x, d0y, d0z, d1x, d1y, d1z, angle, sx, sy, sz, good)
        sx, sy, sz, good = _tri(d1x, d1y, d1z, d2x, d2y, d2z, angle, sx, sy, sz, good)
        sx, sy, sz, good = _tri(d2x, d2y, d2z, d3x, d3y, d3z, angle, sx, sy, sz, good)
        sx, sy, sz, good = _tri(d3x, d3y, d3z, d4x, d4y, d4z, angle, sx, sy, sz, good)
        sx, sy, sz, good = _tri(d4x, d4y, d4z, d5x, d5y, d5z, angle, sx, sy, sz, good)
        sx, sy, sz, good = _tri(d5x, d5y, d5z, d6x, d6y, d6z, angle, sx, sy, sz, good)
        sx, sy, sz, good = _tri(d6x, d6y, d6z, d7x, d7y, d7z, angle, sx, sy, sz, good)
        sx, sy, sz, good = _tri(d7x, d7y, d7z, d0x, d0y, d0z, angle, sx, sy, sz, good)
        n2 = sx * sx + sy * sy + sz * sz
        nrm = math.sqrt(n2)
        inv = 1.0 / nrm
        p2 = xq * xq + yq * yq + zq * zq
        inv = -inv if faces_away(sx * xq + sy * yq + sz * zq, n2, p2, sx, sy, sz) else inv
        bx[u] = sx * inv
        by[u] = sy * inv
        bz[u] = sz * inv
        flag[u] = not (good and nrm > 0.0 and nrm < np.inf)


@nb.njit(cache=True, nogil=True, error_model=_NUMPY)
def _fan_rows(v0, v1, z, fx, fy, cx, cy, ring, angle, out):
    h, w = z.shape
    bx = np.empty(w)
    by = np.empty(w)
    bz = np.empty(w)
    flag = np.empty(w, dtype=np.bool_)
    for v in range(v0, v1):
        flag[:] = True
        if 0 < v < h - 1 and w > 2:
            _fan_row(z[v - 1], z[v], z[v + 1], v, fx, fy, cx, cy, angle, bx, by, bz, flag)
            for u in range(1, w - 1):
                out[v, u, 0] = bx[u]
                out[v, u, 1] = by[u]
                out[v, u, 2] = bz[u]
        for u in range(w):
            if flag[u]:
                _fan_pixel(z, v, u, fx, fy, cx, cy, ring, angle, out)


_SHARED_PARAMS = """
    Parameters
    ----------
    depth : array_like, shape (H, W)
        Planar depth z (any length unit). float32/float64; integers need ``depth_scale``.
        Invalid depth (0, negative, NaN, inf) gives NaN.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Intrinsics in pixels, 0-based pixel centres."""

_RETURNS = """
    Returns
    -------
    normals : ndarray, shape (H, W, 3), float32
        Unit normals facing the camera; NaN at invalid depth and where fewer than three
        non-collinear valid points are left."""


def _scatter(depth, K, window, depth_scale, centred):
    r = check_window(window) // 2
    z, cam = prepare(depth, K, depth_scale)
    out = np.empty((*z.shape, 3), dtype=np.float32)
    run_rows(_scatter_rows, z.shape[0], z, cam.fx, cam.fy, cam.cx, cam.cy, r, centred, out)
    return out


def _fan(depth, K, depth_scale, angle):
    z, cam = prepare(depth, K, depth_scale)
    out = np.empty((*z.shape, 3), dtype=np.float32)
    run_rows(_fan_rows, z.shape[0], z, cam.fx, cam.fy, cam.cx, cam.cy, _RING, angle, out)
    return out


def plane_svd(depth: Any, K: Any, *, window: int = 3,
              depth_scale: float | None = None) -> np.ndarray:
    """PlaneSVD: the least-squares plane through the back-projected window, by SVD.

    The points of the ``window x window`` neighbourhood are centred on their mean; the
    normal is the right singular vector of the smallest singular value of the (n, 3)
    matrix, i.e. the eigenvector of the smallest eigenvalue of its scatter matrix
    (closed-form 3x3 solver, no LAPACK per pixel).
    {params}
    window : int, default 3
        Odd side of the square neighbourhood. Only valid pixels are used.
    depth_scale : float, optional
        Metres per unit of integer depth.
    {returns}

    Notes
    -----
    PlaneSVD and PlanePCA minimise the same orthogonal plane-fitting error, so they give
    the same normal up to rounding (the 3F2N+ paper reports identical errors for both).
    Interpretation (ours): the singular vectors of the centred (n, 3) matrix are computed
    from its 3x3 Gram matrix; invalid neighbours are left out, and three non-collinear
    valid points are needed.

    References
    ----------
    K. Klasing, D. Althoff, D. Wollherr and M. Buss, "Comparison of Surface Normal
    Estimation Methods for Range Sensing Applications," IEEE International Conference on
    Robotics and Automation (ICRA), 2009, pp. 3206-3211. doi:10.1109/ROBOT.2009.5152493

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals import plane_svd
    >>> n = plane_svd(np.full((5, 6), 2.0), (500.0, 500.0, 2.5, 2.0))
    >>> bool(np.allclose(n[2, 2], [0.0, 0.0, -1.0], atol=1e-6))
    True
    """
    return _scatter(depth, K, window, depth_scale, True)


def plane_pca(depth: Any, K: Any, *, window: int = 3,
              depth_scale: float | None = None) -> np.ndarray:
    """PlanePCA: the normal is the least principal axis of the back-projected window.

    The covariance of the points of the ``window x window`` neighbourhood is formed; the
    normal is the eigenvector of its smallest eigenvalue.
    {params}
    window : int, default 3
        Odd side of the square neighbourhood. Only valid pixels are used.
    depth_scale : float, optional
        Metres per unit of integer depth.
    {returns}

    Notes
    -----
    The same minimiser as PlaneSVD (see :func:`plane_svd`); the covariance differs from
    the scatter matrix only by the factor 1/n. Interpretation (ours): invalid neighbours
    are left out.

    References
    ----------
    K. Klasing, D. Wollherr and M. Buss, "Realtime Segmentation of Range Data Using
    Continuous Nearest Neighbors," IEEE International Conference on Robotics and
    Automation (ICRA), 2009, pp. 2431-2436. doi:10.1109/ROBOT.2009.5152543

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals import plane_pca
    >>> n = plane_pca(np.full((5, 6), 2.0), (500.0, 500.0, 2.5, 2.0))
    >>> bool(np.allclose(n[2, 2], [0.0, 0.0, -1.0], atol=1e-6))
    True
    """
    return _scatter(depth, K, window, depth_scale, True)


def vector_svd(depth: Any, K: Any, *, window: int = 3,
               depth_scale: float | None = None) -> np.ndarray:
    """VectorSVD: the direction most orthogonal to the difference vectors p_i - q.

    The normal is the right singular vector of the smallest singular value of the matrix
    of the difference vectors from the centre ``q`` to its valid neighbours in the
    ``window x window`` neighbourhood (not centred on their mean).
    {params}
    window : int, default 3
        Odd side of the square neighbourhood. Only valid pixels are used.
    depth_scale : float, optional
        Metres per unit of integer depth.
    {returns}

    Notes
    -----
    Interpretation (ours): the singular vector comes from the 3x3 matrix
    ``sum (p_i - q)(p_i - q)^T`` (closed-form solver); invalid neighbours are left out.

    References
    ----------
    K. Klasing, D. Althoff, D. Wollherr and M. Buss, "Comparison of Surface Normal
    Estimation Methods for Range Sensing Applications," IEEE International Conference on
    Robotics and Automation (ICRA), 2009, pp. 3206-3211. doi:10.1109/ROBOT.2009.5152493

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals import vector_svd
    >>> n = vector_svd(np.full((5, 6), 2.0), (500.0, 500.0, 2.5, 2.0))
    >>> bool(np.allclose(n[2, 2], [0.0, 0.0, -1.0], atol=1e-6))
    True
    """
    return _scatter(depth, K, window, depth_scale, False)


def area_weighted(depth: Any, K: Any, *, depth_scale: float | None = None) -> np.ndarray:
    """AreaWeighted: the area-weighted mean of the normals of the 8 triangles around q.

    The 8 neighbours ``p_i`` of ``q`` are taken in cyclic order around it; each triangle
    ``(q, p_i, p_i+1)`` contributes its unit normal times its area, i.e. half the cross
    product ``(p_i - q) x (p_i+1 - q)``.
    {params}
    depth_scale : float, optional
        Metres per unit of integer depth.
    {returns}

    Notes
    -----
    Interpretation (ours): a triangle with an invalid or out-of-image vertex is left out;
    the method is defined on the 3x3 neighbourhood only (no ``window``).

    References
    ----------
    S. Jin, R. R. Lewis and D. West, "A comparison of algorithms for vertex normal
    computation," The Visual Computer, vol. 21, no. 1-2, pp. 71-82, 2005.
    doi:10.1007/s00371-004-0271-1

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals import area_weighted
    >>> n = area_weighted(np.full((5, 6), 2.0), (500.0, 500.0, 2.5, 2.0))
    >>> bool(np.allclose(n[2, 2], [0.0, 0.0, -1.0], atol=1e-6))
    True
    """
    return _fan(depth, K, depth_scale, False)


def angle_weighted(depth: Any, K: Any, *, depth_scale: float | None = None) -> np.ndarray:
    """AngleWeighted: the angle-weighted mean of the normals of the 8 triangles around q.

    As :func:`area_weighted`, but each triangle's unit normal is weighted by its angle at
    ``q``, ``atan2(|a x b|, a . b)`` with ``a = p_i - q``, ``b = p_i+1 - q``.
    {params}
    depth_scale : float, optional
        Metres per unit of integer depth.
    {returns}

    Notes
    -----
    Interpretation (ours): a triangle with an invalid or out-of-image vertex is left out;
    the method is defined on the 3x3 neighbourhood only (no ``window``).

    References
    ----------
    S. Jin, R. R. Lewis and D. West, "A comparison of algorithms for vertex normal
    computation," The Visual Computer, vol. 21, no. 1-2, pp. 71-82, 2005.
    doi:10.1007/s00371-004-0271-1

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals import angle_weighted
    >>> n = angle_weighted(np.full((5, 6), 2.0), (500.0, 500.0, 2.5, 2.0))
    >>> bool(np.allclose(n[2, 2], [0.0, 0.0, -1.0], atol=1e-6))
    True
    """
    return _fan(depth, K, depth_scale, True)


for _f in (plane_svd, plane_pca, vector_svd, area_weighted, angle_weighted):
    if _f.__doc__:  # None under python -OO
        _f.__doc__ = (_f.__doc__.replace("    {params}", _SHARED_PARAMS.strip("\n"))
                      .replace("    {returns}", _RETURNS.strip("\n")))
del _f
